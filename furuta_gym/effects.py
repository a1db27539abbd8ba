"""Physical effects a textbook model lacks: one vocabulary for plant variants and diagnosis.

The same names are used by the MuJoCo plant variants (``furuta_gym.envs``: ground truth with an
undeclared effect) and by the diagnosis library (``furuta_gym.diagnose``: which effect is missing).
Sign convention (coefficients positive for restoring or dissipative effects), per joint j:

=====================  ============================================  =======================
name                   generalized force on joint j                  unit of coefficient
=====================  ============================================  =======================
``spring``             −k·(q_j − q_ref)  (q_ref = ``reference``)     N·m/rad or N/m
``coulomb_friction``   −F_c·sgn(q̇_j)                                 N·m or N
``stiction``           −ΔF·exp(−(q̇_j/v_s)²)·sgn(q̇_j)                 N·m or N
``viscous_friction``   −c·q̇_j                                        N·m·s/rad or N·s/m
``quadratic_drag``     −c·q̇_j·|q̇_j|                                  N·m·s²/rad² or N·s²/m²
``constant_torque``    +τ0                                           N·m or N
``hysteretic_spring``  −k·(q_j − r), r dragged along with play w     N·m/rad or N/m
``com_offset``         V(q) → V(q − δ·e_j): −∂V(q − δe_j)/∂q         rad or m
``input_gain``         τ_u → (1 + g)·τ_u (joint "u")                 dimensionless g
``input_delay``        u(t) → u(t − d) (joint "u")                   s
``actuator_lag``       plant gets u_m, τ·u̇_m = u − u_m (joint "u")   s
=====================  ============================================  =======================

* ``spring`` with a non-zero ``reference``: a cable whose neutral is not at q_j = 0.
* ``stiction`` is the Stribeck breakaway above Coulomb friction: used with ``coulomb_friction``
  (F_c) and ΔF = F_s − F_c, the dry friction is −[F_c + ΔF·exp(−(q̇/v_s)²)]·sgn(q̇), F_s at
  rest. v_s is :attr:`Effect.stribeck_velocity` (rad/s or m/s, default 0.05).
* ``com_offset`` shifts the zero of the system's potential on joint j (all joints feel it):
  for the Furuta pendulum's β, a centre of mass off the pendulum's axis by the angle δ,
  V = ½·mp·g·Lp·(1 − cos(β − δ)), so it hangs at β = δ.
* ``actuator_lag``: the amplifier / motor electrical time constant (~1–20 ms).
* ``hysteretic_spring``: a cable whose neutral r moves: it stays put while |q_j − r| ≤ w
  (``play``) and is dragged along beyond (the play operator, r ∈ [q_j − w, q_j + w]); it starts
  at ``reference``. After a large swing the cable's neutral is left where the swing dragged it,
  up to w from the joint, so a rotor oscillating afterwards is pulled towards a centre that a
  fixed spring does not know. It has memory: :class:`CableNeutral` holds r.

Coulomb friction and stiction use sgn(0) = 0, or tanh(q̇/ε) with ``coulomb_smoothing`` ε > 0.

:class:`WithEffects` adds joint effects to any Lagrangian system (springs and ``com_offset``
into V, so energy stays right; the rest into τ_NC; the input gain into τ_u). ``input_delay`` and
``actuator_lag`` have no memoryless form: they live in the env/plant (an input buffer; the lag
state, :class:`ActuatorLag` or MuJoCo's actuator activation), not in a Lagrangian model.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, ClassVar, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .lagrangian import AbstractLagrangianSystem, SystemSpec

__all__ = [
    "Effect",
    "JOINT_EFFECTS",
    "INPUT_EFFECTS",
    "DRY_FRICTION",
    "STATEFUL_EFFECTS",
    "EFFECT_UNITS",
    "WithEffects",
    "ActuatorLag",
    "CableNeutral",
    "actuator_lag_time",
]

JOINT_EFFECTS = (
    "spring",
    "coulomb_friction",
    "stiction",
    "viscous_friction",
    "quadratic_drag",
    "constant_torque",
    "com_offset",
    "hysteretic_spring",
)
INPUT_EFFECTS = ("input_gain", "input_delay", "actuator_lag")
#: friction bounded by a law of q̇ that can hold a joint at rest (:meth:`Effect.dry_friction_limit`)
DRY_FRICTION = ("coulomb_friction", "stiction")
#: effects with memory: no Lagrangian (memoryless) form, applied in the env / plant
STATEFUL_EFFECTS = ("input_delay", "actuator_lag", "hysteretic_spring")

EFFECT_UNITS = {
    # (angular joint, linear joint)
    "spring": ("N m/rad", "N/m"),
    "coulomb_friction": ("N m", "N"),
    "stiction": ("N m", "N"),
    "viscous_friction": ("N m s/rad", "N s/m"),
    "quadratic_drag": ("N m s^2/rad^2", "N s^2/m^2"),
    "constant_torque": ("N m", "N"),
    "com_offset": ("rad", "m"),
    "hysteretic_spring": ("N m/rad", "N/m"),
    "input_gain": ("1", "1"),
    "input_delay": ("s", "s"),
    "actuator_lag": ("s", "s"),
}


@dataclasses.dataclass(frozen=True)
class Effect:
    """One physical effect on one joint (``"alpha"``, ``"beta"``, ``"p"``) or on the input (``"u"``).

    ``reference`` is the spring's rest position (a hysteretic spring's first neutral; ignored by
    other effects); ``stribeck_velocity`` is the stiction's v_s in rad/s or m/s and ``play`` the
    hysteretic spring's w in rad or m (each ignored by other effects).
    """

    name: str
    joint: str
    coefficient: float
    reference: float = 0.0
    stribeck_velocity: float = 0.05
    play: float = 0.0

    def __post_init__(self):
        if self.name not in JOINT_EFFECTS + INPUT_EFFECTS:
            raise ValueError(
                f"unknown effect {self.name!r}; expected one of {JOINT_EFFECTS + INPUT_EFFECTS}"
            )
        if (self.name in INPUT_EFFECTS) != (self.joint == "u"):
            where = "the input 'u'" if self.name in INPUT_EFFECTS else "a joint, not 'u'"
            raise ValueError(f"effect {self.name!r} acts on {where}; got joint={self.joint!r}")
        if not (math.isfinite(self.play) and self.play >= 0):
            raise ValueError(f"effect {self.name!r}: play must be >= 0 (rad or m), got {self.play!r}")
        if not (math.isfinite(self.stribeck_velocity) and self.stribeck_velocity > 0):
            raise ValueError(
                f"effect {self.name!r}: stribeck_velocity must be > 0 (rad/s or m/s), "
                f"got {self.stribeck_velocity!r}"
            )

    def joint_index(self, spec: SystemSpec) -> int:
        """Index of this effect's joint in ``spec``; a clear error for a joint it lacks."""
        if self.joint not in spec.joint_names:
            raise ValueError(
                f"effect {self.name!r}: joint {self.joint!r} is not a joint of {spec.name} "
                f"(joints: {list(spec.joint_names)})"
            )
        return spec.joint_names.index(self.joint)

    def unit(self, spec: SystemSpec) -> str:
        """Unit of the coefficient on this joint of ``spec`` (angular or linear)."""
        angular = self.joint == "u" or spec.angular[self.joint_index(spec)]
        return EFFECT_UNITS[self.name][0 if angular else 1]

    def generalized_force(self, q_j, qd_j, coulomb_smoothing: float = 0.0, xp=jnp):
        """Force on its joint from joint position/velocity (see :meth:`law`). Springs included."""
        return self.law(coulomb_smoothing, xp)(q_j, qd_j)

    def law(self, coulomb_smoothing: float = 0.0, xp=jnp) -> Callable[[Any, Any], Any]:
        """The effect's force law f(q_j, q̇_j) on its joint, written once for every user.

        ``coulomb_smoothing`` > 0 replaces sgn(v) by tanh(v / smoothing) (for integrators), in
        Coulomb friction and stiction alike. ``xp``: the namespace of sign/tanh/exp/abs
        (``jax.numpy``: traceable; MuJoCo's passive-force callback passes one for plain floats).
        ``com_offset`` depends on the whole potential: see :meth:`com_offset_force`.
        """
        c = self.coefficient
        if self.name == "spring":
            reference = self.reference
            return lambda q, qd: -c * (q - reference)
        if self.name in DRY_FRICTION:
            smoothing = coulomb_smoothing
            sgn = xp.sign if smoothing <= 0 else (lambda v: xp.tanh(v / smoothing))
            limit = self.dry_friction_limit(xp)
            return lambda q, qd: -limit(qd) * sgn(qd)
        if self.name == "viscous_friction":
            return lambda q, qd: -c * qd
        if self.name == "quadratic_drag":
            return lambda q, qd: -c * qd * xp.abs(qd)
        if self.name == "constant_torque":
            return lambda q, qd: c + 0.0 * q
        if self.name == "com_offset":
            raise ValueError(
                "com_offset shifts the system's potential, V(q) -> V(q - δ e_j); its force depends "
                "on V: use Effect.com_offset_force(potential, q, spec)"
            )
        if self.name == "hysteretic_spring":
            raise ValueError("hysteretic_spring has memory (its moving neutral): use CableNeutral(effect)")
        raise ValueError(f"{self.name!r} is an input effect, not a joint force")

    def dry_friction_limit(self, xp=jnp) -> Callable[[Any], Any]:
        """The largest force this dry friction exerts, as a law of q̇_j (N·m or N): F_c for
        ``coulomb_friction``, ΔF·exp(−(q̇_j/v_s)²) for ``stiction``. Sliding, the friction is
        −limit·sgn(q̇_j) (:meth:`law`); at rest it holds the joint against any smaller force
        (:func:`furuta_gym.lagrangian.forward_dynamics_with_dry_friction`)."""
        c = self.coefficient
        if self.name == "coulomb_friction":
            return lambda qd: c + 0.0 * qd
        if self.name == "stiction":
            v_s = self.stribeck_velocity
            return lambda qd: c * xp.exp(-((qd / v_s) ** 2))
        raise ValueError(f"{self.name!r} is not dry friction; expected one of {DRY_FRICTION}")

    def shift(self, spec: SystemSpec):
        """δ·e_j: the vector a ``com_offset`` subtracts from q in the potential."""
        if self.name != "com_offset":
            raise ValueError(f"shift is the com_offset's δ·e_j; {self.name!r} has none")
        return jnp.zeros(spec.n_dof).at[self.joint_index(spec)].set(self.coefficient)

    def com_offset_force(self, potential, q, spec: SystemSpec):
        """Extra generalized force (all joints) of a ``com_offset`` on a system with potential
        ``potential(q)``: −∇V(q − δe_j) + ∇V(q) (jnp-traceable)."""
        shift = self.shift(spec)
        return jax.grad(potential)(q) - jax.grad(potential)(q - shift)


