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
``input_dead_band``    τ_u(u) → τ_u(sgn u·max(|u| − d, 0)) ("u")    the input's (V or N)
=====================  ============================================  =======================

* ``spring`` with a non-zero ``reference``: a cable whose neutral is not at q_j = 0.
* ``stiction`` is the Stribeck breakaway above Coulomb friction: used with ``coulomb_friction``
  (F_c) and ΔF = F_s − F_c, the dry friction is −[F_c + ΔF·exp(−(q̇/v_s)²)]·sgn(q̇), F_s at
  rest. v_s is :attr:`Effect.stribeck_velocity` (rad/s or m/s, default 0.05).
* ``com_offset`` shifts the zero of the system's potential on joint j (all joints feel it):
  for the Furuta pendulum's β, a centre of mass off the pendulum's axis by the angle δ,
  V = ½·mp·g·Lp·(1 − cos(β − δ)), so it hangs at β = δ.
* ``actuator_lag``: the amplifier / motor electrical time constant (~1–20 ms).
* ``input_dead_band``: the input passes nothing until its magnitude exceeds the width d, then
  passes what exceeds it (slope 1), oddly (:func:`dead_band`): a motor driver, or brushes
  that need a least voltage to pass any current. It acts on the input after the input delay
  (the model's τ_u takes the dead-banded input; MuJoCo's control is dead-banded before the
  actuator), not on the rotor's velocity as a Coulomb friction does. d is in the system's input
  unit (V for the Furuta's motor voltage, N for the N-MSD's force), d ≥ 0.
* ``hysteretic_spring``: a cable whose neutral r moves: it stays put while |q_j − r| ≤ w
  (``play``) and is dragged along beyond (the play operator, r ∈ [q_j − w, q_j + w]); it starts
  at ``reference``. After a large swing the cable's neutral is left where the swing dragged it,
  up to w from the joint, so a rotor oscillating afterwards is pulled towards a centre that a
  fixed spring does not know. It has memory: :class:`CableNeutral` holds r.

Coulomb friction and stiction use sgn(0) = 0, or tanh(q̇/ε) with ``coulomb_smoothing`` ε > 0.

Each name is an :class:`EffectKind`, registered once (:data:`EFFECT_KINDS`): it holds the law,
the units, the MuJoCo form (:class:`MujocoForm`), the diagnosis library's scale and the physical
sign, so code elsewhere asks ``effect.kind`` and never compares names.

:class:`WithEffects` adds joint effects to any Lagrangian system (springs and ``com_offset``
into V, so energy stays right; the rest into τ_NC; the input gain and dead band into τ_u). ``input_delay`` and
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
    "EffectKind",
    "EFFECT_KINDS",
    "effect_kind",
    "MujocoForm",
    "JOINT_EFFECTS",
    "INPUT_EFFECTS",
    "DRY_FRICTION",
    "STATEFUL_EFFECTS",
    "EFFECT_UNITS",
    "INPUT_DYNAMICS_EFFECTS",
    "WithEffects",
    "spring_rests",
    "merge_spring_rests",
    "can_join",
    "ActuatorLag",
    "CableNeutral",
    "WithNeutral",
    "dragged_neutral",
    "cable_force",
    "play_operator",
    "actuator_lag_time",
    "dead_band",
    "effects_potential",
    "shaped_input",
]


# ----------------------------------------------------------------------------- the registry

#: every effect kind by name, in registration order (which is the diagnosis library's order)
EFFECT_KINDS: dict[str, "EffectKind"] = {}


@dataclasses.dataclass
class MujocoForm:
    """What effects write into a MuJoCo model (see :meth:`EffectKind.to_mujoco`): native joint
    stiffness (with Σ k·q_ref), damping and actuator gain, and the forces MuJoCo cannot express,
    which a passive-force callback applies (laws per dof, moving cable neutrals, a shift of the
    gravity potential)."""

    stiffness: np.ndarray
    stiff_ref: np.ndarray
    damping: np.ndarray
    gain: float = 1.0
    laws: dict[int, list["Effect"]] = dataclasses.field(default_factory=dict)
    neutrals: dict[int, list["CableNeutral"]] = dataclasses.field(default_factory=dict)
    shift: np.ndarray | None = None


