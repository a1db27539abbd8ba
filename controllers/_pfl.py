"""Collocated partial feedback linearisation (Spong 1996) for any Lagrangian-system model.

Paper, appendix "Controller Design": the rotor torque is chosen so that the actuated joint obeys
α̈ = ū exactly *on the design model*, leaving the pendulum with

    M22 β̈ + (∂²L/∂q∂q̇ q̇)_2 − (∂L/∂q)_2 − τ_NC,2 = −M21 ū.

Everything is computed from the protocol by autodiff (``furuta_gym.lagrangian``): the mass matrix,
the Coriolis force ``(∂²L/∂q∂q̇) q̇``, the potential-derived force ``∂L/∂q`` and ``τ_NC``. The
torque is turned into a voltage by inverting the model's input map ``τ_u(q, q̇, u)``, which is
affine in ``u`` (for the QUBE: ``(kt/Rm)(u − km α̇)``, back-EMF included): its gain
``∂τ_u/∂u`` and offset ``τ_u(q, q̇, 0)`` are read off the model, never assumed.

For generality the input map may act on every joint (a learned model may put a small input force
on the pendulum); then the voltage solves ``e_αᵀ M⁻¹ (τ_u(u) + h) = ū`` which reduces to Spong's
collocated formula when ``τ_u = (τ, 0)``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..lagrangian import AbstractLagrangianSystem, coriolis_force, potential_derived_force

__all__ = ["InputMap", "input_map", "pfl_torque", "pfl_voltage", "ACTUATED_JOINT"]

ACTUATED_JOINT = 0  # the rotor α; the pendulum β is unactuated


class InputMap(NamedTuple):
    """τ_u(q, q̇, u) = gain · u + offset at one state (the input map is affine in u)."""

    gain: Float[Array, "n m"]
    offset: Float[Array, " n"]


def input_map(model: AbstractLagrangianSystem, q, qd) -> InputMap:
    """Gain ∂τ_u/∂u and offset τ_u(q, q̇, 0) of the model's input force at (q, q̇).

    The offset carries the back-EMF term (−kt·km/Rm·α̇ for the QUBE).
    """
    m = model.spec.n_inputs
    u0 = jnp.zeros((m,), dtype=jnp.result_type(q, float))
    offset = model.input_force(q, qd, u0)
    gain = jax.jacfwd(lambda u_: model.input_force(q, qd, u_))(u0)
    return InputMap(gain=gain, offset=offset)


def _drift_force(model, q, qd):
    """h = ∂L/∂q + τ_NC − (∂²L/∂q∂q̇) q̇: everything but inertia and input in the EL equation."""
    return potential_derived_force(model, q, qd) + model.nonconservative_force(q, qd) - coriolis_force(model, q, qd)


def pfl_torque(model: AbstractLagrangianSystem, q, qd, ubar) -> Float[Array, ""]:
    """Rotor generalized force τ_α that gives α̈ = ū when the pendulum is unforced (Spong 1996).

    From the pendulum row, β̈ = (h_β − M_βα ū) / M_ββ; the rotor row then needs
    τ_α = M_αα ū + M_αβ β̈ − h_α, with h = ∂L/∂q + τ_NC − Coriolis. Provided for inspection and
    tests; :func:`pfl_voltage` is what the controllers use.
    """
    M = model.mass_matrix(q)
    h = _drift_force(model, q, qd)
    a, p = ACTUATED_JOINT, 1 - ACTUATED_JOINT
    betadd = (h[p] - M[p, a] * ubar) / M[p, p]
    return M[a, a] * ubar + M[a, p] * betadd - h[a]


def pfl_voltage(
    model: AbstractLagrangianSystem,
    x: Float[Array, " 2n"],
    ubar,
    voltage_limit: float | None = None,
) -> Float[Array, ""]:
    """The voltage that makes α̈ = ū on ``model`` at state ``x`` = (q, q̇), clipped to
    ±``voltage_limit`` when given (then α̈ = ū only while unsaturated).

    Solves e_αᵀ M⁻¹ (G u + τ_u(q, q̇, 0) + h) = ū for the scalar input u, where G = ∂τ_u/∂u;
    with a collocated input map this is exactly u = (τ_α − offset_α) / G_α, τ_α from
    :func:`pfl_torque`.
    """
    n = model.spec.n_dof
    q, qd = x[:n], x[n:]
    M = model.mass_matrix(q)
    h = _drift_force(model, q, qd)
    imap = input_map(model, q, qd)
    Minv_row = jnp.linalg.solve(M, jnp.eye(n, dtype=M.dtype)[ACTUATED_JOINT])  # M symmetric
    accel_at_zero = Minv_row @ (imap.offset + h)
    accel_per_volt = Minv_row @ imap.gain[:, 0]
    u = (ubar - accel_at_zero) / accel_per_volt
    return u if voltage_limit is None else jnp.clip(u, -voltage_limit, voltage_limit)
