"""The sensor model, one settings type for every layer that measures a state.

:class:`Sensors` says how a true state (q, q̇) becomes a measured one: joint positions quantised
(encoder counts on angles, a resolution on other joints), Gaussian noise, and the velocity either
exact or estimated by the paper's derivative filter on the measured positions. The envs
(``sensors=Sensors(...)``), the data generation (:mod:`furuta_gym.training.datagen`,
``generate(..., sensor=Sensors(...), sensor_rate_hz=...)``) and the controllers' closed-loop rollouts
(``closed_loop(..., sensor=Sensors(...))``) read the same object; each applies it with the
arithmetic its setting needs (NumPy step by step, over a whole log, or inside a JAX scan) through
the one quantiser (:func:`furuta_gym.signals.quantize_joints`) and the one filter
(:func:`furuta_gym.signals.derivative_filter_coefficients`).

It lives in the spine, below the envs, training and controllers that share it, with the checks
its fields need and their error, :class:`SettingsError` (the envs' ``EnvArgumentError``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from .lagrangian import SystemSpec
from .signals import ENCODER_COUNTS_PER_REV

__all__ = ["Sensors", "SettingsError", "check_int", "as_number", "set_fields", "VELOCITY_ESTIMATES"]

#: the accepted ``Sensors(velocity=...)`` values
VELOCITY_ESTIMATES = ("exact", "filter")


class SettingsError(ValueError, TypeError):
    """A bad settings field, constructor keyword or reset option (a ValueError and, like Python's
    own unknown-keyword error, a TypeError); the envs call it ``EnvArgumentError``."""


def check_int(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int >= ``minimum`` (bools refused), or a SettingsError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise SettingsError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def as_number(value: Any) -> float:
    """``value`` as a float, NaN when it is not a real number (bools and strings are not)."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def set_fields(obj, **values) -> None:
    """Normalise fields of a frozen dataclass in its ``__post_init__``."""
    for name, value in values.items():
        object.__setattr__(obj, name, value)


def _numeric(value: Any) -> bool:
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return not isinstance(value, (bool, str))


def _positive(name: str, value: Any) -> float:
    number = as_number(value)
    if not (math.isfinite(number) and number > 0):
        raise SettingsError(f"Sensors.{name} must be > 0, got {value!r}")
    return number


@dataclasses.dataclass(frozen=True)
class Sensors:
    """The sensor model: angles quantised to 2π/``encoder_counts`` (None: exact; the QUBE has
    2048), other positions to ``position_resolution`` (joint units), Gaussian
    ``measurement_noise`` std (a scalar for every component, a (positions, velocities) pair, or
    one per observation component q…, q̇…), and the observed ``velocity``: ``"exact"`` or
    ``"filter"`` (the paper's derivative filter F(s) = ω0² s / (s² + 2ξω0 s + ω0²) on the
    measured positions, ω0 = ``filter_omega0`` rad/s, ξ = ``filter_xi``)."""

    encoder_counts: int | None = None
    position_resolution: float | None = None
    measurement_noise: float | Sequence[float] = 0.0
    velocity: str = "exact"
    filter_omega0: float = 100.0
    filter_xi: float = 0.8

    def __post_init__(self):
        if self.encoder_counts is not None:
            set_fields(self, encoder_counts=check_int("Sensors.encoder_counts", self.encoder_counts, 1))
        if self.position_resolution is not None:
            set_fields(self, position_resolution=_positive("position_resolution", self.position_resolution))
        noise = self.measurement_noise
        values = np.asarray(noise, dtype=float) if np.ndim(noise) in (0, 1) and _numeric(noise) else None
        if values is None or values.size == 0 or not np.all(np.isfinite(values)) or np.any(values < 0):
            raise SettingsError(
                f"Sensors.measurement_noise must be a standard deviation >= 0, scalar or one per "
                f"observation component; got {noise!r}"
            )
        set_fields(self, measurement_noise=float(values) if values.ndim == 0 else tuple(values.tolist()))
        if self.velocity not in VELOCITY_ESTIMATES:
            raise SettingsError(
                f"Sensors.velocity must be 'exact' (true velocity) or 'filter' (the paper's derivative "
                f"filter on the measured positions); got {self.velocity!r}"
            )
        set_fields(
            self,
            filter_omega0=_positive("filter_omega0", self.filter_omega0),
            filter_xi=_positive("filter_xi", self.filter_xi),
        )

    @classmethod
    def qube(cls, **changes) -> "Sensors":
        """The QUBE-Servo 2's: 2048-count encoders, velocities from the derivative filter."""
        return cls(**{"encoder_counts": ENCODER_COUNTS_PER_REV, "velocity": "filter", **changes})

    def quantization(self, spec: SystemSpec) -> tuple[float, ...]:
        """Quantisation step per joint of ``spec`` (rad or m; 0: exact)."""
        quant = np.zeros(spec.n_dof)
        if self.encoder_counts is not None:
            if not any(spec.angular):
                raise SettingsError(
                    f"encoder_counts quantises angles, but {spec.name} has no angular joint; "
                    "use position_resolution (in joint units)"
                )
            quant[list(spec.angular)] = 2.0 * math.pi / self.encoder_counts
        if self.position_resolution is not None:
            quant[[not a for a in spec.angular]] = self.position_resolution
        return tuple(float(q) for q in quant)

    def noise(self, spec: SystemSpec) -> tuple[float, ...]:
        """Noise std per observation component (q, q̇) of ``spec``."""
        noise = np.asarray(self.measurement_noise, dtype=float)
        n = spec.n_dof
        if noise.size == 2 and n != 1:  # (positions, velocities); with one joint the same thing
            noise = np.repeat(noise, n)
        if noise.size not in (1, 2 * n):
            raise SettingsError(
                f"measurement_noise must be a standard deviation >= 0, scalar, a (positions, velocities) "
                f"pair or one per observation component {spec.state_names}; got {self.measurement_noise!r}"
            )
        return tuple(float(s) for s in np.broadcast_to(noise, (2 * n,)))

    @property
    def quantizes(self) -> bool:
        """Some joint's position is quantised."""
        return self.encoder_counts is not None or self.position_resolution is not None

    @property
    def exact(self) -> bool:
        """The observation is the true state."""
        return not self.quantizes and not np.any(self.measurement_noise) and self.velocity == "exact"
