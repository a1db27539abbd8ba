"""The Lagrangian-system protocol and everything derived from it, once, by autodiff.

A Lagrangian system is four functions (Laiche et al. 2026, eq. 2):

* the mass matrix ``M(q)`` (symmetric positive definite), so that ``T = ½ q̇ᵀ M(q) q̇``;
* the potential energy ``V(q)``; the Lagrangian is ``L = T − V``;
* the non-conservative generalized force ``τ_NC(q, q̇)`` (friction, drag, ...);
* the generalized input force ``τ_u(q, q̇, u)`` (e.g. a DC motor with back-EMF).

The Euler–Lagrange equation with external forces reads

    (∂²L/∂q̇²) q̈ + (∂²L/∂q∂q̇) q̇ − ∂L/∂q = τ_u + τ_NC,

whose three left-hand terms are the *inertial*, *Coriolis* and *potential-derived* parts of the
inverse dynamics. This module derives from the four protocol functions: forward and inverse
dynamics, the three parts, energy, momentum ``∂L/∂q̇``, linearisation, and the integral inverse
residual ``Z̄ − Ā`` of the paper (eq. 8-10). Every function takes a single sample; batch with
``jax.vmap``. Nothing here knows a concrete model: analytic models, DeLaN, APHYNITY and augmented
DeLaN all subclass :class:`AbstractLagrangianSystem` and get the rest for free.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = [
    "SystemSpec",
    "AbstractLagrangianSystem",
    "InverseDynamicsTerms",
    "kinetic_energy",
    "lagrangian",
    "energy",
    "momentum",
    "coriolis_force",
    "potential_derived_force",
    "inverse_dynamics_terms",
    "inverse_dynamics",
    "forward_dynamics",
    "forward_dynamics_with_dry_friction",
    "solve_mass_matrix",
    "vector_field",
    "linearize",
    "interval_integral",
    "interval_quadrature",
    "hermite_states",
    "interval_difference",
    "quadrature_consistency",
    "IntegralTerms",
    "integral_terms",
    "integral_residual",
    "QuadratureRule",
    "QUADRATURE_RULES",
]

QuadratureRule = Literal["trapezoid", "simpson", "hermite"]
#: every quadrature rule of the integral residual (see :func:`interval_quadrature`)
QUADRATURE_RULES: tuple[str, ...] = ("trapezoid", "simpson", "hermite")

# Two-point Gauss–Legendre nodes on [0, 1] (fractions of a sampling interval) and their weights:
# exact for cubics, so for any integrand linear in a cubic Hermite interpolant of q
_GAUSS_NODES = (0.5 - 0.5 / 3.0**0.5, 0.5 + 0.5 / 3.0**0.5)
_GAUSS_WEIGHTS = (0.5, 0.5)


@dataclasses.dataclass(frozen=True)
class SystemSpec:
    """What a system *is*, independent of any model of it: names, units, which joints are angles.

    Used to check that data, checkpoints and envs belong together, and to name columns.
    """

    name: str
    joint_names: tuple[str, ...]
    angular: tuple[bool, ...]
    input_names: tuple[str, ...]
    joint_units: tuple[str, ...]
    input_units: tuple[str, ...]

    @property
    def n_dof(self) -> int:
        """Number of degrees of freedom."""
        return len(self.joint_names)

    @property
    def n_inputs(self) -> int:
        """Number of inputs."""
        return len(self.input_names)

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of x = (q, q̇): joints then ``<joint>_dot``."""
        return self.joint_names + tuple(f"{j}_dot" for j in self.joint_names)


