"""One object per benchmark system: :class:`SystemDefinition`.

Each system's module (``_furuta.py``, ``_nmsd.py``) writes its physics once — the analytic model
and the same M, V, τ_NC in the parameters they are linear in (:class:`LumpedForm`, which the
diagnosis fits) — and states its defaults for the layers above (learned models, diagnosis,
synthetic logs, the reproduction). Code elsewhere asks the definition instead of branching on a
system's name; a third system is one new module plus a line in :data:`SYSTEM_DEFINITIONS`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, cast

import jax.numpy as jnp

from .._x64 import ensure_x64
from ..lagrangian import SystemSpec

__all__ = [
    "Equilibrium",
    "LumpedForm",
    "RigidBodyCondition",
    "SystemDefinition",
    "check_rigid_bodies",
    "first_joint_input",
    "parameter_defaults",
]

#: ``b(name)``: the value of a lumped parameter (a traced array inside a fit)
Lookup = Callable[[str], Any]


def scalar(x) -> jnp.ndarray:
    """A physical parameter as a float64 JAX scalar (the parameter classes' field converter)."""
    ensure_x64()
    return jnp.asarray(x, dtype=float)


def parameter_defaults(cls) -> dict[str, float]:
    """A parameter class's pinned values as plain floats, read from its fields (no JAX array is
    made: a MuJoCo-only env never touches JAX's configuration)."""
    return {f.name: float(cast(float, f.default)) for f in dataclasses.fields(cls)}


def first_joint_input(spec: SystemSpec, gain, u):
    """τ_u = (gain·u, 0, …): both systems drive their first joint only (the rotor; the mass)."""
    if spec.n_dof == 1:
        return gain * u[:1]
    return jnp.stack([gain * u[0], *([jnp.zeros_like(u[0])] * (spec.n_dof - 1))])


@dataclasses.dataclass(frozen=True)
class LumpedForm:
    """M, V and τ_NC written in the parameters they are linear in (base parameters ``names``);
    τ_u = (gain·u, 0, …) with gain the parameter named ``gain``.

    ``scale_anchor``: the base parameter held at its nominal value to fix the overall scale of
    forced data (``anchor_note(nominal, forced)`` says so in the report, or ``None``);
    ``mechanical_anchor``: the one also held on free data (u = 0), where the gain is not
    identifiable either. ``gravity_joints``: joints whose declared potential is gravity, so a
    centre-of-mass offset shifts it.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    nominal: Callable[[], dict[str, float]]
    mass_matrix: Callable[[Lookup, Any], Any]
    potential: Callable[[Lookup, Any], Any]
    damping: Callable[[Lookup, Any], Any]
    is_physical: Callable[[dict], bool]
    gain: str
    scale_anchor: str
    anchor_note: Callable[[dict, bool], str | None]
    mechanical_anchor: str
    gravity_joints: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class Equilibrium:
    """A rest position ``q`` (u = 0) whose potential shape the physics fixes: along ``joint`` (a
    joint name) V has a ``"minimum"`` (stable, ∂²V/∂q² > 0) or a ``"maximum"`` (unstable, < 0).
    A learned model must reproduce it (:func:`furuta_gym.training.consistency.check_potential_shape`)."""

    name: str
    q: tuple[float, ...]
    joint: str
    shape: str

    def __post_init__(self):
        if self.shape not in ("minimum", "maximum"):
            raise ValueError(f"Equilibrium {self.name!r}: shape must be 'minimum' or 'maximum', got {self.shape!r}")


@dataclasses.dataclass(frozen=True)
class RigidBodyCondition:
    """One thing bodies need of a system's lumped values: ``value`` (of ``expression``) > 0.
    ``parameters``: the lumped parameters it involves (which one to hold when it fails)."""

    expression: str
    value: float
    parameters: tuple[str, ...]

    @property
    def holds(self) -> bool:
        return bool(self.value > 0)


def check_rigid_bodies(lumped, conditions) -> None:
    """Raise, naming the first failed condition, if ``lumped`` has no rigid bodies."""
    for c in conditions:
        if not c.holds:
            raise ValueError(
                f"lumped parameters {dict(lumped)}: {c.expression} = {c.value:.3g} must be > 0 "
                "for a MuJoCo body (no rigid bodies have these values; their lumped model runs "
                "them: dynamics='analytic')"
            )


@dataclasses.dataclass(frozen=True)
class MujocoTerms:
    """What a system's MuJoCo writer leaves to the backend, per dof: native joint stiffness and
    damping, the cubic stiffness and damping MuJoCo cannot express (the passive callback's), and
    the motor as an affine actuator, force = ``motor_gain``·u + ``motor_bias``·q̇₀ (back-EMF)."""

    stiffness: tuple[float, ...]
    damping: tuple[float, ...]
    cubic_stiffness: tuple[float, ...] = ()
    cubic_damping: tuple[float, ...] = ()
    motor_gain: float = 1.0
    motor_bias: float = 0.0


@dataclasses.dataclass(frozen=True)
class SystemDefinition:
    """Everything about one system that is not a choice of model: spec, analytic model, lumped
    form, and the defaults the learned models, the diagnosis and the reproduction use.

    ``title``: its name in prose. ``learned_defaults``: the learned models' default
    hyper-parameters (reference magnitudes in SI, network widths, initial damping: order-of-
    magnitude guesses, deliberately not the true values); ``force_defaults``: F_a's design per
    model kind (``"aph"``, ``"adln"``) as the models' hyper-parameters of the same names:
    ``damping_scale``, the unit of the linear velocity term W (N·m·s/rad or N·s/m, of the order of
    the real damping so that Adam moves W as fast as the network's weights), ``force_activation``,
    the network's activation, and ``odd_in_velocity`` (all chosen on validation data,
    docs/reproduce.md).
    ``friction_parameters``: the analytic parameters that are friction (APHYNITY's prior has
    none); ``back_emf_parameter``: the one that makes the input force depend on velocity, or
    ``None``; ``back_emf_damping``: its pinned damping (DeLaN lumps it with friction).
    ``known_damping_force(coefficients, q̇)``: the paper's τ_NC structure with given positive
    coefficients (DeLaN). ``excitations``: the synthetic experiments of
    :func:`furuta_gym.rigs.measured_like`; ``chirp_ranges``: its random chirps' amplitude,
    start and end frequency and offset ranges (offset ``None``: no offset drawn).
    ``chirp_initial_ranges``: their initial states' (low, high) per state variable; ``encoders``:
    the joints are measured by quadrature encoders (else by a position sensor with Gaussian noise).
    ``lumped_values(parameters)``: the values the lumped form and ``energy`` use, from a mapping
    of physical parameter floats; ``energy(values, x)``: T + V on plain floats (the envs' info).
    ``diagnosis_substeps``: RK4 steps per sample of the diagnosis's open-loop predictions, whose
    dry friction holds a joint at rest within one step
    (:func:`~furuta_gym.lagrangian.forward_dynamics_with_dry_friction`, relaxation = the step).
    ``elementary_seconds``: the length of the elementary trajectories measured logs are cut into
    for training (:func:`furuta_gym.measured.split_elementary`). ``energy_panels``: (state index, grid low, grid high, grid factor, label) of the
    reproduction's energy figure. ``write_mujoco(model, parameters)``: writes the physical
    parameters' bodies, inertias and gravity into an ``MjModel`` of the system's MJCF and returns
    the rest as :class:`MujocoTerms` (no MuJoCo import needed: it only sets the model's arrays).
    ``write_lumped_mujoco(model, lumped)``: the same from the lumped form's values (what the
    diagnosis fits: :class:`furuta_gym.envs.Plant`), or ``None``. ``body_conditions(lumped)``: what
    bodies need of those values (:class:`RigidBodyCondition`, each > 0), or ``None``.
    ``equilibria``: the rest positions whose potential shape (minimum / maximum) the physics
    fixes, each an :class:`Equilibrium`; training checks a learned potential against them.
    """

    spec: SystemSpec
    title: str
    model: type
    parameters: type
    lumped: LumpedForm
    learned_defaults: dict
    force_defaults: dict[str, dict[str, Any]]
    learnable_parameters: tuple[str, ...]
    friction_parameters: tuple[str, ...]
    known_damping_force: Callable[[Any, Any], Any]
    sample_period: float
    chirp_ranges: tuple
    chirp_initial_ranges: tuple
    chirp_end_frequency: float
    diagnosis_window: float
    diagnosis_segment_seconds: float
    elementary_seconds: float
    diagnosis_substeps: int
    table_title: str
    energy_panels: tuple
    lumped_values: Callable[[Any], dict]
    energy: Callable[[Any, Any], float]
    write_mujoco: Callable[[Any, Any], MujocoTerms]
    back_emf_parameter: str | None = None
    back_emf_damping: float | None = None
    excitations: tuple[str, ...] = ("chirp",)
    encoders: bool = False
    scale_fit_on_forced_data: bool = False
    equilibria: tuple[Equilibrium, ...] = ()
    write_lumped_mujoco: Callable[[Any, Any], MujocoTerms] | None = None
    body_conditions: Callable[[Any], tuple["RigidBodyCondition", ...]] | None = None

    @property
    def name(self) -> str:
        return self.spec.name

    def input_force(self, gain, u):
        """τ_u of the lumped form: ``gain``·u on the first joint."""
        return first_joint_input(self.spec, gain, u)
