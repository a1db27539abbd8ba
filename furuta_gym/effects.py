"""Physical effects a textbook model lacks: one vocabulary for plant variants and diagnosis.

The same names are used by the MuJoCo plant variants (``furuta_gym.envs``: ground truth with an
undeclared effect) and by the diagnosis library (``furuta_gym.diagnose``: which effect is missing).
Sign convention (coefficients positive for restoring or dissipative effects), per joint j:

=====================  ==============================  ======================
name                   generalized force on joint j     unit of coefficient
=====================  ==============================  ======================
``spring``             −k·(q_j − q_ref)                 N·m/rad or N/m
``coulomb_friction``   −F·sgn(q̇_j)                      N·m or N
``viscous_friction``   −c·q̇_j                           N·m·s/rad or N·s/m
``quadratic_drag``     −c·q̇_j·|q̇_j|                     N·m·s²/rad² or N·s²/m²
``constant_torque``    +τ0                              N·m or N
``input_gain``         τ_u → (1 + g)·τ_u (joint "u")    dimensionless g
``input_delay``        u(t) → u(t − d) (joint "u")      s
=====================  ==============================  ======================

:class:`WithEffects` adds joint effects to any Lagrangian system (the spring into V, so energy
stays right; the rest into τ_NC; the input gain into τ_u). Delay has no memoryless form: it lives
in the env/plant (an input buffer), not in a Lagrangian model.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, Sequence

import equinox as eqx
import jax.numpy as jnp

from .lagrangian import AbstractLagrangianSystem, SystemSpec

__all__ = ["Effect", "JOINT_EFFECTS", "INPUT_EFFECTS", "EFFECT_UNITS", "WithEffects"]

JOINT_EFFECTS = ("spring", "coulomb_friction", "viscous_friction", "quadratic_drag", "constant_torque")
INPUT_EFFECTS = ("input_gain", "input_delay")

EFFECT_UNITS = {
    # (angular joint, linear joint)
    "spring": ("N m/rad", "N/m"),
    "coulomb_friction": ("N m", "N"),
    "viscous_friction": ("N m s/rad", "N s/m"),
    "quadratic_drag": ("N m s^2/rad^2", "N s^2/m^2"),
    "constant_torque": ("N m", "N"),
    "input_gain": ("1", "1"),
    "input_delay": ("s", "s"),
}


@dataclasses.dataclass(frozen=True)
class Effect:
    """One physical effect on one joint (``"alpha"``, ``"beta"``, ``"p"``) or on the input (``"u"``).

    ``reference`` is the spring's rest position (ignored by other effects).
    """

    name: str
    joint: str
    coefficient: float
    reference: float = 0.0

    def __post_init__(self):
        if self.name not in JOINT_EFFECTS + INPUT_EFFECTS:
            raise ValueError(
                f"unknown effect {self.name!r}; expected one of {JOINT_EFFECTS + INPUT_EFFECTS}"
            )
        if (self.name in INPUT_EFFECTS) != (self.joint == "u"):
            where = "the input 'u'" if self.name in INPUT_EFFECTS else "a joint, not 'u'"
            raise ValueError(f"effect {self.name!r} acts on {where}; got joint={self.joint!r}")

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

    def generalized_force(self, q_j, qd_j, coulomb_smoothing: float = 0.0):
        """Force on its joint from joint position/velocity (jnp-traceable). Springs included.

        ``coulomb_smoothing`` > 0 replaces sgn(v) by tanh(v / smoothing) (for integrators).
        """
        c = self.coefficient
        if self.name == "spring":
            return -c * (q_j - self.reference)
        if self.name == "coulomb_friction":
            s = jnp.sign(qd_j) if coulomb_smoothing <= 0 else jnp.tanh(qd_j / coulomb_smoothing)
            return -c * s
        if self.name == "viscous_friction":
            return -c * qd_j
        if self.name == "quadratic_drag":
            return -c * qd_j * jnp.abs(qd_j)
        if self.name == "constant_torque":
            return c + 0.0 * q_j
        raise ValueError(f"{self.name!r} is an input effect, not a joint force")


class WithEffects(AbstractLagrangianSystem):
    """``base`` plus extra joint effects and an input gain; a Lagrangian system itself.

    Springs enter the potential (½k(q − q_ref)²) so energy and the force decomposition stay
    physical; friction, drag and constant torques enter τ_NC; ``input_gain`` scales τ_u.
    ``input_delay`` is rejected here (it is not memoryless).
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
            if e.name == "input_delay":
                raise ValueError(
                    "input_delay has no memoryless Lagrangian form; use the env's actuation delay"
                )
            if e.joint != "u":
                e.joint_index(base.spec)
        self.base = base
        self.effects = effects
        self.coulomb_smoothing = coulomb_smoothing

    def mass_matrix(self, q):
        return self.base.mass_matrix(q)

    def potential(self, q):
        v = self.base.potential(q)
        for e in self.effects:
            if e.name == "spring":
                j = e.joint_index(self.spec)
                v = v + 0.5 * e.coefficient * (q[j] - e.reference) ** 2
        return v

    def nonconservative_force(self, q, qd):
        tau = self.base.nonconservative_force(q, qd)
        for e in self.effects:
            if e.joint == "u" or e.name == "spring":
                continue
            j = e.joint_index(self.spec)
            tau = tau.at[j].add(e.generalized_force(q[j], qd[j], self.coulomb_smoothing))
        return tau

    def input_force(self, q, qd, u):
        gain = 1.0 + sum(e.coefficient for e in self.effects if e.name == "input_gain")
        return gain * self.base.input_force(q, qd, u)
