"""From the true state to the observation: the sensor model, then the presentation.

:class:`Observer` holds what :class:`~furuta_gym.envs.Sensors` and
:class:`~furuta_gym.envs.Spaces` mean for one system: per-joint quantisation steps, noise per
component, the derivative filter's memory, the observation layout and its Box.
"""

from __future__ import annotations

import math
import types
from typing import Any, Callable

import numpy as np
from gymnasium import spaces

from ..lagrangian import SystemSpec
from ..signals import DerivativeFilter, quantize_joints
from ._settings import EnvArgumentError, Sensors, Spaces
from ._tasks import wrap_angle

__all__ = ["Observer", "present_components"]

# The float fast path of present_components: the single env presents a few Python floats.
_FLOATS = types.SimpleNamespace(cos=math.cos, sin=math.sin, clip=lambda v, lo, hi: min(max(v, lo), hi))


def present_components(z, angular, observation: str, bound: float, xp: Any = _FLOATS) -> list:
    """The components of a measured state ``z`` = (q, q̇) in the bounded layouts, as a list.

    "trig": each angle as (cos, sin); "wrapped": angles in (−π, π]; in both, the other components
    clipped to ±``bound``. ``z`` is a sequence of Python floats (``xp`` default) or of JAX/NumPy
    arrays with ``xp`` their namespace, so the single env and the functional JAX env present the
    state with the same code. ``angular``: one bool per joint.
    """
    n = len(angular)
    parts = []
    for j, is_angle in enumerate(angular):
        if is_angle and observation == "trig":
            parts += [xp.cos(z[j]), xp.sin(z[j])]
        elif is_angle:
            parts.append(wrap_angle(z[j]))
        else:
            parts.append(xp.clip(z[j], -bound, bound))
    return parts + [xp.clip(v, -bound, bound) for v in z[n : 2 * n]]


class Observer:
    """The observation of a system's true state (q, q̇) under ``sensors``, laid out as ``layout``
    says; ``dt`` is the control period the derivative filter runs at, ``random`` gives the
    generator the noise is drawn from (called only when there is noise to draw)."""

    def __init__(
        self, spec: SystemSpec, sensors: Sensors, layout: Spaces, dt: float, random: Callable[[], np.random.Generator]
    ):
        if layout.observation != "raw" and not any(spec.angular):
            raise EnvArgumentError(
                f"observation={layout.observation!r} wraps angles, but {spec.name} has no angular joint; "
                "use observation='raw'"
            )
        self.spec, self.n, self.random = spec, spec.n_dof, random
        self.quant = np.array(sensors.quantization(spec))
        self.noise = np.array(sensors.noise(spec))
        self.filter = (
            DerivativeFilter(dt, self.n, sensors.filter_omega0, sensors.filter_xi)
            if sensors.velocity == "filter"
            else None
        )
        self.exact_sensors = sensors.exact
        self.observation = layout.observation
        self.dtype = np.dtype(layout.dtype)
        #: components beyond ±state_bound are clipped in the bounded layouts (set by the task)
        self.state_bound = math.inf

    def is_the_state(self, extra_size: int) -> bool:
        """Whether the observation is the true state itself: exact sensors, the raw layout in
        float64 and nothing appended (``extra_size`` components after the state)."""
        return self.exact_sensors and self.observation == "raw" and self.dtype == np.float64 and not extra_size

    def reset(self, x: np.ndarray) -> None:
        """A new episode at ``x``: the derivative filter starts from the measured positions."""
        if self.filter is not None:
            self.filter.reset(self.measure_positions(x))

    def measure_positions(self, x: np.ndarray) -> np.ndarray:
        n = self.n
        q = x[:n].copy()
        if self.quant.any():
            q = quantize_joints(q, self.quant)
        if self.noise[:n].any():
            q = q + self.noise[:n] * self.random().standard_normal(n)
        return np.asarray(q)

    def measure(self, x: np.ndarray) -> np.ndarray:
        """Sensor model: quantised, noisy positions; exact or derivative-filtered velocities
        (from the measured positions), plus velocity noise."""
        if self.exact_sensors:
            return x.copy()
        n = self.n
        q = self.measure_positions(x)
        qd = self.filter(q) if self.filter is not None else x[n:].copy()
        if self.noise[n:].any():
            qd = qd + self.noise[n:] * self.random().standard_normal(n)
        return np.concatenate((q, qd))

    def present(self, z: np.ndarray, extra: list[float]) -> np.ndarray:
        """The measured state ``z`` = (q, q̇) plus ``extra`` components in the layout and dtype:
        "raw" as is; "wrapped" with angles in (−π, π]; "trig" with each angle as (cos, sin). In the
        last two, the other components are clipped to ±state_bound (beyond it the env diverges;
        only sensor noise can reach it), so the observation is always in the bounded space."""
        if self.observation == "raw":
            if extra:
                z = np.concatenate((z, extra))
            return z.astype(self.dtype, copy=False)
        parts = present_components(z.tolist(), self.spec.angular, self.observation, self.state_bound)
        return np.array(parts + extra, dtype=self.dtype)

    def space(self, extra: int) -> spaces.Box:
        """The Box of :meth:`present`'s output with ``extra`` appended components."""
        if self.observation == "raw":
            return spaces.Box(-np.inf, np.inf, (2 * self.n + extra,), dtype=self.dtype)
        bound, high = self.state_bound, []
        for angular in self.spec.angular:
            if angular and self.observation == "trig":
                high += [1.0, 1.0]
            else:
                high.append(math.pi if angular else bound)
        high = np.array(high + [bound] * self.n + [np.inf] * extra, dtype=self.dtype)
        return spaces.Box(-high, high, dtype=self.dtype)
