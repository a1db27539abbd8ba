"""The envs' validated sensor and actuation settings, shared by the single and the vector env.

:class:`Sensors` is what the observation carries (quantisation, noise, which velocity);
:class:`Actuation` what stands between the action and the plant (a delay, an actuator lag).
Both are built once from the env's keywords, each bad keyword named in one
:class:`EnvArgumentError`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from ..effects import Effect, actuator_lag_time
from ..lagrangian import SystemSpec

__all__ = ["EnvArgumentError", "check_int", "Sensors", "Actuation"]


class EnvArgumentError(ValueError, TypeError):
    """A bad constructor keyword or reset option (a ValueError and, like Python's own unknown-
    keyword error, a TypeError)."""


def check_int(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int >= ``minimum`` (bools refused), or an EnvArgumentError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise EnvArgumentError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def substeps_of_delay(seconds: float, timestep: float, what: str) -> int:
    """Delay in seconds → whole RK4 substeps (it must be a multiple of the timestep)."""
    if not (np.isfinite(seconds) and seconds >= 0):
        raise EnvArgumentError(f"{what} must be a delay in seconds >= 0, got {seconds!r}")
    n = round(seconds / timestep)
    if abs(n * timestep - seconds) > 1e-9:
        raise EnvArgumentError(f"{what} = {seconds} s is not a multiple of the simulation timestep {timestep} s")
    return int(n)


@dataclasses.dataclass(frozen=True)
class Sensors:
    """The sensor model: ``quantization`` per joint (rad or m; 0 exact), Gaussian ``noise`` std per
    observation component, and the observed ``velocity`` (``"exact"`` or ``"filter"``: the
    paper's derivative filter on the measured positions)."""

    quantization: tuple[float, ...]
    noise: tuple[float, ...]
    velocity: str = "exact"

    @classmethod
    def from_arguments(cls, spec: SystemSpec, encoder_counts: int | None, position_resolution: float | None,
                       measurement_noise: float | Sequence[float], velocity: str) -> "Sensors":
        n = spec.n_dof
        quant = np.zeros(n)
        if encoder_counts is not None:
            counts = check_int("encoder_counts", encoder_counts, 1)
            if not any(spec.angular):
                raise EnvArgumentError(f"encoder_counts quantises angles, but {spec.name} has no angular joint; "
                                       "use position_resolution (in joint units)")
            quant[list(spec.angular)] = 2.0 * math.pi / counts
        if position_resolution is not None:
            res = float(position_resolution)
            if not (np.isfinite(res) and res > 0):
                raise EnvArgumentError(f"position_resolution must be > 0, got {position_resolution!r}")
            quant[[not a for a in spec.angular]] = res
        noise = (np.broadcast_to(np.asarray(measurement_noise, dtype=float), (2 * n,))
                 if np.ndim(measurement_noise) in (0, 1) and np.size(measurement_noise) in (1, 2 * n) else None)
        if noise is None or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise EnvArgumentError(
                f"measurement_noise must be a standard deviation >= 0, scalar or one per observation "
                f"component {spec.state_names}; got {measurement_noise!r}")
        if velocity not in ("exact", "filter"):
            raise EnvArgumentError(f"velocity must be 'exact' (true velocity) or 'filter' (the paper's derivative "
                                   f"filter on the measured positions); got {velocity!r}")
        return cls(tuple(float(x) for x in quant), tuple(float(x) for x in noise), velocity)

    @property
    def exact(self) -> bool:
        """The observation is the true state."""
        return not any(self.quantization) and not any(self.noise) and self.velocity == "exact"


@dataclasses.dataclass(frozen=True)
class Actuation:
    """Between the action and the plant: a delay of ``delay_substeps`` RK4 substeps (keywords plus
    an ``input_delay`` effect) and a first-order actuator lag of ``lag`` seconds (0: none)."""

    delay_substeps: int = 0
    lag: float = 0.0

    @classmethod
    def from_arguments(cls, effects: Sequence[Effect], timestep: float, frame_skip: int,
                       actuation_delay: float, actuation_delay_steps: int) -> "Actuation":
        steps = check_int("actuation_delay_steps", actuation_delay_steps, 0)
        delay = substeps_of_delay(float(actuation_delay), timestep, "actuation_delay") + steps * frame_skip
        for e in effects:
            if e.kind.input_dynamics == "delay":
                delay += substeps_of_delay(e.coefficient, timestep, "effect input_delay")
        return cls(delay, actuator_lag_time(effects))