class CableNeutral:
    """The moving neutral r of a ``hysteretic_spring`` (the play operator): r starts at the
    effect's ``reference`` and is dragged along once the joint is more than ``play`` from it.

    :meth:`force` is the spring's force at q_j with r as it would be dragged to there (exact for a
    joint moving one way within a step); :meth:`advance` moves r once a plant step is done.
    """

    def __init__(self, effect: Effect):
        if effect.name != "hysteretic_spring":
            raise ValueError(f"CableNeutral is a hysteretic_spring's neutral; got {effect.name!r}")
        self.stiffness, self.play, self.start = effect.coefficient, effect.play, effect.reference
        self.reset()

    def reset(self) -> None:
        self.neutral = self.start

    def _dragged(self, q: float) -> float:
        return min(max(self.neutral, q - self.play), q + self.play)

    def force(self, q: float) -> float:
        return -self.stiffness * (q - self._dragged(q))

    def advance(self, q: float) -> None:
        self.neutral = self._dragged(q)


def actuator_lag_time(effects: Sequence[Effect]) -> float:
    """τ of the ``actuator_lag`` among ``effects`` (0.0: none); at most one, τ ≥ 0 finite."""
    lags = [e.coefficient for e in effects if e.name == "actuator_lag"]
    if len(lags) > 1:
        raise ValueError(
            f"at most one actuator_lag effect (two first-order lags in series are not one "
            f"first-order lag); got time constants {lags}"
        )
    tau = float(lags[0]) if lags else 0.0
    if not (math.isfinite(tau) and tau >= 0):
        raise ValueError(f"actuator_lag must be a time constant >= 0 s, got {tau!r}")
    return tau