class EffectKind:
    """One kind of physical effect, registered once by subclassing: the class attributes are its
    data (units, where it acts, its diagnosis scale), the methods its force law and its forms in a
    Lagrangian model and in MuJoCo. Everything that differs between kinds lives here, so code
    elsewhere asks a kind, never compares names; adding an effect is one subclass plus tests."""

    name: ClassVar[str]
    #: unit of the coefficient on an (angular, linear) joint
    units: ClassVar[tuple[str, str]]
    on_input: ClassVar[bool] = False
    #: has a state (no memoryless Lagrangian form); ``home`` says where it is applied instead
    has_memory: ClassVar[bool] = False
    home: ClassVar[str] = ""
    #: enters the potential: a term of its own (a spring) or a shift of its zero (a CoM offset)
    in_potential: ClassVar[bool] = False
    shifts_potential: ClassVar[bool] = False
    #: a law of q̇ that can hold a joint at rest (:meth:`dry_friction_limit`)
    is_dry_friction: ClassVar[bool] = False
    #: the coefficient of the physical effect is positive (restoring or dissipative)
    physically_positive: ClassVar[bool] = False
    #: the diagnosis library's typical coefficient on an (angular, linear) joint; None: no candidate
    typical: ClassVar[tuple[float, float] | None] = None
    #: library order on a joint (ties between effects the data cannot tell apart go to the lower)
    library_rank: ClassVar[int] = 0
    #: a candidate only on joints that gravity loads
    gravity_joints_only: ClassVar[bool] = False
    #: the diagnosis' input-dynamics form ("delay", "lag") of an input effect with memory
    input_dynamics: ClassVar[str | None] = None
    #: a constant force on its joint moves its rest position (−k·q + τ0 = −k·(q − τ0/k))
    absorbs_constant_force: ClassVar[bool] = False
    #: a constant force (what a spring absorbs)
    is_constant_force: ClassVar[bool] = False
    #: the dry friction this one is the breakaway above (a stiction's Coulomb friction)
    breakaway_above: ClassVar[str | None] = None
    #: a law with memory: the memoryless kind it generalises (the diagnosis tries it where that
    #: one is a candidate), the name of its second parameter (an :class:`Effect` field) and its bounds
    generalises: ClassVar[str | None] = None
    second_parameter: ClassVar[str] = ""
    second_bounds: ClassVar[tuple[float, float]] = (0.0, 0.0)
    #: scales the input force
    scales_input: ClassVar[bool] = False
    #: a memoryless law of the input itself (:meth:`input_law`), in the system's input unit, with
    #: the physical bounds of its coefficient
    shapes_input: ClassVar[bool] = False
    coefficient_bounds: ClassVar[tuple[float, float]] = (-math.inf, math.inf)
    #: what the sensor must resolve for a found value to mean something: "position" (one count)
    #: or "sample" (one sample period)
    resolution: ClassVar[str | None] = None

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if "name" in cls.__dict__:
            if cls.name in EFFECT_KINDS:
                raise ValueError(f"effect kind {cls.name!r} is registered twice")
            EFFECT_KINDS[cls.name] = cls()

    def __repr__(self) -> str:
        return f"<effect kind {self.name}>"

    def law(self, effect: "Effect", smoothing: float, xp) -> Callable[[Any, Any], Any] | None:
        """Its force f(q_j, q̇_j) in τ_NC; None when it enters the model elsewhere."""
        return None

    def potential_energy(self, effect: "Effect", q_j):
        """Its term of the potential (a spring's ½k(q_j − q_ref)²), if ``in_potential``."""
        return 0.0

    def potential_shift(self, effect: "Effect") -> float:
        """How far it moves the zero of the system's potential along its joint (δ), if
        ``shifts_potential``."""
        return 0.0

    def input_gain(self, effect: "Effect") -> float:
        """Its share g of the input force's factor (1 + Σ g)."""
        return 0.0

    def input_law(self, effect: "Effect", xp) -> Callable[[Any], Any] | None:
        """The input the plant takes, as a law of the commanded input (``shapes_input``)."""
        return None

    def dry_friction_limit(self, effect: "Effect", xp) -> Callable[[Any], Any]:
        raise ValueError(f"{self.name!r} is not dry friction; expected one of {DRY_FRICTION}")

    def to_mujoco(self, effect: "Effect", dof: int, form: MujocoForm) -> None:
        """Write it into ``form``: by default its law, through the passive-force callback."""
        form.laws.setdefault(dof, []).append(effect)


