"""Closed-loop rollouts of a controller against a Lagrangian-system plant, entirely in JAX.

Used for gain picking on the design model, tests and the benchmark's model plants. The plant is
integrated with fixed-step RK4 and the voltage held over each control period (``rk4_zoh_step``,
the same scheme as MuJoCo's RK4 integrator and the model-backed envs). An optional
sensor (:class:`furuta_gym.sensors.Sensors`, the envs' and the data generation's sensor model;
:func:`Sensor` is the QUBE's: 2048-count encoder quantisation of both angles and velocities from
the paper's causal derivative filter, ω0 = 100 rad/s, ξ = 0.8) makes the observation
measured-like instead of the exact state.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float
from scipy import signal

from ..envs.vector import scan_closed_loop
from ..lagrangian import AbstractLagrangianSystem
from ..sensors import Sensors
from ..signals import ENCODER_COUNTS_PER_REV, derivative_filter_coefficients, quantize_joints
from ._base import AbstractController

__all__ = ["Sensor", "ClosedLoop", "closed_loop"]


def Sensor(counts_per_rev: int = ENCODER_COUNTS_PER_REV, omega0: float = 100.0, xi: float = 0.8) -> Sensors:
    """The QUBE's sensor as :class:`~furuta_gym.sensors.Sensors` (kept for its callers:
    ``closed_loop(..., sensor=Sensor())``): angles quantised to ``counts_per_rev`` counts, velocities
    from the derivative filter (ω0, ξ)."""
    return Sensors(encoder_counts=counts_per_rev, velocity="filter", filter_omega0=omega0, filter_xi=xi)


class ClosedLoop(NamedTuple):
    """One closed-loop trajectory at the control instants."""

    xs: Float[Array, "T+1 4"]  # true plant states, xs[0] = x0
    us: Float[Array, "T 1"]  # applied voltages
    obs: Float[Array, "T 4"]  # what the controller saw
    modes: Array  # controller state after each step (e.g. SwingUpLQR's mode), or zeros


class _SensorObserver(eqx.Module):
    """:class:`~furuta_gym.sensors.Sensors` at a control period, in JAX: quantise the positions
    (``steps`` per joint) and, with ``velocity="filter"``, filter them into velocities (direct form
    II transposed, one sample per joint), starting at rest at the first sample. No noise: a scan
    without a key draws none (``closed_loop`` refuses a noisy sensor)."""

    sensor: Sensors = eqx.field(static=True)
    steps: tuple[float, ...] = eqx.field(static=True)
    dt: float = eqx.field(static=True)

    def _filter(self):
        b, a = derivative_filter_coefficients(self.dt, self.sensor.filter_omega0, self.sensor.filter_xi)
        return jnp.asarray(b), jnp.asarray(a), jnp.asarray(signal.lfilter_zi(b, a))

    def _quantize(self, x):
        # one step for all joints as a scalar: the program (and its rounding) the loop always had
        steps = self.steps[0] if len(set(self.steps)) == 1 else self.steps
        return quantize_joints(jnp.asarray(x[: len(self.steps)]), steps)

    def init(self, x0):
        _, _, zi = self._filter()
        # the filter's steady state for a constant (quantised) first sample
        return zi[:, None] * self._quantize(x0)[None, :]

    def observe(self, x, z):
        q = self._quantize(x)
        if self.sensor.velocity == "exact":
            return jnp.concatenate([q, x[len(self.steps) :]]), z
        b, a, _ = self._filter()
        v = b[0] * q + z[0]
        z_new = jnp.stack([b[1] * q - a[1] * v + z[1], b[2] * q - a[2] * v])
        return jnp.concatenate([q, v]), z_new


def _observer(sensor: Sensors | None, plant: AbstractLagrangianSystem, dt: float) -> _SensorObserver | None:
    if sensor is None:
        return None
    if any(sensor.noise(plant.spec)):
        raise ValueError(
            f"closed_loop's sensor draws no noise (a JAX scan without a key); got measurement_noise="
            f"{sensor.measurement_noise!r}: use an env (furuta_gym.envs) for a noisy sensor"
        )
    return _SensorObserver(sensor, sensor.quantization(plant.spec), float(dt))


def closed_loop(
    controller: AbstractController,
    plant: AbstractLagrangianSystem,
    x0: Float[Array, " 4"],
    steps: int,
    dt: float = 1.0 / 500.0,
    substeps: int = 1,
    sensor: Sensors | None = None,
) -> ClosedLoop:
    """Run ``controller`` on ``plant`` for ``steps`` control periods from ``x0`` (jittable; vmap
    over ``x0`` for a batch). The controller state starts at ``controller.init_state()``.

    The loop is the envs' (:func:`furuta_gym.envs.vector.rollout`): the same controlled step, and a
    plant state that diverges (non-finite or beyond 1e6) is frozen at its last finite value, with
    zero voltage recorded from then on."""
    x0 = jnp.asarray(x0, dtype=float)
    out, obs, cstates = scan_closed_loop(
        plant,
        controller.step,
        x0,
        controller.init_state(),
        steps=int(steps),
        dt=float(dt),
        substeps=int(substeps),
        observer=_observer(sensor, plant, dt),
        record=True,
    )
    modes = jnp.zeros(int(steps), dtype=jnp.int32) if isinstance(cstates, tuple) else cstates.astype(jnp.int32)
    return ClosedLoop(out.states, out.actions, obs, modes)