class ActuatorLag:
    """The ``actuator_lag`` τ·u̇_m = u − u_m, discretised exactly for an input held over an
    interval (zero-order hold): what a model backend / env applies, one control period at a time.

    :meth:`advance` returns the MEAN of u_m over the interval (the plant then receives the exact
    impulse of the lagged input, held over the interval) and moves u_m to its value at the end.
    MuJoCo instead integrates u_m with the state at every RK4 stage; the two agree to O(dt/τ)
    of what the lag changes (0.3 % at τ = 5 ms, dt = 2 ms: tests/test_effects_plants.py; holding
    u_m's value at the start or the end of the period instead was ~60× further off).
    """

    def __init__(self, tau: float, n_inputs: int = 1):
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f"ActuatorLag needs a time constant > 0 s, got {tau!r}")
        self.tau = float(tau)
        self.state = np.zeros(n_inputs)  # u_m; 0 at reset, like MuJoCo's actuator activation

    def reset(self, u_m=0.0) -> None:
        self.state = np.zeros_like(self.state) + u_m

    def advance(self, u, duration: float) -> np.ndarray:
        """Hold ``u`` for ``duration`` s: return the mean of u_m over it, move u_m to its end."""
        u = np.asarray(u, dtype=np.float64)
        decay = math.exp(-duration / self.tau)
        gap = self.state - u  # u_m(t) = u + gap·exp(−t/τ)
        mean = u + gap * (self.tau / duration) * (1.0 - decay) if duration > 0 else self.state.copy()
        self.state = u + gap * decay
        return mean


