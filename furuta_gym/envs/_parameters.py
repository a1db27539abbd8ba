"""Physical parameters as plain floats, domain randomisation, and plant variants.

The analytic models' parameter classes (:class:`~furuta_gym.models.FurutaParameters`,
:class:`~furuta_gym.models.NMSDParameters`) are the single source of the pinned values; this
module reads their *defaults* without constructing JAX arrays, so a MuJoCo-only env never touches
JAX's configuration.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..effects import Effect
from ..models import SYSTEM_DEFINITIONS, parameter_defaults, system_definition
from ..systems import get_spec

__all__ = [
    "PARAMETER_CLASSES",
    "default_parameters",
    "parse_randomization",
    "randomize_parameters",
    "resolve_effects",
]

PARAMETER_CLASSES = {name: d.parameters for name, d in SYSTEM_DEFINITIONS.items()}

# Parameters a relative spread applies to when `randomize` is a single number. Gravity is a fact
# of the lab, not of the device, so it is left out (name it explicitly to randomise it).
_NOT_RANDOMISED_BY_DEFAULT = ("g",)


def default_parameters(system: str) -> dict[str, float]:
    """The pinned physical parameters of ``"furuta"`` or ``"nmsd"`` as ``{name: float}``."""
    return parameter_defaults(system_definition(system).parameters)


def parse_randomization(system: str, randomize) -> dict[str, float]:
    """Normalise the ``randomize`` kwarg to ``{parameter: relative spread}``.

    ``None``/``0`` → no randomisation; a number s → every parameter but g drawn uniformly in
    [(1 − s)·p, (1 + s)·p]; a mapping → only the named parameters, each with its own spread.
    """
    names = list(default_parameters(system))
    if randomize is None:
        return {}
    if isinstance(randomize, (int, float, np.floating)) and not isinstance(randomize, bool):
        spreads = {n: float(randomize) for n in names if n not in _NOT_RANDOMISED_BY_DEFAULT}
    elif isinstance(randomize, Mapping):
        unknown = sorted(set(randomize) - set(names))
        if unknown:
            raise ValueError(f"randomize: unknown {system} parameter(s) {unknown}; expected names among {names}")
        spreads = {str(k): float(v) for k, v in randomize.items()}
    else:
        raise ValueError(
            f"randomize must be None, a relative spread (float) or a mapping {{parameter: spread}}; got {randomize!r}"
        )
    for name, s in spreads.items():
        if not (np.isfinite(s) and 0.0 <= s < 1.0):
            raise ValueError(f"randomize[{name!r}] must be a relative spread in [0, 1); got {s}")
    return {n: s for n, s in spreads.items() if s > 0.0}


def randomize_parameters(
    nominal: Mapping[str, float], spreads: Mapping[str, float], rng: np.random.Generator
) -> dict[str, float]:
    """Draw each parameter in ``spreads`` uniformly in [(1 − s)·p, (1 + s)·p] (names sorted, so
    the draw depends only on the seed)."""
    out = dict(nominal)
    for name in sorted(spreads):
        out[name] = nominal[name] * (1.0 + spreads[name] * rng.uniform(-1.0, 1.0))
    return out


def resolve_effects(
    system: str, plant, effects: Sequence[Effect] | None, presets: Mapping[str, Sequence[Effect]]
) -> tuple[Effect, ...]:
    """Combine a named ``plant`` preset of ``presets`` (or a list of names) with explicit ``effects``."""
    spec = get_spec(system)
    names = [] if plant is None else [plant] if isinstance(plant, str) else list(plant)
    out: list[Effect] = []
    for name in names:
        if name not in presets:
            raise ValueError(f"unknown plant {name!r} for {system}; expected one of {sorted(presets)}")
        out.extend(presets[name])
    for e in effects or ():
        if not isinstance(e, Effect):
            raise ValueError(f"effects must be furuta_gym.effects.Effect objects, got {type(e).__name__}: {e!r}")
        out.append(e)
    for e in out:
        if not e.kind.on_input:
            e.joint_index(spec)  # clear error for a joint the system lacks
        elif e.kind.input_dynamics and e.coefficient < 0:
            raise ValueError(f"{e.name} must be >= 0 s, got {e.coefficient}")
    return tuple(out)