class _Spring(EffectKind):
    name, units, physically_positive = "spring", ("N m/rad", "N/m"), True
    typical, library_rank, in_potential = (1e-3, 1.0), 1, True
    absorbs_constant_force = True

    def law(self, effect, smoothing, xp):
        c, reference = effect.coefficient, effect.reference
        return lambda q, qd: -c * (q - reference)

    def potential_energy(self, effect, q_j):
        return 0.5 * effect.coefficient * (q_j - effect.reference) ** 2

    def to_mujoco(self, effect, dof, form):
        form.stiffness[dof] += effect.coefficient
        form.stiff_ref[dof] += effect.coefficient * effect.reference


class _DryFriction(EffectKind):
    is_dry_friction, physically_positive = True, True

    def law(self, effect, smoothing, xp):
        sgn = xp.sign if smoothing <= 0 else (lambda v: xp.tanh(v / smoothing))
        limit = self.dry_friction_limit(effect, xp)
        return lambda q, qd: -limit(qd) * sgn(qd)


class _CoulombFriction(_DryFriction):
    name, units, typical, library_rank = "coulomb_friction", ("N m", "N"), (1e-4, 0.1), 2

    def dry_friction_limit(self, effect, xp):
        c = effect.coefficient
        return lambda qd: c + 0.0 * qd


class _Stiction(_DryFriction):
    name, units, typical, library_rank = "stiction", ("N m", "N"), (1e-4, 0.1), 3
    breakaway_above = "coulomb_friction"

    def dry_friction_limit(self, effect, xp):
        c, v_s = effect.coefficient, effect.stribeck_velocity
        return lambda qd: c * xp.exp(-((qd / v_s) ** 2))


class _ViscousFriction(EffectKind):
    name, units, physically_positive = "viscous_friction", ("N m s/rad", "N s/m"), True
    typical, library_rank = (1e-5, 0.1), 4

    def law(self, effect, smoothing, xp):
        c = effect.coefficient
        return lambda q, qd: -c * qd

    def to_mujoco(self, effect, dof, form):
        form.damping[dof] += effect.coefficient


class _QuadraticDrag(EffectKind):
    name, units, physically_positive = "quadratic_drag", ("N m s^2/rad^2", "N s^2/m^2"), True
    typical, library_rank = (1e-6, 0.01), 5

    def law(self, effect, smoothing, xp):
        c = effect.coefficient
        return lambda q, qd: -c * qd * xp.abs(qd)


class _ConstantTorque(EffectKind):
    # the catch-all comes after the specific mechanisms in the library
    name, units, typical, library_rank = "constant_torque", ("N m", "N"), (1e-4, 0.1), 9
    is_constant_force = True

    def law(self, effect, smoothing, xp):
        c = effect.coefficient
        return lambda q, qd: c + 0.0 * q


class _ComOffset(EffectKind):
    # on a joint loaded by gravity a shifted potential comes first in the library
    name, units, typical, library_rank = "com_offset", ("rad", "m"), (1e-3, 1e-3), 0
    gravity_joints_only, resolution, shifts_potential = True, "position", True

    def potential_shift(self, effect):
        return effect.coefficient

    def to_mujoco(self, effect, dof, form):
        assert form.shift is not None
        form.shift[dof] += effect.coefficient