class WithEffects(AbstractLagrangianSystem):
    """``base`` plus extra joint effects and an input gain; a Lagrangian system itself.

    Springs enter the potential (½k(q − q_ref)²) and ``com_offset`` shifts the base potential,
    V(q − Σδ·e_j), so energy and the force decomposition stay physical; friction, stiction, drag
    and constant torques enter τ_NC; ``input_gain`` scales τ_u. ``input_delay`` and
    ``actuator_lag`` are rejected here (they are not memoryless).
    """

    base: AbstractLagrangianSystem
    effects: tuple[Effect, ...] = eqx.field(static=True)
    coulomb_smoothing: float = eqx.field(static=True, default=0.0)

    spec: ClassVar = property(lambda self: self.base.spec)  # type: ignore[assignment]

    def __init__(
        self,
        base: AbstractLagrangianSystem,
        effects: Sequence[Effect],
        coulomb_smoothing: float = 0.0,
    ):
        effects = tuple(effects)
        for e in effects:
            if e.name in STATEFUL_EFFECTS:
                where = {
                    "input_delay": "the env's actuation delay",
                    "actuator_lag": "the env's actuation path (ActuatorLag) or MujocoBackend (actuator dynamics)",
                }.get(e.name, "the MuJoCo plant (MujocoBackend), which keeps its state")
                raise ValueError(
                    f"{e.name} has no memoryless Lagrangian form (it has a state); use {where}"
                )
            if e.joint != "u":
                e.joint_index(base.spec)
        self.base = base
        self.effects = effects
        self.coulomb_smoothing = coulomb_smoothing

    def mass_matrix(self, q):
        return self.base.mass_matrix(q)

    def potential(self, q):
        shifted = q
        for e in self.effects:
            if e.name == "com_offset":
                shifted = shifted - e.shift(self.spec).astype(q.dtype)
        v = self.base.potential(shifted)
        for e in self.effects:
            if e.name == "spring":
                j = e.joint_index(self.spec)
                v = v + 0.5 * e.coefficient * (q[j] - e.reference) ** 2
        return v

    def nonconservative_force(self, q, qd):
        tau = self.base.nonconservative_force(q, qd)
        for e in self.effects:
            if e.joint == "u" or e.name in ("spring", "com_offset"):
                continue
            j = e.joint_index(self.spec)
            tau = tau.at[j].add(e.generalized_force(q[j], qd[j], self.coulomb_smoothing))
        return tau

    def input_force(self, q, qd, u):
        gain = 1.0 + sum(e.coefficient for e in self.effects if e.name == "input_gain")
        return gain * self.base.input_force(q, qd, u)