class AbstractLagrangianSystem(eqx.Module):
    """The protocol: M(q), V(q), τ_NC(q, q̇), τ_u(q, q̇, u). Subclass and implement the four.

    Shapes: ``q``, ``q̇`` are ``(n_dof,)``; ``u`` is ``(n_inputs,)``. Derived quantities are
    available both as module-level functions (``forward_dynamics(system, q, qd, u)``) and as
    methods of the same name that delegate to them.
    """

    if TYPE_CHECKING:
        # an AbstractVar is a dataclass field to a type checker, and would be the first
        # argument of every subclass' __init__
        @property
        def spec(self) -> SystemSpec: ...
    else:
        spec: eqx.AbstractVar[SystemSpec]

    @abc.abstractmethod
    def mass_matrix(self, q: Float[Array, " n"]) -> Float[Array, "n n"]:
        """Symmetric positive-definite mass matrix M(q)."""

    @abc.abstractmethod
    def potential(self, q: Float[Array, " n"]) -> Float[Array, ""]:
        """Potential energy V(q), a scalar."""

    @abc.abstractmethod
    def nonconservative_force(self, q: Float[Array, " n"], qd: Float[Array, " n"]) -> Float[Array, " n"]:
        """Generalized non-conservative force τ_NC(q, q̇)."""

    @abc.abstractmethod
    def input_force(self, q: Float[Array, " n"], qd: Float[Array, " n"], u: Float[Array, " m"]) -> Float[Array, " n"]:
        """Generalized input force τ_u(q, q̇, u)."""

    # -- derived quantities, delegating to the module functions (the one place they live) --
    def energy(self, q, qd):
        """Total energy T + V; see :func:`energy`."""
        return energy(self, q, qd)

    def momentum(self, q, qd):
        """∂L/∂q̇ = M(q)q̇; see :func:`momentum`."""
        return momentum(self, q, qd)

    def forward_dynamics(self, q, qd, u):
        """q̈ at (q, q̇, u); see :func:`forward_dynamics`."""
        return forward_dynamics(self, q, qd, u)

    def inverse_dynamics_terms(self, q, qd, qdd):
        """Inertial, Coriolis and potential-derived parts; see :func:`inverse_dynamics_terms`."""
        return inverse_dynamics_terms(self, q, qd, qdd)

    def vector_field(self, x, u):
        """ẋ for x = (q, q̇); see :func:`vector_field`."""
        return vector_field(self, x, u)

    def linearize(self, x, u):
        """(A, B) at (x, u); see :func:`linearize`."""
        return linearize(self, x, u)


class InverseDynamicsTerms(NamedTuple):
    """The three parts of the Euler–Lagrange left-hand side (paper, eq. 3)."""

    inertial: Float[Array, " n"]  # (∂²L/∂q̇²) q̈ = M(q) q̈
    coriolis: Float[Array, " n"]  # (∂²L/∂q∂q̇) q̇
    potential: Float[Array, " n"]  # ∂L/∂q  (potential-derived; includes ∂T/∂q)


def kinetic_energy(system: AbstractLagrangianSystem, q, qd) -> Float[Array, ""]:
    """T = ½ q̇ᵀ M(q) q̇."""
    return 0.5 * qd @ system.mass_matrix(q) @ qd


def lagrangian(system: AbstractLagrangianSystem, q, qd) -> Float[Array, ""]:
    """L = T − V."""
    return kinetic_energy(system, q, qd) - system.potential(q)


def energy(system: AbstractLagrangianSystem, q, qd) -> Float[Array, ""]:
    """Total mechanical energy E = T + V."""
    return kinetic_energy(system, q, qd) + system.potential(q)


def momentum(system: AbstractLagrangianSystem, q, qd) -> Float[Array, " n"]:
    """Generalized momentum ∂L/∂q̇ = M(q) q̇ (exact for L = ½q̇ᵀMq̇ − V)."""
    return system.mass_matrix(q) @ qd


def coriolis_force(system: AbstractLagrangianSystem, q, qd) -> Float[Array, " n"]:
    """(∂²L/∂q∂q̇) q̇: the directional derivative of the momentum M(q)q̇ along q̇."""
    return jax.jvp(lambda q_: system.mass_matrix(q_) @ qd, (q,), (qd,))[1]


def potential_derived_force(system: AbstractLagrangianSystem, q, qd) -> Float[Array, " n"]:
    """∂L/∂q = ∂T/∂q − ∂V/∂q."""
    return jax.grad(lagrangian, argnums=1)(system, q, qd)


def inverse_dynamics_terms(system: AbstractLagrangianSystem, q, qd, qdd) -> InverseDynamicsTerms:
    """Inertial, Coriolis and potential-derived parts at (q, q̇, q̈)."""
    return InverseDynamicsTerms(
        inertial=system.mass_matrix(q) @ qdd,
        coriolis=coriolis_force(system, q, qd),
        potential=potential_derived_force(system, q, qd),
    )