class _HystereticSpring(EffectKind):
    name, units, physically_positive = "hysteretic_spring", ("N m/rad", "N/m"), True
    has_memory = True
    home = "the MuJoCo plant (MujocoBackend) or an analytic model at its neutral (WithNeutral), which keep its state"
    # the memoryless law it generalises (play 0: a fixed cable) and its second parameter, fitted by
    # the diagnosis within these bounds (rad or m) where the memoryless one is in its library
    generalises, second_parameter, second_bounds = "spring", "play", (0.02, 2.0)

    def to_mujoco(self, effect, dof, form):
        form.neutrals.setdefault(dof, []).append(CableNeutral(effect))


class _InputEffect(EffectKind):
    on_input = True

    def to_mujoco(self, effect, dof, form):
        pass  # an input effect with memory lives in the env's actuation path (see ``home``)


class _InputGain(_InputEffect):
    name, units, typical, library_rank = "input_gain", ("1", "1"), (0.1, 0.1), 0
    scales_input = True

    def input_gain(self, effect):
        return effect.coefficient

    def to_mujoco(self, effect, dof, form):
        form.gain += effect.coefficient


class _InputDelay(_InputEffect):
    name, units, has_memory, home = "input_delay", ("s", "s"), True, "the env's actuation delay"
    input_dynamics, resolution = "delay", "sample"


class _InputDeadBand(_InputEffect):
    # memoryless, but MuJoCo has no native form: MujocoBackend dead-bands the control itself
    name, units, physically_positive = "input_dead_band", ("input", "input"), True
    shapes_input, coefficient_bounds = True, (0.0, math.inf)
    home = "the input: the model's τ_u (WithEffects) and MujocoBackend's control"

    def input_law(self, effect, xp):
        width = effect.coefficient
        return lambda u: dead_band(u, width, xp)


class _ActuatorLag(_InputEffect):
    name, units, has_memory = "actuator_lag", ("s", "s"), True
    home = "the env's actuation path (ActuatorLag) or MujocoBackend (actuator dynamics)"
    input_dynamics, resolution = "lag", "sample"


def effect_kind(name: str) -> EffectKind:
    """The registered kind called ``name``; a clear error for an unknown one."""
    try:
        return EFFECT_KINDS[name]
    except KeyError:
        raise ValueError(f"unknown effect {name!r}; expected one of {tuple(EFFECT_KINDS)}") from None


JOINT_EFFECTS = tuple(n for n, k in EFFECT_KINDS.items() if not k.on_input)
INPUT_EFFECTS = tuple(n for n, k in EFFECT_KINDS.items() if k.on_input)
#: friction bounded by a law of q̇ that can hold a joint at rest (:meth:`Effect.dry_friction_limit`)
DRY_FRICTION = tuple(n for n, k in EFFECT_KINDS.items() if k.is_dry_friction)
#: effects with memory: no Lagrangian (memoryless) form, applied in the env / plant
STATEFUL_EFFECTS = tuple(n for n, k in EFFECT_KINDS.items() if k.has_memory)
EFFECT_UNITS = {n: k.units for n, k in EFFECT_KINDS.items()}
#: the input effect of each input-dynamics form ("delay", "lag")
INPUT_DYNAMICS_EFFECTS = {k.input_dynamics: n for n, k in EFFECT_KINDS.items() if k.input_dynamics}


