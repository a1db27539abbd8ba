"""Closed-loop rollouts of a controller against a Lagrangian-system plant, entirely in JAX.

Used for gain picking on the design model, tests and the benchmark's model plants. The plant is
integrated with fixed-step RK4 and the voltage held over each control period (``rk4_zoh_step``,
the same scheme as MuJoCo's RK4 integrator and the model-backed envs). An optional
:class:`Sensor` makes the observation measured-like: 2048-count encoder quantisation of both
angles and velocities from the paper's causal derivative filter (ω0 = 100 rad/s, ξ = 0.8),
instead of the exact state.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float
from scipy import signal

from ..envs.vector import scan_closed_loop
from ..lagrangian import AbstractLagrangianSystem
from ..signals import ENCODER_COUNTS_PER_REV, derivative_filter_coefficients, quantize_encoder
from ._base import AbstractController

__all__ = ["Sensor", "ClosedLoop", "closed_loop"]


class Sensor(eqx.Module):
    """Measured-like observation: quantised angles, filtered-derivative velocities."""

    counts_per_rev: int = eqx.field(static=True, default=ENCODER_COUNTS_PER_REV)
    omega0: float = eqx.field(static=True, default=100.0)
    xi: float = eqx.field(static=True, default=0.8)

    def coefficients(self, dt: float):
        """Bilinear-discretised F(s) = ω0² s / (s² + 2ξω0 s + ω0²), a[0] = 1."""
        return derivative_filter_coefficients(dt, self.omega0, self.xi)

    def quantize(self, angles):
        return quantize_encoder(jnp.asarray(angles), self.counts_per_rev)


class ClosedLoop(NamedTuple):
    """One closed-loop trajectory at the control instants."""

    xs: Float[Array, "T+1 4"]  # true plant states, xs[0] = x0
    us: Float[Array, "T 1"]  # applied voltages
    obs: Float[Array, "T 4"]  # what the controller saw
    modes: Array  # controller state after each step (e.g. SwingUpLQR's mode), or zeros


class _SensorObserver(eqx.Module):
    """A :class:`Sensor` at a control period: quantise the angles, filter them into velocities
    (direct form II transposed, one sample per joint), starting at rest at the first sample."""

    sensor: Sensor
    dt: float = eqx.field(static=True)

    def _filter(self):
        b, a = self.sensor.coefficients(self.dt)
        return jnp.asarray(b), jnp.asarray(a), jnp.asarray(signal.lfilter_zi(b, a))

    def init(self, x0):
        _, _, zi = self._filter()
        # the filter's steady state for a constant (quantised) first sample
        return zi[:, None] * self.sensor.quantize(x0[:2])[None, :]

    def observe(self, x, z):
        b, a, _ = self._filter()
        q = self.sensor.quantize(x[:2])
        v = b[0] * q + z[0]
        z_new = jnp.stack([b[1] * q - a[1] * v + z[1], b[2] * q - a[2] * v])
        return jnp.concatenate([q, v]), z_new


def closed_loop(
    controller: AbstractController,
    plant: AbstractLagrangianSystem,
    x0: Float[Array, " 4"],
    steps: int,
    dt: float = 1.0 / 500.0,
    substeps: int = 1,
    sensor: Sensor | None = None,
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
        observer=None if sensor is None else _SensorObserver(sensor, float(dt)),
        record=True,
    )
    modes = jnp.zeros(int(steps), dtype=jnp.int32) if isinstance(cstates, tuple) else cstates.astype(jnp.int32)
    return ClosedLoop(out.states, out.actions, obs, modes)