def inverse_dynamics(system: AbstractLagrangianSystem, q, qd, qdd) -> Float[Array, " n"]:
    """The input force τ_u needed for acceleration q̈: inertial + Coriolis − ∂L/∂q − τ_NC."""
    terms = inverse_dynamics_terms(system, q, qd, qdd)
    return terms.inertial + terms.coriolis - terms.potential - system.nonconservative_force(q, qd)


def solve_mass_matrix(M: Float[Array, "n n"], b: Float[Array, " n"]) -> Float[Array, " n"]:
    """M⁻¹b; in closed form for one or two degrees of freedom, else ``jnp.linalg.solve``.

    Why: on CPU ``jnp.linalg.solve`` is a LAPACK custom call whose fixed cost outweighs the rest
    of an RK4 step of these tiny systems; the closed form agrees to round-off.
    """
    n = b.shape[-1]
    if n == 1:
        return b / M[0, 0]
    if n == 2:
        det = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
        return jnp.stack([M[1, 1] * b[0] - M[0, 1] * b[1], M[0, 0] * b[1] - M[1, 0] * b[0]]) / det
    return jnp.linalg.solve(M, b)


def _applied_force(system: AbstractLagrangianSystem, q, qd, u) -> Float[Array, " n"]:
    """τ_u + τ_NC + ∂L/∂q − (∂²L/∂q∂q̇) q̇: what M(q) q̈ equals."""
    return (
        system.input_force(q, qd, u)
        + system.nonconservative_force(q, qd)
        + potential_derived_force(system, q, qd)
        - coriolis_force(system, q, qd)
    )


def forward_dynamics(system: AbstractLagrangianSystem, q, qd, u) -> Float[Array, " n"]:
    """q̈ = M(q)⁻¹ (τ_u + τ_NC + ∂L/∂q − (∂²L/∂q∂q̇) q̇)."""
    return solve_mass_matrix(system.mass_matrix(q), _applied_force(system, q, qd, u))


def forward_dynamics_with_dry_friction(
    system: AbstractLagrangianSystem, limit: Float[Array, " n"], q, qd, u, relaxation: float, impedance: float = 1.0
) -> Float[Array, " n"]:
    """q̈ of ``system`` with dry friction added that can hold a joint at rest.

    ``limit`` (n,) ≥ 0 is the largest dry-friction force on each joint at this state (N·m or N;
    0 where a joint has none; e.g. :meth:`furuta_gym.effects.Effect.dry_friction_limit`). Each
    joint's friction is the force within ±limit that, given the other forces, brings its velocity
    to zero with time constant ``relaxation`` (s): it holds the joint while the rest of the forces
    stay within the limit, and is ∓limit while the joint slides (Karnopp's stick–slip model, in a
    form an explicit integrator can take at steps ≲ ``relaxation``). The sgn law instead chatters
    about q̇ = 0 and tanh(q̇/ε) lets the joint creep. Joints are resolved in turn, twice
    (Gauss–Seidel): exact with friction on one joint, close when several stick at once.
    ``impedance`` < 1 applies that share of the holding force, as MuJoCo's soft friction loss
    does, so a loaded joint creeps instead of sticking.
    """
    M = system.mass_matrix(q)
    free = solve_mass_matrix(M, _applied_force(system, q, qd, u))
    n = free.shape[-1]
    # column j: the accelerations a unit force on joint j gives
    response = jnp.stack([solve_mass_matrix(M, e) for e in jnp.eye(n, dtype=free.dtype)], axis=1)
    friction = jnp.zeros_like(free)
    for _ in range(2):
        for j in range(n):
            others = free[j] + response[j] @ friction - response[j, j] * friction[j]
            holding = impedance * (-qd[j] / relaxation - others) / response[j, j]
            friction = friction.at[j].set(jnp.clip(holding, -limit[j], limit[j]))
    return free + response @ friction


def vector_field(system: AbstractLagrangianSystem, x, u) -> Float[Array, " 2n"]:
    """ẋ for the state x = (q, q̇)."""
    n = system.spec.n_dof
    q, qd = x[:n], x[n:]
    return jnp.concatenate([qd, forward_dynamics(system, q, qd, u)])