@dataclasses.dataclass(frozen=True)
class Effect:
    """One physical effect on one joint (``"alpha"``, ``"beta"``, ``"p"``) or on the input (``"u"``).

    ``name`` is a registered kind (:data:`EFFECT_KINDS`; :attr:`kind` is its type). ``reference``
    is the spring's rest position (a hysteretic spring's first neutral; ignored by other
    effects); ``stribeck_velocity`` is the stiction's v_s in rad/s or m/s and ``play`` the
    hysteretic spring's w in rad or m (each ignored by other effects).
    """

    name: str
    joint: str
    coefficient: float
    reference: float = 0.0
    stribeck_velocity: float = 0.05
    play: float = 0.0

    def __post_init__(self):
        kind = effect_kind(self.name)
        if kind.on_input != (self.joint == "u"):
            where = "the input 'u'" if kind.on_input else "a joint, not 'u'"
            raise ValueError(f"effect {self.name!r} acts on {where}; got joint={self.joint!r}")
        low, high = kind.coefficient_bounds
        if kind.shapes_input and not (math.isfinite(self.coefficient) and low <= self.coefficient <= high):
            raise ValueError(
                f"effect {self.name!r}: its width must be in [{low:g}, {high:g}] (the input's unit), "
                f"got {self.coefficient!r}"
            )
        if not (math.isfinite(self.play) and self.play >= 0):
            raise ValueError(f"effect {self.name!r}: play must be >= 0 (rad or m), got {self.play!r}")
        if not (math.isfinite(self.stribeck_velocity) and self.stribeck_velocity > 0):
            raise ValueError(
                f"effect {self.name!r}: stribeck_velocity must be > 0 (rad/s or m/s), got {self.stribeck_velocity!r}"
            )

    @property
    def kind(self) -> EffectKind:
        return EFFECT_KINDS[self.name]

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
        if self.kind.shapes_input:
            return spec.input_units[0]
        angular = self.joint == "u" or spec.angular[self.joint_index(spec)]
        return self.kind.units[0 if angular else 1]

    def generalized_force(self, q_j, qd_j, coulomb_smoothing: float = 0.0, xp: Any = jnp):
        """Force on its joint from joint position/velocity (see :meth:`law`). Springs included."""
        return self.law(coulomb_smoothing, xp)(q_j, qd_j)

    def law(self, coulomb_smoothing: float = 0.0, xp: Any = jnp) -> Callable[[Any, Any], Any]:
        """The effect's force law f(q_j, q̇_j) on its joint, written once for every user.

        ``coulomb_smoothing`` > 0 replaces sgn(v) by tanh(v / smoothing) (for integrators), in
        Coulomb friction and stiction alike. ``xp``: the namespace of sign/tanh/exp/abs
        (``jax.numpy``: traceable; MuJoCo's passive-force callback passes one for plain floats).
        A ``com_offset`` depends on the whole potential: see :meth:`com_offset_force`.
        """
        law = self.kind.law(self, coulomb_smoothing, xp)
        if law is not None:
            return law
        if self.kind.shifts_potential:
            raise ValueError(
                f"{self.name} shifts the system's potential, V(q) -> V(q - δ e_j); its force depends "
                "on V: use Effect.com_offset_force(potential, q, spec)"
            )
        if self.kind.has_memory and not self.kind.on_input:
            raise ValueError(f"{self.name} has memory (its moving neutral): use CableNeutral(effect)")
        raise ValueError(
            f"{self.name!r} is not a force law on a joint (it acts through {self.kind.home or 'the input'})"
        )

    def dry_friction_limit(self, xp: Any = jnp) -> Callable[[Any], Any]:
        """The largest force this dry friction exerts, as a law of q̇_j (N·m or N): F_c for
        ``coulomb_friction``, ΔF·exp(−(q̇_j/v_s)²) for ``stiction``. Sliding, the friction is
        −limit·sgn(q̇_j) (:meth:`law`); at rest it holds the joint against any smaller force
        (:func:`furuta_gym.lagrangian.forward_dynamics_with_dry_friction`)."""
        return self.kind.dry_friction_limit(self, xp)

    def shift(self, spec: SystemSpec):
        """δ·e_j: the vector by which it moves the zero of the potential (zero for most kinds)."""
        return jnp.zeros(spec.n_dof).at[self.joint_index(spec)].set(self.kind.potential_shift(self))

    def com_offset_force(self, potential, q, spec: SystemSpec):
        """Extra generalized force (all joints) of a potential shift (a ``com_offset``) on a system
        with potential ``potential(q)``: −∇V(q − δe_j) + ∇V(q) (jnp-traceable)."""
        shift = self.shift(spec)
        return jax.grad(potential)(q) - jax.grad(potential)(q - shift)


