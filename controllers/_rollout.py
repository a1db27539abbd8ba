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
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float
from scipy import signal

from ..lagrangian import AbstractLagrangianSystem
from ..signals import ENCODER_COUNTS_PER_REV, derivative_filter_coefficients, quantize_encoder
from ..simulate import rk4_zoh_step
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
    over ``x0`` for a batch). The controller state starts at ``controller.init_state()``."""
    x0 = jnp.asarray(x0, dtype=float)
    if sensor is None:

        def observe(x, z):
            return x, z

        z0 = jnp.zeros((2, 2))
    else:
        b_np, a_np = sensor.coefficients(dt)
        zi = jnp.asarray(signal.lfilter_zi(b_np, a_np))
        b, a = jnp.asarray(b_np), jnp.asarray(a_np)

        def observe(x, z):
            q = sensor.quantize(x[:2])
            # direct form II transposed, one sample per channel (α, β)
            v = b[0] * q + z[0]
            z_new = jnp.stack([b[1] * q - a[1] * v + z[1], b[2] * q - a[2] * v])
            return jnp.concatenate([q, v]), z_new

        # start at rest at the first (quantised) sample: the filter's steady state for constant q
        q0 = sensor.quantize(x0[:2])
        z0 = zi[:, None] * q0[None, :]

    def one(carry, _):
        x, cstate, z = carry
        o, z = observe(x, z)
        u, cstate = controller.step(cstate, o)
        x_next = rk4_zoh_step(plant, x, u, dt, substeps)
        mode = jnp.asarray(cstate if not isinstance(cstate, tuple) else 0, dtype=jnp.int32)
        return (x_next, cstate, z), (x_next, u, o, mode)

    _, (xs, us, obs, modes) = jax.lax.scan(
        one, (x0, controller.init_state(), z0), None, length=steps
    )
    return ClosedLoop(jnp.concatenate([x0[None], xs]), us, obs, modes)