def linearize(system: AbstractLagrangianSystem, x, u):
    """(A, B) = (∂ẋ/∂x, ∂ẋ/∂u) at (x, u), continuous time."""
    A = jax.jacfwd(lambda x_: vector_field(system, x_, u))(x)
    B = jax.jacfwd(lambda u_: vector_field(system, x, u_))(u)
    return A, B


#: the interval rules are plain array arithmetic: NumPy in, NumPy out (the diagnosis' fit)
_ArrayT = TypeVar("_ArrayT", Array, np.ndarray)


def interval_integral(
    f: Float[_ArrayT, " T *rest"], dt: float, rule: QuadratureRule = "trapezoid"
) -> Float[_ArrayT, " K *rest"]:
    """∫ f dt over consecutive intervals of uniformly sampled ``f``.

    ``"trapezoid"``: K = T − 1 intervals [t_{j−1}, t_j] (the paper's eq. 9-10).
    ``"simpson"``: K = (T − 1) // 2 intervals [t_{2k}, t_{2k+2}] (a trailing sample is dropped
    when T is even); fourth order, so its quadrature floor on smooth data is far lower.
    Any quantity integrated over the same intervals (a candidate effect, an input) is comparable
    to the residual term by term. ``"hermite"`` integrates between the samples, so it needs the
    states, not samples of ``f``: use :func:`interval_quadrature`.
    """
    if rule == "trapezoid":
        return 0.5 * dt * (f[1:] + f[:-1])
    if rule == "simpson":
        k = (f.shape[0] - 1) // 2
        a, m, b = f[0 : 2 * k : 2], f[1 : 2 * k : 2], f[2 : 2 * k + 1 : 2]
        return dt / 3.0 * (a + 4.0 * m + b)
    if rule == "hermite":
        raise ValueError(
            "rule='hermite' evaluates the integrand between the samples and so needs the states: "
            "use interval_quadrature(g, q, qd, u, dt, 'hermite')"
        )
    raise ValueError(f"rule must be one of {QUADRATURE_RULES}, got {rule!r}")


def hermite_states(
    q: Float[Array, "T n"], qd: Float[Array, "T n"], u: Float[Array, "T m"], dt: float, s: float
) -> tuple[Float[Array, "K n"], Float[Array, "K n"], Float[Array, "K m"]]:
    """(q, q̇, u) at the fraction ``s`` ∈ [0, 1] of every sampling interval [t_{j−1}, t_j].

    q is the cubic Hermite interpolant through q and q̇ at both ends (the unique cubic that
    matches the measured positions *and* velocities), q̇ its derivative, u linear between samples
    (what the simulated plants receive). On the interval q is exact to O(dt⁴) and q̇ to O(dt³),
    from measured data alone: no acceleration enters.
    """
    q0, q1, v0, v1 = q[:-1], q[1:], qd[:-1], qd[1:]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    d00, d10, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, 3 * s**2 - 2 * s
    q_s = h00 * q0 + h01 * q1 + dt * (h10 * v0 + h11 * v1)
    qd_s = d00 * (q0 - q1) / dt + d10 * v0 + d11 * v1
    return q_s, qd_s, (1.0 - s) * u[:-1] + s * u[1:]


def interval_quadrature(
    g,
    q: Float[Array, "T n"],
    qd: Float[Array, "T n"],
    u: Float[Array, "T m"],
    dt: float,
    rule: QuadratureRule = "trapezoid",
) -> Float[Array, " K *rest"]:
    """∫ g(q, q̇, u) dt over the intervals of ``rule``, for a per-sample function ``g``.

    ``"trapezoid"`` / ``"simpson"`` evaluate g at the samples (:func:`interval_integral`).
    ``"hermite"`` keeps the paper's intervals [t_{j−1}, t_j] but evaluates g at two Gauss–Legendre
    nodes inside each, on the states of :func:`hermite_states`. Where the sampling under-resolves
    the motion (a pendulum whirling at 30 rad/s sampled at 100 Hz turns 0.3 rad per sample) the
    sample-based rules integrate a badly resolved integrand, and that quadrature error is what
    the true model's residual is made of; this rule lowers that floor by orders of magnitude
    (docs/learning.md has the numbers).
    """
    if rule != "hermite":
        return interval_integral(jax.vmap(g)(q, qd, u), dt, rule)
    total: Any = 0.0
    for s, w in zip(_GAUSS_NODES, _GAUSS_WEIGHTS, strict=True):
        total = total + w * jax.vmap(g)(*hermite_states(q, qd, u, dt, s))
    return dt * total