def effects_potential(potential, effects: Sequence[Effect], q, spec: SystemSpec):
    """``potential`` seen through the effects: its zero moved by their shifts (centre-of-mass
    offsets), plus their own terms (springs). Written once for every model with effects."""
    shift = jnp.zeros_like(q)
    for e in effects:
        if e.kind.shifts_potential:
            shift = shift + e.shift(spec).astype(q.dtype)
    v = potential(q - shift)
    for e in effects:
        if e.kind.in_potential:
            v = v + e.kind.potential_energy(e, q[e.joint_index(spec)])
    return v


def dead_band(u, width, xp: Any = np):
    """The input through a dead band of ``width`` d ≥ 0: sgn(u)·max(|u| − d, 0), zero for
    |u| ≤ d, slope 1 beyond, odd. Written once for the analytic model (:class:`WithEffects`),
    the MuJoCo plant and the diagnosis' windows (``xp``: numpy or jax.numpy)."""
    return xp.sign(u) * xp.maximum(xp.abs(u) - width, 0.0)


def shaped_input(effects: Sequence[Effect], xp: Any = np) -> Callable[[Any], Any] | None:
    """The input the plant takes as a law of the commanded one, the ``effects``' input laws in
    their order (an ``input_dead_band``); None when none of them shapes the input."""
    laws = [e.kind.input_law(e, xp) for e in effects if e.kind.shapes_input]
    if not laws:
        return None

    def shaped(u):
        for law in laws:
            u = law(u)
        return u

    return shaped


def dragged_neutral(neutral, q, play, xp: Any = np):
    """The play operator's one step: a cable's neutral ``neutral`` dragged to within ``play`` of
    the joint at ``q`` (unchanged while the joint stays within the play of it). Written once for
    the MuJoCo plant (:class:`CableNeutral`), the analytic model (:class:`WithNeutral`) and the
    diagnosis's neutral paths (:func:`play_operator`)."""
    return xp.minimum(xp.maximum(neutral, q - play), q + play)


def cable_force(stiffness, play, q_j, neutral, xp: Any = np):
    """A ``hysteretic_spring``'s force at q_j with its neutral as dragged there from ``neutral``
    (exact for a joint moving one way from where the neutral was last advanced)."""
    return -stiffness * (q_j - dragged_neutral(neutral, q_j, play, xp))


def play_operator(q, play: float, start: float) -> np.ndarray:
    """The neutral after each sample of the joint's path ``q`` (1-D), dragged from ``start``: what
    a ``hysteretic_spring`` of this ``play`` has been pulled to by the history ``q``."""
    out, r = np.empty(len(q)), float(start)
    lo, hi = np.asarray(q, dtype=float) - play, np.asarray(q, dtype=float) + play
    for k in range(len(out)):  # a recursion: each neutral depends on the last
        r = min(max(r, lo[k]), hi[k])
        out[k] = r
    return out


class CableNeutral:
    """The moving neutral r of a ``hysteretic_spring`` (the play operator): r starts at the
    effect's ``reference`` and is dragged along once the joint is more than ``play`` from it.

    :meth:`force` is the spring's force at q_j with r as it would be dragged to there (exact for a
    joint moving one way within a step); :meth:`advance` moves r once a plant step is done.
    """

    def __init__(self, effect: Effect):
        if not isinstance(effect.kind, _HystereticSpring):
            raise ValueError(f"CableNeutral is a hysteretic_spring's neutral; got {effect.name!r}")
        self.stiffness, self.play, self.start = effect.coefficient, effect.play, effect.reference
        self.reset()

    def reset(self) -> None:
        self.neutral = self.start

    def _dragged(self, q: float) -> float:
        return float(dragged_neutral(self.neutral, q, self.play, np))

    def force(self, q: float) -> float:
        return float(cable_force(self.stiffness, self.play, q, self.neutral, np))

    def advance(self, q: float) -> None:
        self.neutral = self._dragged(q)


