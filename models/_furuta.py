"""The Furuta pendulum (Quanser QUBE-Servo 2; Laiche et al. 2026, §5): its physics, written once,
and its :class:`~furuta_gym.models.SystemDefinition`.

Physical parameters are Equinox pytrees of float64 scalars, so they can be fitted with the same
machinery as network weights (``eqx.filter(model, eqx.is_inexact_array)``).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Mapping

import equinox as eqx
import jax
import jax.numpy as jnp

from ..lagrangian import AbstractLagrangianSystem, SystemSpec
from ..systems import FURUTA
from ._system import (
    Equilibrium,
    LumpedForm,
    MujocoTerms,
    RigidBodyCondition,
    SystemDefinition,
    check_rigid_bodies,
    parameter_defaults,
    scalar,
)

__all__ = [
    "FURUTA_DEFINITION",
    "FurutaParameters",
    "Furuta",
    "FurutaSharedTrig",
    "furuta_energy",
    "furuta_lumped",
    "furuta_mass_matrix",
    "furuta_potential",
]


class FurutaParameters(eqx.Module):
    """Quanser QUBE-Servo 2 rotary pendulum (docs/conventions.md; SI units, volts)."""

    mr: jnp.ndarray = eqx.field(default=0.095, converter=scalar)  # rotor arm mass, kg
    Lr: jnp.ndarray = eqx.field(default=0.085, converter=scalar)  # rotor arm length, m
    mp: jnp.ndarray = eqx.field(default=0.024, converter=scalar)  # pendulum mass, kg
    Lp: jnp.ndarray = eqx.field(default=0.129, converter=scalar)  # pendulum length, m
    g: jnp.ndarray = eqx.field(default=9.81, converter=scalar)  # gravity, m/s²
    c_r: jnp.ndarray = eqx.field(default=3e-4, converter=scalar)  # rotor viscous friction, N·m·s/rad
    c_p: jnp.ndarray = eqx.field(default=1.5e-5, converter=scalar)  # pendulum viscous friction
    kt: jnp.ndarray = eqx.field(default=0.042, converter=scalar)  # motor torque constant, N·m/A
    km: jnp.ndarray = eqx.field(default=0.042, converter=scalar)  # back-EMF constant, V·s/rad
    Rm: jnp.ndarray = eqx.field(default=8.4, converter=scalar)  # terminal resistance, Ω

    @property
    def Jr(self):
        """Rotor arm inertia about the motor axis, mr·Lr²/12 (Quanser's convention)."""
        return self.mr * self.Lr**2 / 12.0

    @property
    def Jp(self):
        """Pendulum inertia about its centre of mass, mp·Lp²/12."""
        return self.mp * self.Lp**2 / 12.0

    @property
    def J1(self):
        return self.Jr + self.mp * self.Lr**2

    @property
    def J2(self):
        return self.Jp + self.mp * self.Lp**2 / 4.0


class _FloatParameters:
    """Parameter values as plain floats, with :class:`FurutaParameters`' own derived inertias
    (its property objects), for arithmetic without JAX arrays."""

    Jr, Jp, J1, J2 = FurutaParameters.Jr, FurutaParameters.Jp, FurutaParameters.J1, FurutaParameters.J2

    def __init__(self, values: Mapping[str, float]):
        self.__dict__.update(values)


def furuta_lumped(p: FurutaParameters | Mapping[str, float]) -> dict[str, jnp.ndarray]:
    """The Furuta's M and V in the parameters they are linear in: J1 (Jr + mp·Lr²), J1b
    (¼mp·Lp², the sin²β term), Jc (½mp·Lr·Lp), J2 (Jp + ¼mp·Lp²), G (½mp·g·Lp). The
    diagnosis fits these (furuta_gym.diagnose). ``p``: parameters, or a mapping of plain floats
    (then the values are floats: the env's per-step energy touches no JAX)."""
    q: Any = _FloatParameters(p) if isinstance(p, Mapping) else p  # FurutaParameters' fields
    return {
        "J1": q.J1,
        "J1b": 0.25 * q.mp * q.Lp**2,
        "Jc": 0.5 * q.mp * q.Lr * q.Lp,
        "J2": q.J2,
        "G": 0.5 * q.mp * q.g * q.Lp,
    }


def _mass_entries(J1, J1b, Jc, sin_beta, cos_beta):
    """M11 and M12 of M(q) (M22 = J2 is constant)."""
    return J1 + J1b * sin_beta**2, Jc * cos_beta


def furuta_mass_matrix(J1, J1b, Jc, J2, q, sin=jnp.sin, cos=jnp.cos):
    """M(q) = [[J1 + J1b·sin²β, Jc·cosβ], [Jc·cosβ, J2]] (``sin``, ``cos``: see
    :class:`FurutaSharedTrig`)."""
    m11, m12 = _mass_entries(J1, J1b, Jc, sin(q[1]), cos(q[1]))
    return jnp.stack([jnp.stack([m11, m12]), jnp.stack([m12, J2 * jnp.ones_like(m11)])])


def furuta_potential(G, q, cos=jnp.cos):
    """V(q) = G·(1 − cosβ): β = 0 hanging down."""
    return G * (1.0 - cos(q[1]))


def furuta_energy(lumped: Mapping[str, float], x) -> float:
    """T + V at the state ``x`` = (α, β, α̇, β̇) on plain floats, from :func:`furuta_lumped`
    values: the envs' per-step ``info["energy"]``, where a JAX call would cost far more than the step."""
    _, beta, alpha_dot, beta_dot = x
    m11, m12 = _mass_entries(lumped["J1"], lumped["J1b"], lumped["Jc"], math.sin(beta), math.cos(beta))
    kinetic = 0.5 * (
        m11 * alpha_dot * alpha_dot + 2.0 * m12 * alpha_dot * beta_dot + lumped["J2"] * beta_dot * beta_dot
    )
    return kinetic + furuta_potential(lumped["G"], x, cos=math.cos)


class Furuta(AbstractLagrangianSystem):
    """Furuta pendulum, q = (α, β), β = 0 hanging down, u in volts (Laiche et al. 2026, §5).

    M = [[J1 + ¼mpLp²sin²β, ½mpLrLp cosβ], [½mpLrLp cosβ, J2]], V = ½mp g Lp (1 − cosβ),
    τ_NC = (−c_r α̇, −c_p β̇), τ_u = ((kt/Rm)(u − km α̇), 0). Unlike the paper (−u), positive
    voltage drives positive α.
    """

    params: FurutaParameters = eqx.field(default_factory=FurutaParameters)
    spec: ClassVar[SystemSpec] = FURUTA

    def mass_matrix(self, q):
        b = furuta_lumped(self.params)
        return furuta_mass_matrix(b["J1"], b["J1b"], b["Jc"], b["J2"], q)

    def potential(self, q):
        return furuta_potential(furuta_lumped(self.params)["G"], q)

    def nonconservative_force(self, q, qd):
        p = self.params
        return jnp.stack([-p.c_r * qd[0], -p.c_p * qd[1]])

    def input_force(self, q, qd, u):
        p = self.params
        return jnp.stack([p.kt / p.Rm * (u[0] - p.km * qd[0]), jnp.zeros_like(u[0])])


def _nominal_lumped() -> dict[str, float]:
    p = FurutaParameters()
    lumped = {k: float(v) for k, v in furuta_lumped(p).items()}
    return {**lumped, "c_alpha": float(p.c_r + p.kt * p.km / p.Rm), "c_beta": float(p.c_p), "K": float(p.kt / p.Rm)}


class FurutaSharedTrig(Furuta):
    """:class:`Furuta` with sin β and cos β evaluated once per call of the mass matrix or
    potential, however many terms and derivatives use them (:func:`_shared_sin_cos`): the same
    physics, faster under ``jit`` on XLA:CPU in float64. Equal to :class:`Furuta` to round-off,
    not always bit for bit (XLA may fuse, and so round, the arithmetic around the shared values
    otherwise; the functional env's steps came out bit for bit alike where checked). The
    JAX closed loops integrate with it (every controlled step: the functional and batched envs,
    their rollouts and the controllers' ``closed_loop``; ``furuta_gym.envs.vector.stepping_model``);
    everything else keeps :class:`Furuta`.
    """

    def mass_matrix(self, q):
        b = furuta_lumped(self.params)
        return furuta_mass_matrix(b["J1"], b["J1b"], b["Jc"], b["J2"], q, sin=_shared_sin, cos=_shared_cos)

    def potential(self, q):
        return furuta_potential(furuta_lumped(self.params)["G"], q, cos=_shared_cos)


@jax.custom_jvp
def _shared_sin_cos(beta):
    """(sin β, cos β), each one kernel's output that every use reads.

    Why: XLA:CPU counts sin and cos of reals as cheap, so it evaluates them afresh inside every
    fused kernel that consumes them; after the mass matrix's and the potential's derivatives a
    vector field of this model reads β's sin and cos in many kernels, and in float64 those
    evaluations are most of an RK4 step. A division XLA does not duplicate, and it cannot fold
    one by 1 + 0·β (exactly 1 for a finite β; NaN for a non-finite one, whose sin and cos are
    NaN already): x / 1 = x. The jvp takes the derivatives' sin and cos from the same values.
    """
    one = 1.0 + 0.0 * beta
    return jnp.sin(beta) / one, jnp.cos(beta) / one


@_shared_sin_cos.defjvp
def _shared_sin_cos_jvp(primals, tangents):
    (beta,), (t,) = primals, tangents
    sin, cos = _shared_sin_cos(beta)
    return (sin, cos), (t * cos, -(t * sin))  # JAX's rules for sin and cos, on the shared values


def _shared_sin(beta):
    return _shared_sin_cos(beta)[0]


def _shared_cos(beta):
    return _shared_sin_cos(beta)[1]


def _physical(p) -> bool:
    ok = p["J1"] > 0 and p["J2"] > 0 and p["J1b"] >= 0 and p["J1"] * p["J2"] > p["Jc"] ** 2
    return bool(ok and p["c_alpha"] >= 0 and p["c_beta"] >= 0 and p["Jc"] > 0)


def _anchor_note(nominal, forced) -> str:
    return f"scale anchored on the pendulum gravity term G = 0.5*mp*g*Lp = {nominal['G']:.6g} N m (nominal)" + (
        "; everything else, including the motor gain K, is fitted" if forced else ""
    )


# Rotor viscous friction and back-EMF are the same regressor (−α̇) on any data: one parameter.
FURUTA_LUMPED = LumpedForm(
    names=("J1", "J1b", "Jc", "J2", "G", "c_alpha", "c_beta", "K"),
    units=("kg m^2", "kg m^2", "kg m^2", "kg m^2", "N m", "N m s/rad", "N m s/rad", "N m/V"),
    nominal=_nominal_lumped,
    mass_matrix=lambda b, q: furuta_mass_matrix(b("J1"), b("J1b"), b("Jc"), b("J2"), q),
    potential=lambda b, q: furuta_potential(b("G"), q),
    damping=lambda b, qd: jnp.stack([-b("c_alpha") * qd[0], -b("c_beta") * qd[1]]),
    is_physical=_physical,
    gain="K",
    scale_anchor="G",
    anchor_note=_anchor_note,
    mechanical_anchor="G",
    gravity_joints=("beta",),
)

_PINNED = parameter_defaults(FurutaParameters)

# MuJoCo refuses a zero inertia on a moving body: the pendulum's point mass carries this much
# about each axis, and the hinge armature is reduced by the same amount so M22 stays exact.
_POINT_MASS_INERTIA = 1e-14


def _write_furuta_bodies(model, rotor_inertia, arm, mass, com, pendulum_inertia, g) -> None:
    """The rotor's inertia about its axis, the pendulum hinge at ``arm`` on it, the pendulum a
    point ``mass`` at ``com`` down its length plus hinge armature = ``pendulum_inertia`` (about
    its centre of mass), and gravity ``g``: M and V exactly as the paper's."""
    rotor, pend = model.body("rotor").id, model.body("pendulum").id
    model.body_inertia[rotor] = rotor_inertia
    model.body_pos[pend] = (arm, 0.0, 0.0)
    model.body_mass[pend] = mass
    model.body_ipos[pend] = (0.0, 0.0, -com)
    model.body_inertia[pend] = _POINT_MASS_INERTIA
    model.dof_armature[:] = (0.0, pendulum_inertia - _POINT_MASS_INERTIA)
    model.opt.gravity[:] = (0.0, 0.0, -g)


def write_furuta_mujoco(model, p: Mapping[str, float]) -> MujocoTerms:
    """The QUBE-Servo 2's bodies (the pendulum a point mass at Lp/2 plus hinge armature = the
    rest of Jp) and gravity; viscous friction native, the motor with its back-EMF as bias."""
    model.body_mass[model.body("rotor").id] = p["mr"]
    _write_furuta_bodies(
        model, p["mr"] * p["Lr"] ** 2 / 12.0, p["Lr"], p["mp"], 0.5 * p["Lp"], p["mp"] * p["Lp"] ** 2 / 12.0, p["g"]
    )
    return MujocoTerms(
        stiffness=(0.0, 0.0),
        damping=(p["c_r"], p["c_p"]),
        motor_gain=p["kt"] / p["Rm"],
        motor_bias=-p["kt"] * p["km"] / p["Rm"],
    )


def furuta_body_conditions(b: Mapping[str, float]) -> tuple[RigidBodyCondition, ...]:
    """What a rigid pendulum on an arm needs of the lumped values (each > 0): G, J1b and Jc
    themselves, the rotor's own inertia J1 − m·r² = J1 − Jc²/J1b and the pendulum's J2 − J1b."""
    j1b = b["J1b"] if b["J1b"] != 0 else float("nan")
    return (
        RigidBodyCondition("G", b["G"], ("G",)),
        RigidBodyCondition("J1b", b["J1b"], ("J1b",)),
        RigidBodyCondition("Jc", b["Jc"], ("Jc",)),
        RigidBodyCondition("J1 - m*r^2", b["J1"] - b["Jc"] ** 2 / j1b, ("J1", "Jc", "J1b")),
        RigidBodyCondition("J2 - J1b", b["J2"] - b["J1b"] - _POINT_MASS_INERTIA, ("J2", "J1b")),
    )


def write_furuta_lumped_mujoco(model, b: Mapping[str, float]) -> MujocoTerms:
    """The lumped parameters (what the diagnosis fits) as bodies: with g pinned, the pendulum's
    mass m and centre-of-mass distance l from G = m·g·l and J1b = m·l², the arm r from
    Jc = m·r·l, the rotor's inertia J1 − m·r² and the pendulum's J2 − J1b. The rotor damping
    c_alpha holds the back-EMF (the data cannot split them), so the motor has no bias."""
    check_rigid_bodies(b, furuta_body_conditions(b))
    g = _PINNED["g"]
    com = b["J1b"] * g / b["G"]
    mass, arm = b["G"] / (g * com), b["Jc"] * g / b["G"]
    _write_furuta_bodies(model, b["J1"] - mass * arm**2, arm, mass, com, b["J2"] - b["J1b"], g)
    return MujocoTerms(stiffness=(0.0, 0.0), damping=(b["c_alpha"], b["c_beta"]), motor_gain=b["K"])


FURUTA_DEFINITION = SystemDefinition(
    spec=FURUTA,
    title="the Furuta pendulum (QUBE-Servo 2)",
    model=Furuta,
    parameters=FurutaParameters,
    lumped=FURUTA_LUMPED,
    # J1 = Jr + mp·Lr² = 2.31e-4 kg·m², mp·g·Lp = 0.0304 J, lumped rotor damping 5.1e-4 N·m·s/rad
    learned_defaults=dict(
        hidden=(16, 16),
        mass_scale=2.3e-4,
        potential_scale=0.03,
        force_scale=1e-3,
        position_scale=1.0,
        velocity_scale=10.0,
        damping_init=(1e-3, 1e-4),
        input_gain=_PINNED["kt"] / _PINNED["Rm"],  # the motor's torque per volt (back-EMF lumped, see DeLaN)
    ),
    force_defaults={  # F_a general in q̇: it also holds the lumped back-EMF
        "aph": {"damping_scale": 1e-3, "force_activation": "tanh", "odd_in_velocity": False},
        "adln": {"damping_scale": 1e-3, "force_activation": "silu", "odd_in_velocity": False},
    },
    learnable_parameters=("mr", "Lr", "mp", "Lp"),
    friction_parameters=("c_r", "c_p"),
    known_damping_force=lambda coefficients, qd: -coefficients * qd,
    back_emf_parameter="km",
    back_emf_damping=_PINNED["kt"] * _PINNED["km"] / _PINNED["Rm"],  # N·m·s/rad
    sample_period=0.002,
    chirp_ranges=((0.6, 1.5), (0.3, 1.0), (2.0, 5.0), (-0.15, 0.15)),
    chirp_initial_ranges=((-1.0, 1.0), (-3.141592653589793, 3.141592653589793), (-3.0, 3.0), (-3.0, 3.0)),
    chirp_end_frequency=5.0,
    diagnosis_window=0.5,
    diagnosis_substeps=2,
    elementary_seconds=1.0,  # the paper's, for its experimental pendulum
    diagnosis_segment_seconds=2.0,
    excitations=("chirp", "sine_sweep", "sticky_sweep", "rotor_releases", "closed_loop_prbs"),
    encoders=True,
    table_title="Table 2 — Furuta pendulum (simulation)",
    energy_panels=(
        (1, -3.141592653589793, 3.141592653589793, 1.0, "β [rad] (α̇ = β̇ = 0)"),
        (3, -20.0, 20.0, 1.0, "β̇ [rad/s] (β = α̇ = 0)"),
    ),
    scale_fit_on_forced_data=True,
    # gravity: the hanging pendulum is stable, the upright one unstable (whatever the rotor does)
    equilibria=(
        Equilibrium("hanging (β = 0)", (0.0, 0.0), "beta", "minimum"),
        Equilibrium("upright (β = π)", (0.0, math.pi), "beta", "maximum"),
    ),
    lumped_values=furuta_lumped,
    energy=furuta_energy,
    write_mujoco=write_furuta_mujoco,
    write_lumped_mujoco=write_furuta_lumped_mujoco,
    body_conditions=furuta_body_conditions,
)
