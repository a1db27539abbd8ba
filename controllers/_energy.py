"""Energy-based swing-up through partial feedback linearisation (paper appendix, eq. 19).

    ū = k_e · (V(β) − V(π)) · sgn(s · cos β · β̇)  −  k_α · α − d_α · α̇,

with V the *design model's* potential (the paper's variant of Åström & Furuta 2000: the
potential, not the total energy, because V(π) singles out the upright configuration), s the sign
of the model's coupling M_αβ at the hanging rest (+1 with the pinned convention, read from the
model so that a model with the other β sign still pumps), and u = PFL⁻¹(ū) clipped at the voltage
limit. Why it pumps: with α̈ = ū the pendulum's energy changes as dE_β/dt ≈ −M_βα β̇ ū, and
V(β) − V(π) ≤ 0 below the upright, so ū always opposes sgn(M_βα β̇) and fades out as β → π.

Two additions the paper leaves implicit:

* **First push.** At exact rest sgn(cos β · β̇) = 0 and nothing would move; we define
  sgn(0) := ``push`` (+1 by default), i.e. at rest the rotor is pushed with the full energy-law
  magnitude k_e·(V(π) − V(0)) in the −push·α direction. Quantised encoders at rest read β̇ = 0
  exactly, so this is also what starts a real unit.
* **Centring.** A PD term −k_α α − d_α α̇ on the rotor acceleration keeps the arm from running
  away (without it the rotor drifts by several radians during the pump). It is small against the
  pumping term (which saturates the 5 V limit) and its peak travel is reported by the benchmark.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..lagrangian import AbstractLagrangianSystem
from ._base import AbstractController
from ._pfl import pfl_voltage

__all__ = [
    "EnergySwingUp",
    "model_state",
    "upright_potential",
    "default_k_e",
    "DEFAULT_PUMP_ACCELERATION",
]

UPRIGHT = jnp.pi

#: Rotor acceleration (rad/s²) the energy law commands at the hanging position, before centring:
#: k_e·(V(π) − V(0)). 150 rad/s² saturates the 5 V QUBE motor from rest and sits a factor ≈ 2
#: above the gain where the pump stalls (k_e ≈ 2 500 ↔ 76 rad/s², BENCHMARKS.md).
DEFAULT_PUMP_ACCELERATION = 150.0


def model_state(obs: Float[Array, " 4"]) -> Float[Array, " 4"]:
    """The state fed to the design model: β wrapped to [−π/2, 3π/2) so that both the hanging
    (0) and the upright (π) configurations are interior — a learned model is then always queried
    where it was trained, whatever the unwrapped β the env reports. α is never wrapped."""
    beta = jnp.mod(obs[1] + 0.5 * jnp.pi, 2.0 * jnp.pi) - 0.5 * jnp.pi
    return obs.at[1].set(beta)


def upright_potential(model: AbstractLagrangianSystem) -> Float[Array, ""]:
    """V(α = 0, β = π) of the model."""
    return model.potential(jnp.array([0.0, UPRIGHT]))


def sign_with_push(x, push):
    """sgn(x) with sgn(0) := push (the defined first push at exact rest)."""
    return jnp.where(x > 0, 1.0, jnp.where(x < 0, -1.0, push))


@eqx.filter_jit
def _design_constants(model):
    """V(π) and the sign of the coupling M_αβ at the hanging rest (one compilation)."""
    m_ab = model.mass_matrix(jnp.zeros(2))[0, 1]
    return upright_potential(model), jnp.where(m_ab >= 0, 1.0, -1.0)


def default_k_e(model: AbstractLagrangianSystem) -> float:
    """k_e = DEFAULT_PUMP_ACCELERATION / (V(π) − V(0)) of ``model``: the same commanded pump
    whatever the units or scale of the model's potential (4 939 for the analytic QUBE model,
    whose V(π) − V(0) = 0.0304 J). Raises ``ValueError`` if the model's upright is not above its
    hanging position (no energy to pump towards)."""
    dV = float(_potential_rise(model))
    if not dV > 0:
        raise ValueError(
            f"the model's potential is not higher upright than hanging (V(pi) - V(0) = {dV:g}); "
            "cannot derive a default k_e — give k_e explicitly"
        )
    return DEFAULT_PUMP_ACCELERATION / dV


@eqx.filter_jit
def _potential_rise(model):
    return upright_potential(model) - model.potential(jnp.zeros(2))


class EnergySwingUp(AbstractController):
    """Energy swing-up ū = k_e (V(β) − V(π)) sgn(cos β β̇) − k_α α − d_α α̇, through PFL.

    ``k_e`` is in rad/s² per joule of the design model's potential; ``None`` (default) takes
    :func:`default_k_e` (see docs/control.md; the paper's values are tied to its units and don't
    carry over).
    """

    model: AbstractLagrangianSystem
    k_e: Float[Array, ""]
    k_alpha: Float[Array, ""]
    d_alpha: Float[Array, ""]
    V_up: Float[Array, ""]
    coupling_sign: Float[Array, ""]
    push: float = eqx.field(static=True)
    voltage_limit: float = eqx.field(static=True)

    def __init__(
        self,
        model: AbstractLagrangianSystem,
        k_e: float | None = None,
        k_alpha: float = 10.0,
        d_alpha: float = 2.0,
        voltage_limit: float = 5.0,
        push: float = 1.0,
    ):
        if model.spec.n_dof != 2 or model.spec.n_inputs != 1:
            raise ValueError(
                f"model must be a Furuta-like system (2 joints, 1 input), got {model.spec.name} "
                f"with {model.spec.n_dof} joints and {model.spec.n_inputs} inputs"
            )
        if not voltage_limit > 0:
            raise ValueError(f"voltage_limit must be > 0 V, got {voltage_limit}")
        if push not in (1.0, -1.0):
            raise ValueError(f"push must be +1 or -1, got {push}")
        self.model = model
        self.k_e = jnp.asarray(default_k_e(model) if k_e is None else k_e, dtype=float)
        self.k_alpha = jnp.asarray(k_alpha, dtype=float)
        self.d_alpha = jnp.asarray(d_alpha, dtype=float)
        self.V_up, self.coupling_sign = _design_constants(model)
        self.push = float(push)
        self.voltage_limit = float(voltage_limit)

    def desired_acceleration(self, obs: Float[Array, " 4"]) -> Float[Array, ""]:
        """ū, the rotor acceleration the energy law asks for (before PFL and saturation)."""
        x = model_state(obs)
        beta, betad = x[1], x[3]
        # V(β) as the paper writes it: the potential at α = 0. A rotor spring's ½kα² (the
        # QUBE's cable) is no pendulum energy: in V(α, β) it flips the pump's sign near the top
        dV = self.model.potential(jnp.stack([jnp.zeros_like(beta), beta])) - self.V_up
        s = sign_with_push(self.coupling_sign * jnp.cos(beta) * betad, self.push)
        return self.k_e * dV * s - self.k_alpha * obs[0] - self.d_alpha * obs[2]

    def step(self, state, obs):
        obs = jnp.asarray(obs, dtype=float)
        ubar = self.desired_acceleration(obs)
        u = pfl_voltage(self.model, model_state(obs), ubar)
        u = jnp.clip(u, -self.voltage_limit, self.voltage_limit)
        return jnp.reshape(u, (1,)), state