class WithNeutral(AbstractLagrangianSystem):
    """``base`` plus a ``hysteretic_spring`` whose neutral stands at ``neutral``: the analytic
    model of the law with memory over one step, its force dragged within the step as
    :class:`CableNeutral`'s; the caller advances the neutral after each step
    (:func:`dragged_neutral` at the step's end), as the MuJoCo plant does. ``neutral`` may be
    traced (a predictor carries it through a scan)."""

    base: AbstractLagrangianSystem
    neutral: Any
    stiffness: Any
    play: Any
    joint: int = eqx.field(static=True)

    spec: ClassVar = property(lambda self: self.base.spec)  # type: ignore[assignment]

    def mass_matrix(self, q):
        return self.base.mass_matrix(q)

    def potential(self, q):
        return self.base.potential(q)

    def nonconservative_force(self, q, qd):
        f = cable_force(self.stiffness, self.play, q[self.joint], self.neutral, jnp)
        return self.base.nonconservative_force(q, qd).at[self.joint].add(f)

    def input_force(self, q, qd, u):
        return self.base.input_force(q, qd, u)


def actuator_lag_time(effects: Sequence[Effect]) -> float:
    """τ of the ``actuator_lag`` among ``effects`` (0.0: none); at most one, τ ≥ 0 finite."""
    lags = [e.coefficient for e in effects if e.kind.input_dynamics == "lag"]
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
    of what the lag changes (tests/test_effects_plants.py measures it); the mean is what keeps
    the agreement close, where u_m's value at the start or the end of the period would not.
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
    and constant torques enter τ_NC; ``input_gain`` scales τ_u, whose input an
    ``input_dead_band`` passes through its law first. ``input_delay`` and
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
            if e.kind.has_memory:
                raise ValueError(f"{e.name} has no memoryless Lagrangian form (it has a state); use {e.kind.home}")
            if e.joint != "u":
                e.joint_index(base.spec)
        self.base = base
        self.effects = effects
        self.coulomb_smoothing = coulomb_smoothing

    def mass_matrix(self, q):
        return self.base.mass_matrix(q)

    def potential(self, q):
        return effects_potential(self.base.potential, self.effects, q, self.spec)

    def nonconservative_force(self, q, qd):
        tau = self.base.nonconservative_force(q, qd)
        for e in self.effects:
            if e.kind.on_input or e.kind.in_potential or e.kind.shifts_potential:
                continue
            j = e.joint_index(self.spec)
            tau = tau.at[j].add(e.generalized_force(q[j], qd[j], self.coulomb_smoothing))
        return tau

    def input_force(self, q, qd, u):
        gain = 1.0 + sum(e.kind.input_gain(e) for e in self.effects)
        shaped = shaped_input(self.effects, jnp)
        return gain * self.base.input_force(q, qd, u if shaped is None else shaped(u))


def spring_rests(effects) -> dict[str, float]:
    """{joint: rest position τ0/k} where ``effects`` (anything with ``kind``, ``joint`` and
    ``coefficient``) hold a positive spring and a constant force on one joint: −k·q + τ0 is one
    spring whose rest position is not zero (a cable's neutral)."""
    constant = {e.joint: e for e in effects if e.kind.is_constant_force}
    return {
        e.joint: float(constant[e.joint].coefficient) / float(e.coefficient)
        for e in effects
        if e.kind.absorbs_constant_force and e.joint in constant and e.coefficient is not None and e.coefficient > 0
    }


def can_join(effect, found) -> bool:
    """Whether ``effect`` (anything with ``name``, ``kind``, ``joint`` and ``coefficient``) can
    join the effects ``found`` in a plant: of its physical sign, and a breakaway only above a dry
    friction found on its joint."""
    if effect.coefficient is None or (effect.kind.physically_positive and effect.coefficient <= 0):
        return False
    below = effect.kind.breakaway_above
    return not below or any((e.name, e.joint) == (below, effect.joint) for e in found)


def merge_spring_rests(effects: Sequence[Effect]) -> list[Effect]:
    """``effects`` with each spring and constant force on one joint written as one spring with
    its rest position (:func:`spring_rests`); the rest unchanged, in order."""
    rests = spring_rests(effects)
    out = []
    for e in effects:
        if e.joint in rests and e.kind.absorbs_constant_force:
            out.append(dataclasses.replace(e, reference=rests[e.joint]))
        elif not (e.joint in rests and e.kind.is_constant_force):
            out.append(e)
    return out
