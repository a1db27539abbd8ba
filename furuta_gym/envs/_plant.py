"""A rig as a simulator: a system's lumped parameters and the effects a diagnosis found, for
MuJoCo (``MujocoBackend(plant=...)``), an env (``plant=``) and an MJCF file for other tools
(:func:`save_mjcf`)."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import mujoco

from ..effects import Effect
from ..models import system_definition
from ..systems import get_spec

__all__ = ["Plant", "PLANT_TEXT"]

#: the name of the MJCF ``<custom><text>`` element that holds a plant, as JSON, for furuta-gym
PLANT_TEXT = "furuta_gym_plant"


@dataclasses.dataclass(frozen=True)
class Plant:
    """A system's plant: its lumped parameters (the names of the system's lumped form, e.g. the
    Furuta's J1, J1b, Jc, J2, G, c_alpha, c_beta, K) and its effects (:mod:`furuta_gym.effects`,
    input delay and lag included). ``source`` says where it came from (a diagnosis, a file).

    ``MujocoBackend(system, plant=...)`` and the envs' ``plant=`` simulate it: the lumped values
    become bodies, inertias and native terms (the system's ``write_lumped_mujoco``), and each
    effect its own MuJoCo form (native term, or the passive-force callback).
    """

    system: str
    lumped: Mapping[str, float]
    effects: tuple[Effect, ...] = ()
    source: str = ""

    def __post_init__(self):
        spec = get_spec(self.system)
        object.__setattr__(self, "system", spec.name)
        names = system_definition(spec).lumped.names
        missing, unknown = sorted(set(names) - set(self.lumped)), sorted(set(self.lumped) - set(names))
        if missing or unknown:
            raise ValueError(f"Plant({spec.name!r}): lumped parameters must be exactly {list(names)}; "
                             f"missing {missing}, unknown {unknown}")
        object.__setattr__(self, "lumped", {k: float(self.lumped[k]) for k in names})
        effects = tuple(self.effects)
        for e in effects:
            if not isinstance(e, Effect):
                raise ValueError(f"Plant effects must be furuta_gym.effects.Effect objects, got {e!r}")
            if not e.kind.on_input:
                e.joint_index(spec)
        object.__setattr__(self, "effects", effects)

    @classmethod
    def nominal(cls, system: str, effects: Sequence[Effect] = ()) -> "Plant":
        """The pinned model's plant (its lumped values), with ``effects``."""
        return cls(system, system_definition(system).lumped.nominal(), tuple(effects), "nominal")

    # ------------------------------------------------------------------ JSON and files

    def to_json(self) -> dict[str, Any]:
        return {"system": self.system, "lumped": dict(self.lumped), "source": self.source,
                "effects": [_effect_json(e) for e in self.effects]}

    @classmethod
    def from_json(cls, doc: Mapping[str, Any], where: str = "plant") -> "Plant":
        try:
            effects = tuple(Effect(**e) for e in doc.get("effects", ()))
            return cls(doc["system"], doc["lumped"], effects, doc.get("source", ""))
        except (KeyError, TypeError) as err:
            raise ValueError(f"{where}: not a plant ({{'system', 'lumped', 'effects'}} expected): {err}") from None

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Plant":
        """A plant from a diagnosis JSON (its ``"plant"``), a plant JSON, or an MJCF file that
        :func:`save_mjcf` wrote (its ``<custom>`` text)."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"plant file {path} does not exist")
        if path.suffix.lower() == ".xml":
            model = mujoco.MjModel.from_xml_path(str(path))
            text = _custom_text(model, PLANT_TEXT)
            if text is None:
                raise ValueError(f"{path}: no <custom><text name={PLANT_TEXT!r}> element: not an MJCF "
                                 "written by furuta-gym (plain MuJoCo loads it, without the effects MJCF lacks)")
            return cls.from_json(json.loads(text), str(path))
        try:
            doc = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(f"{path}: not JSON ({err})") from None
        if isinstance(doc, dict) and "plant" in doc:
            doc = doc["plant"]
        return cls.from_json(doc, str(path))


def _effect_json(e: Effect) -> dict[str, Any]:
    out = {"name": e.name, "joint": e.joint, "coefficient": float(e.coefficient)}
    defaults = {f.name: f.default for f in dataclasses.fields(Effect) if f.name not in out}
    out.update({k: float(getattr(e, k)) for k, d in defaults.items() if getattr(e, k) != d})
    return out


def _custom_text(model: mujoco.MjModel, name: str) -> str | None:
    """The data of the ``<custom><text>`` called ``name``, or None."""
    for i in range(model.ntext):
        if mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TEXT, i) == name:
            start, size = int(model.text_adr[i]), int(model.text_size[i])
            return bytes(model.text_data[start : start + size]).rstrip(b"\0").decode()
    return None