def interval_difference(
    p: Float[_ArrayT, " T *rest"], rule: QuadratureRule = "trapezoid"
) -> Float[_ArrayT, " K *rest"]:
    """p(end) − p(start) over the same intervals as :func:`interval_integral` (``"hermite"``
    uses the trapezoid's intervals)."""
    if rule in ("trapezoid", "hermite"):
        return p[1:] - p[:-1]
    if rule == "simpson":
        k = (p.shape[0] - 1) // 2
        return p[2 : 2 * k + 1 : 2] - p[0 : 2 * k : 2]
    raise ValueError(f"rule must be one of {QUADRATURE_RULES}, got {rule!r}")


def quadrature_consistency(
    q: Float[Array, "T n"], qd: Float[Array, "T n"], dt: float, rule: QuadratureRule = "trapezoid"
) -> Float[Array, "K n"]:
    """∫q̇ dt − Δq over the quadrature intervals: how well the rule resolves the motion there.

    Data only, no model: positions and velocities are both measured, so the rule's error on
    q̇ is known exactly. Where the motion is too fast for the sampling (a pendulum whirling at
    30 rad/s sampled at 100 Hz) every integrand of the residual is under-resolved too, and the
    true model's residual there is quadrature error, not physics: on the Furuta training data
    the 1 % of Simpson intervals with the largest consistency error carry 77 % of the true
    model's squared residual (correlation of the logs 0.86). Zero for ``"hermite"`` by
    construction: its interpolant's velocity integrates to Δq exactly.
    """
    if rule == "hermite":
        return jnp.zeros_like(interval_difference(q, rule))
    return interval_integral(qd, dt, rule) - interval_difference(q, rule)


class IntegralTerms(NamedTuple):
    """Per-interval generalized impulses of a trajectory (paper eq. 8-10)."""

    A: Float[Array, "K n"]  # Ā: Δ(∂L/∂q̇) − ∫(∂L/∂q + τ_NC) dt
    Z: Float[Array, "K n"]  # Z̄: ∫ τ_u dt


def integral_terms(
    system: AbstractLagrangianSystem,
    q: Float[Array, "T n"],
    qd: Float[Array, "T n"],
    u: Float[Array, "T m"],
    dt: float,
    rule: QuadratureRule = "trapezoid",
) -> IntegralTerms:
    """Ā and Z̄ of one uniformly sampled trajectory; no accelerations needed."""
    p = jax.vmap(lambda q_, qd_: momentum(system, q_, qd_))(q, qd)

    def forces(q_, qd_, u_):
        return (
            potential_derived_force(system, q_, qd_) + system.nonconservative_force(q_, qd_),
            system.input_force(q_, qd_, u_),
        )

    if rule == "hermite":  # one pass over the interior nodes for both integrands
        f, tau_u = interval_quadrature(lambda *a: jnp.stack(forces(*a)), q, qd, u, dt, rule).swapaxes(0, 1)
        return IntegralTerms(A=interval_difference(p, rule) - f, Z=tau_u)
    f, tau_u = jax.vmap(forces)(q, qd, u)
    A = interval_difference(p, rule) - interval_integral(f, dt, rule)
    Z = interval_integral(tau_u, dt, rule)
    return IntegralTerms(A=A, Z=Z)


def integral_residual(
    system: AbstractLagrangianSystem,
    q: Float[Array, "T n"],
    qd: Float[Array, "T n"],
    u: Float[Array, "T m"],
    dt: float,
    rule: QuadratureRule = "trapezoid",
) -> Float[Array, "K n"]:
    """The integral inverse-model residual Z̄ − Ā per interval and joint (paper eq. 10).

    Zero for the true model up to the quadrature floor (O(dt²) per unit time for the trapezoid
    rule, O(dt⁴) for Simpson's and for ``"hermite"``, whose integrand is resolved between the
    samples; see :func:`interval_quadrature`); L_Iτ is its sum of squares.
    """
    terms = integral_terms(system, q, qd, u, dt, rule)
    return terms.Z - terms.A
