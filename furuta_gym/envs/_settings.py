"""The envs' settings as a few validated objects, one per concern.

* :class:`Plant` — the simulated device: named variants, extra effects, domain randomisation;
* :class:`Episode` — the control period (``frame_skip``), the horizon, the start noise;
* :class:`Actuation` — between the action and the plant: the limit and a delay;
* :class:`Sensors` — between the plant and the observation: quantisation, noise, velocity (the
  spine's :mod:`furuta_gym.sensors`, one type the data generation and the controllers read too);
* :class:`Spaces` — what the agent sees: observation layout, dtype, a normalised action;
* :class:`Camera` — the rendered frame.

Each object checks its own values when it is built (one :class:`EnvArgumentError` naming the field
and what was expected); what depends on the system (an angle to quantise, a parameter name) is
checked by the env that receives it. :func:`settings_from_keywords` maps the plain keywords the
envs took before (``max_voltage=``, ``frame_skip=``, ``encoder_counts=``, ...) onto the objects.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import warnings
from typing import Any, Mapping, Sequence

import gymnasium
import numpy as np

from ..effects import Effect
from ..models import system_definition
from ..sensors import Sensors, SettingsError, as_number as _number, check_int, set_fields as _set
from ._plant import effect_json, plant_document

__all__ = [
    "EnvArgumentError",
    "check_int",
    "Plant",
    "Episode",
    "Actuation",
    "Sensors",
    "Spaces",
    "Camera",
    "OBSERVATIONS",
    "LEGACY_KEYWORDS",
    "settings_from_keywords",
]

#: the accepted ``Spaces(observation=...)`` layouts
OBSERVATIONS = ("raw", "wrapped", "trig")


#: a bad constructor keyword, settings field or reset option (a ValueError and a TypeError); the
#: spine's SettingsError, which the sensor model shared with training and controllers raises too
EnvArgumentError = SettingsError


def _check_bool(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise EnvArgumentError(f"{name} must be a bool, got {value!r}")
    return bool(value)


@dataclasses.dataclass(frozen=True)
class Plant:
    """The simulated device: ``presets`` (named variants of the env's ``plant_presets``, e.g.
    ``"coulomb"``), extra ``effects`` (:class:`furuta_gym.effects.Effect`) on top of them, and
    domain randomisation per reset (``randomize``: a relative spread for every parameter but g, or
    ``{parameter: spread}``, each spread in [0, 1)). ``plant="coulomb"`` is short for
    ``plant=Plant("coulomb")``.

    A diagnosed rig also carries its ``lumped`` parameters (the names of ``system``'s lumped form,
    e.g. the Furuta's J1, J1b, Jc, J2, G, c_alpha, c_beta, K), which replace the pinned ones, and
    its ``source`` (which diagnosis or file it came from): ``DiagnosisResult.plant()``,
    :meth:`load` (a diagnosis JSON, a plant JSON or an MJCF written by
    :func:`~furuta_gym.envs.save_mjcf`). ``plant=`` also takes a diagnosis or such a file directly.
    """

    presets: str | Sequence[str] = ()
    effects: Sequence[Effect] = ()
    randomize: float | Mapping[str, float] | None = None
    lumped: Mapping[str, float] | None = None
    system: str | None = None
    source: str = ""

    def __post_init__(self):
        presets = (self.presets,) if isinstance(self.presets, str) else tuple(self.presets or ())
        if not all(isinstance(p, str) for p in presets):
            raise EnvArgumentError(f"Plant.presets must be names (str), got {self.presets!r}")
        effects = tuple(self.effects or ())
        for e in effects:
            if not isinstance(e, Effect):
                raise EnvArgumentError(
                    f"Plant.effects must be furuta_gym.effects.Effect objects, got {type(e).__name__}: {e!r}"
                )
        _check_spreads(self.randomize)
        _set(self, presets=presets, effects=effects)
        if self.lumped is not None:
            _set(self, **_checked_lumped(self.system, self.lumped, effects, bool(self.randomize)))

    @classmethod
    def nominal(cls, system: str, effects: Sequence[Effect] = ()) -> "Plant":
        """The pinned model's lumped values as a plant, with ``effects``."""
        return cls(effects=effects, lumped=system_definition(system).lumped.nominal(), system=system, source="nominal")

    def to_json(self) -> dict[str, Any]:
        """The plant as JSON (a diagnosed plant: its system, lumped values, effects, source)."""
        doc = {
            "system": self.system,
            "lumped": None if self.lumped is None else dict(self.lumped),
            "source": self.source,
            "effects": [effect_json(e) for e in self.effects],
        }
        return {**doc, "presets": list(self.presets)} if self.presets else doc

    @classmethod
    def from_json(cls, doc: Mapping[str, Any], where: str = "plant") -> "Plant":
        try:
            effects = tuple(Effect(**e) for e in doc.get("effects") or ())
            return cls(
                presets=tuple(doc.get("presets") or ()),
                effects=effects,
                lumped=doc.get("lumped"),
                system=doc.get("system"),
                source=doc.get("source", ""),
            )
        except (AttributeError, TypeError, ValueError) as err:
            raise EnvArgumentError(f"{where}: not a plant (expected 'system', 'lumped', 'effects'): {err}") from None

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Plant":
        """A plant from a diagnosis JSON (its ``"plant"``), a plant JSON, or an MJCF file that
        :func:`~furuta_gym.envs.save_mjcf` wrote (its ``<custom>`` text)."""
        return cls.from_json(plant_document(path), os.fspath(path))


def _check_spreads(spreads) -> None:
    if isinstance(spreads, Mapping):
        values = list(spreads.values())
    elif spreads is None:
        values = []
    else:
        values = [spreads] if not isinstance(spreads, (str, bytes)) and np.ndim(spreads) == 0 else [None]
    if any(not 0.0 <= _number(v) < 1.0 for v in values):
        raise EnvArgumentError(
            f"Plant.randomize must be None, a relative spread in [0, 1) or a mapping {{parameter: spread}}; "
            f"got {spreads!r}"
        )


def _checked_lumped(system, lumped, effects, randomize: bool) -> dict[str, Any]:
    """A diagnosed plant's fields, checked: its system, exactly its lumped form's names, effects on
    its joints; randomisation is over physical parameters, which it does not have."""
    if system is None:
        raise EnvArgumentError("Plant.lumped needs Plant.system: the lumped form's names are a system's")
    definition = system_definition(system)
    names = definition.lumped.names
    missing, unknown = sorted(set(names) - set(lumped)), sorted(set(lumped) - set(names))
    if missing or unknown:
        raise EnvArgumentError(
            f"Plant.lumped of {definition.name} must be exactly {list(names)}; missing {missing}, unknown {unknown}"
        )
    if randomize:
        raise EnvArgumentError("Plant.randomize draws physical parameters; a plant with lumped ones has none")
    for e in effects:
        if not e.kind.on_input:
            e.joint_index(definition.spec)
    return {"system": definition.name, "lumped": {k: float(lumped[k]) for k in names}}


@dataclasses.dataclass(frozen=True)
class Episode:
    """Timing of an episode: ``frame_skip`` RK4 steps per action (the control period is the
    system's timestep × frame_skip), truncation after ``seconds`` (None: never), and uniform
    start noise of ``reset_noise_scale`` on every state component (rad, rad/s, m, m/s)."""

    frame_skip: int = 1
    seconds: float | None = 10.0
    reset_noise_scale: float = 0.01

    def __post_init__(self):
        check_int("Episode.frame_skip", self.frame_skip, 1)
        if self.seconds is not None and not (_number(self.seconds) > 0 and math.isfinite(self.seconds)):
            raise EnvArgumentError(f"Episode.seconds must be > 0 or None, got {self.seconds!r}")
        if not (_number(self.reset_noise_scale) >= 0 and math.isfinite(self.reset_noise_scale)):
            raise EnvArgumentError(f"Episode.reset_noise_scale must be >= 0, got {self.reset_noise_scale!r}")
        _set(
            self,
            frame_skip=int(self.frame_skip),
            reset_noise_scale=float(self.reset_noise_scale),
            seconds=None if self.seconds is None else float(self.seconds),
        )


@dataclasses.dataclass(frozen=True)
class Actuation:
    """Between the action and the plant: the action limit ``max_action`` in the input's unit (V
    for the Furuta motor, N for the N-MSD force; None: the system's default, 5 V / 20 N; actions
    are clipped to it), and an input delay of ``delay`` seconds (a multiple of the timestep) plus
    ``delay_steps`` control periods."""

    max_action: float | None = None
    delay: float = 0.0
    delay_steps: int = 0

    def __post_init__(self):
        if self.max_action is not None:
            limit = _number(self.max_action)
            if not (math.isfinite(limit) and limit > 0):
                raise EnvArgumentError(
                    f"Actuation.max_action (the action limit) must be a positive finite number, got {self.max_action!r}"
                )
            _set(self, max_action=limit)
        if not (_number(self.delay) >= 0 and math.isfinite(self.delay)):
            raise EnvArgumentError(f"Actuation.delay must be a delay in seconds >= 0, got {self.delay!r}")
        _set(self, delay=float(self.delay), delay_steps=check_int("Actuation.delay_steps", self.delay_steps, 0))


@dataclasses.dataclass(frozen=True)
class Spaces:
    """What the agent sees: the ``observation`` layout (``"raw"``: the state as integrated;
    ``"wrapped"``: angles in (−π, π]; ``"trig"``: each angle as (cos, sin)), the ``dtype`` of both
    spaces (``"float32"`` or ``"float64"``; physics is always float64) and ``normalize_action``
    (actions in [−1, 1], scaled to ±max_action)."""

    observation: str = "raw"
    dtype: str = "float64"
    normalize_action: bool = False

    def __post_init__(self):
        if self.observation not in OBSERVATIONS:
            raise EnvArgumentError(f"Spaces.observation must be one of {list(OBSERVATIONS)}, got {self.observation!r}")
        try:
            dtype = np.dtype(self.dtype)
        except TypeError:
            dtype = None
        if dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise EnvArgumentError(f"Spaces.dtype must be 'float32' or 'float64', got {self.dtype!r}")
        _set(self, dtype=dtype.name, normalize_action=_check_bool("Spaces.normalize_action", self.normalize_action))


@dataclasses.dataclass(frozen=True)
class Camera:
    """The rendered frame: ``width`` × ``height`` pixels."""

    width: int = 480
    height: int = 480

    def __post_init__(self):
        _set(self, width=check_int("Camera.width", self.width, 1), height=check_int("Camera.height", self.height, 1))


#: The plain keywords the envs took before their settings were objects: keyword -> (the env
#: keyword of its object, the object's field). Each env class adds its own (its action limit, its
#: task's keywords) in ``legacy_keywords``.
LEGACY_KEYWORDS: dict[str, tuple[str, str]] = {
    "effects": ("plant", "effects"),
    "randomize": ("plant", "randomize"),
    "frame_skip": ("episode", "frame_skip"),
    "episode_seconds": ("episode", "seconds"),
    "reset_noise_scale": ("episode", "reset_noise_scale"),
    "actuation_delay": ("actuation", "delay"),
    "actuation_delay_steps": ("actuation", "delay_steps"),
    "encoder_counts": ("sensors", "encoder_counts"),
    "position_resolution": ("sensors", "position_resolution"),
    "measurement_noise": ("sensors", "measurement_noise"),
    "velocity": ("sensors", "velocity"),
    "observation": ("spaces", "observation"),
    "dtype": ("spaces", "dtype"),
    "normalize_action": ("spaces", "normalize_action"),
    "width": ("camera", "width"),
    "height": ("camera", "height"),
}

#: each settings keyword's object type
SETTINGS_TYPES: dict[str, type] = {
    "plant": Plant,
    "episode": Episode,
    "actuation": Actuation,
    "sensors": Sensors,
    "spaces": Spaces,
    "camera": Camera,
}


def _as_settings(name: str, value: Any, kind: type | None, owner: str):
    """``value`` of the env keyword ``name`` as its settings object (None: the default)."""
    if kind is None:
        if value is not None:
            raise EnvArgumentError(f"{owner} has no {name} settings: pass {name}=None, got {value!r}")
        return None
    if value is None:
        return kind()
    if kind is Plant:
        return _as_plant(value)
    if not isinstance(value, kind):
        raise EnvArgumentError(f"{name} must be a furuta_gym.envs.{kind.__name__}(...), got {value!r}")
    return value


def _as_plant(value: Any) -> Plant:
    """``plant=``: a Plant; a diagnosis (anything with a ``plant()`` method); a plant, diagnosis or
    MJCF file (a path, or a name ending in .json / .xml); or preset names."""
    if isinstance(value, Plant):
        return value
    if callable(getattr(value, "plant", None)):
        return value.plant()
    if isinstance(value, os.PathLike) or (isinstance(value, str) and value.lower().endswith((".json", ".xml"))):
        return Plant.load(value)
    if isinstance(value, str) or isinstance(value, Sequence):
        return Plant(presets=value)
    raise EnvArgumentError(
        f"plant must be a furuta_gym.envs.Plant(...), a diagnosis, a file or preset names; got {value!r}"
    )


def settings_from_keywords(
    owner: str,
    settings: dict[str, Any],
    types: Mapping[str, type | None],
    legacy: Mapping[str, Any],
    table: Mapping[str, tuple[str, str]],
) -> dict[str, Any]:
    """The env's settings objects: ``settings`` (env keyword -> object, None or a shorthand) checked
    against ``types``, with the plain ``legacy`` keywords of ``table`` applied on top of them
    (one DeprecationWarning naming the new spelling). An unknown keyword is an EnvArgumentError."""
    unknown = sorted(set(legacy) - set(table))
    if unknown:
        raise EnvArgumentError(
            f"{owner}: unknown keyword argument(s) {unknown}; expected any of "
            f"{sorted(['dynamics', 'kernel', 'render_mode', *types])} (or the older {sorted(table)})"
        )
    out = {name: _as_settings(name, settings[name], types[name], owner) for name in types}
    fields: dict[str, dict[str, Any]] = {}
    for keyword, value in legacy.items():
        target, field = table[keyword]
        fields.setdefault(target, {})[field] = value
    if fields:
        hints = [
            f"{target}={types[target].__name__}({', '.join(f'{k}={v!r}' for k, v in values.items())})"
            for target, values in fields.items()
        ]
        warnings.warn(
            f"{owner}: the keyword(s) {', '.join(k + '=' for k in legacy)} are deprecated; write "
            f"{', '.join(hints)} (furuta_gym.envs)",
            DeprecationWarning,
            stacklevel=_outside_stacklevel(),
        )
    for keyword, value in legacy.items():
        target, field = table[keyword]
        try:
            out[target] = dataclasses.replace(out[target] or types[target](), **{field: value})
        except EnvArgumentError as exc:
            raise EnvArgumentError(f"{keyword}={value!r}: {exc}") from None
    return out


#: the folders whose frames a deprecation warning skips to point at the user's line
_INTERNAL = tuple(os.path.dirname(str(m.__file__)) + os.sep for m in (gymnasium, sys.modules[__name__.split(".")[0]]))


def _outside_stacklevel() -> int:
    """The ``warnings.warn`` stacklevel, from its caller, of the first frame outside furuta_gym
    and Gymnasium: the user's line, whether the env was made directly, by ``gymnasium.make`` or
    by a vector env."""
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(_INTERNAL):
        frame, level = frame.f_back, level + 1
    return level
