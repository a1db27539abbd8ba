"""Linear-in-parameters ("lumped") forms of the declared models and the candidate-effect library.

The integral inverse residual Z̄ − Ā (Laiche et al. 2026, eq. 8-10) is linear in the *base* (lumped)
parameters of both benchmark systems and in the coefficient of every candidate effect of
:mod:`furuta_gym.effects`. :class:`LumpedModel` is a Lagrangian system whose M, V, τ_NC, τ_u are
written in those parameters, one flat vector ``theta`` = base parameters followed by one
coefficient per library effect. Because the residual is linear in ``theta``, its Jacobian (taken by
autodiff, through :func:`furuta_gym.lagrangian.momentum` and friends) *is* the regressor matrix of
the equation-error fit, and the same model simulated open loop is the output-error model.

Furuta lumped parameters (docs/conventions.md):

=============  =====================================  ==============
``J1``         Jr + mp·Lr²                            kg m²
``J1b``        ¼·mp·Lp²   (the sin²β term of M11)     kg m²
``Jc``         ½·mp·Lr·Lp (the coupling, cos β)       kg m²
``J2``         Jp + ¼·mp·Lp²                          kg m²
``G``          ½·mp·g·Lp  (V = G(1 − cos β))          N m
``c_alpha``    c_r + kt·km/Rm (friction + back-EMF)   N m s/rad
``c_beta``     c_p                                    N m s/rad
``K``          kt/Rm      (τ_u,α = K·u)                N m/V
=============  =====================================  ==============

Rotor viscous friction and back-EMF are the same regressor (−α̇) on any data, so they are one
parameter here. N-MSD: ``m, k1, k2, b1, b2`` and the input gain ``gain`` (τ_u = gain·u, 1 for a
force in newtons).
"""

from __future__ import annotations

import dataclasses
from typing import Callable, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..effects import EFFECT_KINDS, Effect, EffectKind, effects_potential
from ..lagrangian import AbstractLagrangianSystem, SystemSpec
from ..models import system_definition
from ..systems import get_spec

__all__ = [
    "Candidate",
    "ParameterLayout",
    "LumpedModel",
    "LearnedWithLibrary",
    "layout_for",
    "nominal_base",
    "check_input_linear",
    "is_physical",
    "non_physical",
]


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One library effect: ``name`` from :mod:`furuta_gym.effects` on ``joint`` (or ``"u"``)."""

    name: str
    joint: str

    @property
    def key(self) -> str:
        return f"{self.name}:{self.joint}"

    @property
    def kind(self) -> EffectKind:
        return EFFECT_KINDS[self.name]

    def unit(self, spec: SystemSpec) -> str:
        angular = self.joint == "u" or spec.angular[spec.joint_names.index(self.joint)]
        return self.kind.units[0 if angular else 1]


def nominal_base(system: str) -> dict[str, float]:
    """The pinned analytic model's values of the lumped parameters."""
    return system_definition(system).lumped.nominal()


@dataclasses.dataclass(frozen=True)
class ParameterLayout:
    """Where each base parameter and each library effect lives in the flat ``theta``."""

    system: str
    base: tuple[str, ...]
    base_units: tuple[str, ...]
    candidates: tuple[Candidate, ...]  # memoryless library effects (delay is handled apart)
    # a learned (or any) Lagrangian model taken as the declared model: its one base parameter is
    # an overall scale (held at 1), the library effects are added around it
    learned: AbstractLagrangianSystem | None = dataclasses.field(default=None, compare=False, repr=False)

    @property
    def cache_key(self):
        """What identifies this layout's compiled functions (the system, or the learned model)."""
        return self.system if self.learned is None else ("learned", id(self.learned))

    def model(self, theta, dry_friction: bool = True) -> AbstractLagrangianSystem:
        """The Lagrangian system of parameters ``theta`` (declared model + library effects);
        ``dry_friction=False`` leaves the library's dry friction out of τ_NC (a predictor then
        adds it with :meth:`dry_friction_limit`)."""
        if self.learned is None:
            return LumpedModel(theta=theta, system=self.system, dry_friction=dry_friction)
        return LearnedWithLibrary(theta=theta, base=self.learned, dry_friction=dry_friction)

    def dry_friction_limit(self, theta, qd):
        """The library's dry friction at q̇ as the largest force per joint (N·m or N), for
        :func:`furuta_gym.lagrangian.forward_dynamics_with_dry_friction`; a negative
        coefficient counts as none."""
        spec = get_spec(self.system)
        n_base = len(self.base)
        limit = [0.0 * qd[j] for j in range(spec.n_dof)]
        for e in _library_effects(theta, self.system, n_base, lambda k: k.is_dry_friction):
            j = e.joint_index(spec)
            limit[j] = limit[j] + jnp.maximum(e.dry_friction_limit()(qd[j]), 0.0)
        return jnp.stack(limit)

    @property
    def size(self) -> int:
        return len(self.base) + len(self.candidates)

    def index(self, name: str) -> int:
        """Index of a base parameter name or a candidate key ``"effect:joint"``."""
        if name in self.base:
            return self.base.index(name)
        keys = [c.key for c in self.candidates]
        if name in keys:
            return len(self.base) + keys.index(name)
        raise ValueError(
            f"unknown parameter {name!r} for {self.system}; base parameters are {list(self.base)}, effects are {keys}"
        )

    def nominal(self) -> np.ndarray:
        nom = nominal_base(self.system) if self.learned is None else {"scale": 1.0}
        return np.array([nom[b] for b in self.base] + [0.0] * len(self.candidates))

    def typical_scale(self) -> np.ndarray:
        """Magnitudes used to scale the fits (base: nominal values; effects: typical sizes)."""
        spec = get_spec(self.system)
        out = list(np.abs(self.nominal()[: len(self.base)]))
        for c in self.candidates:
            angular = c.joint == "u" or spec.angular[spec.joint_names.index(c.joint)]
            out.append(c.kind.typical[0 if angular else 1])
        return np.array(out)


def layout_for(system: str, learned: AbstractLagrangianSystem | None = None) -> ParameterLayout:
    """The lumped base parameters of ``system`` plus every memoryless library effect; with a
    ``learned`` model, that model (scale 1) instead of the lumped declared model."""
    spec = get_spec(system)
    # library order (each kind's rank) breaks ties between effects the data cannot tell apart
    kinds = sorted(
        (k for k in EFFECT_KINDS.values() if k.typical is not None and not k.has_memory), key=lambda k: k.library_rank
    )
    cands = []
    for j in spec.joint_names:
        gravity = j in system_definition(spec).lumped.gravity_joints
        cands += [Candidate(k.name, j) for k in kinds if not k.on_input and (gravity or not k.gravity_joints_only)]
    cands += [Candidate(k.name, "u") for k in kinds if k.on_input]
    if learned is not None:
        return ParameterLayout(spec.name, ("scale",), ("1",), tuple(cands), learned)
    lumped = system_definition(spec).lumped
    return ParameterLayout(system=spec.name, base=lumped.names, base_units=lumped.units, candidates=tuple(cands))


def _library_effects(theta, system: str, n_base: int, which: Callable[[EffectKind], bool]) -> list[Effect]:
    """The library effects whose kind ``which`` accepts, with their coefficients in ``theta``
    (jnp-traceable)."""
    cands = layout_for(system).candidates
    return [Effect(c.name, c.joint, theta[n_base + i]) for i, c in enumerate(cands) if which(c.kind)]


def _library_potential(theta, system, n_base, q, declared_potential):
    """The declared potential seen through the centre-of-mass offsets (linear in δ at δ = 0,
    where the equation-error regressors are taken), plus the springs' ½k·q²."""
    effects = _library_effects(theta, system, n_base, lambda k: k.in_potential or k.shifts_potential)
    return effects_potential(declared_potential, effects, q, get_spec(system))


def _library_force(theta, system, n_base, q, qd, dry_friction: bool):
    """Generalized force of the library's joint effects, the laws of :mod:`furuta_gym.effects`
    (dry friction with sgn(q̇), or left out)."""
    spec = get_spec(system)
    tau = [0.0 * qd[j] for j in range(spec.n_dof)]

    def in_tau_nc(k: EffectKind) -> bool:
        return not (k.on_input or k.in_potential or k.shifts_potential) and (dry_friction or not k.is_dry_friction)

    for e in _library_effects(theta, system, n_base, in_tau_nc):
        j = e.joint_index(spec)
        tau[j] = tau[j] + e.generalized_force(q[j], qd[j])
    return jnp.stack(tau)


def _library_gain(theta, system, n_base):
    return 1.0 + sum(e.coefficient for e in _library_effects(theta, system, n_base, lambda k: k.scales_input))


class LumpedModel(AbstractLagrangianSystem):
    """The declared model written in its lumped parameters, plus every library effect.

    ``theta`` follows :func:`layout_for`; effects with a zero coefficient are absent. Springs go
    into V (rest position 0), the other joint effects into τ_NC, the input gain into τ_u (as
    :class:`furuta_gym.effects.WithEffects` does). Dry friction uses sgn(q̇) (the equation-error
    fit) or, with ``dry_friction=False``, is left to the predictor (see :meth:`ParameterLayout.model`).
    """

    theta: jnp.ndarray
    system: str = eqx.field(static=True)
    dry_friction: bool = eqx.field(static=True, default=True)

    spec: ClassVar = property(lambda self: get_spec(self.system))  # type: ignore[assignment]

    @property
    def _lumped(self):
        return system_definition(self.system).lumped

    def _base(self, name):
        return self.theta[self._lumped.names.index(name)]

    @property
    def _n_base(self) -> int:
        return len(self._lumped.names)

    def mass_matrix(self, q):
        return self._lumped.mass_matrix(self._base, q)

    def _declared_potential(self, q):
        return self._lumped.potential(self._base, q)

    def potential(self, q):
        return _library_potential(self.theta, self.system, self._n_base, q, self._declared_potential)

    def nonconservative_force(self, q, qd):
        tau = self._lumped.damping(self._base, qd)
        return tau + _library_force(self.theta, self.system, self._n_base, q, qd, self.dry_friction)

    def input_force(self, q, qd, u):
        gain = self._base(self._lumped.gain) * _library_gain(self.theta, self.system, self._n_base)
        return system_definition(self.system).input_force(gain, u)


class LearnedWithLibrary(AbstractLagrangianSystem):
    """A given Lagrangian model (e.g. a trained DeLaN) times an overall scale ``theta[0]``, plus
    every library effect, coefficients in ``theta[1:]`` (as :class:`LumpedModel` lays them out).

    The model's input force is split into its part at u = 0 (e.g. a back-EMF), which joins τ_NC,
    and the part that grows with u, which must be B·u with a constant B (checked by
    :func:`check_input_linear`): the equation-error fit integrates the input as ∫u·B.
    """

    theta: jnp.ndarray
    base: AbstractLagrangianSystem
    dry_friction: bool = eqx.field(static=True, default=True)

    spec: ClassVar = property(lambda self: self.base.spec)  # type: ignore[assignment]

    def mass_matrix(self, q):
        return self.theta[0] * self.base.mass_matrix(q)

    def potential(self, q):
        return _library_potential(self.theta, self.spec.name, 1, q, lambda x: self.theta[0] * self.base.potential(x))

    def nonconservative_force(self, q, qd):
        zero_u = jnp.zeros(len(self.spec.input_names))
        own = self.base.nonconservative_force(q, qd) + self.base.input_force(q, qd, zero_u)
        return self.theta[0] * own + _library_force(self.theta, self.spec.name, 1, q, qd, self.dry_friction)

    def input_force(self, q, qd, u):
        zero_u = jnp.zeros_like(u)
        driven = self.base.input_force(q, qd, u) - self.base.input_force(q, qd, zero_u)
        return self.theta[0] * _library_gain(self.theta, self.spec.name, 1) * driven


def check_input_linear(model: AbstractLagrangianSystem, seed: int = 0) -> None:
    """Raise if ``model``'s input force is not B·u + f(q, q̇) with a constant B (what the
    diagnosis of a learned model assumes), tested at random states and inputs."""
    rng = np.random.default_rng(seed)
    n, m = model.spec.n_dof, len(model.spec.input_names)
    ref = None
    for _ in range(8):
        q, qd, u = (jnp.asarray(rng.normal(size=k)) for k in (n, n, m))
        driven = np.asarray(model.input_force(q, qd, u) - model.input_force(q, qd, jnp.zeros(m)))
        unit = np.asarray(model.input_force(q, qd, jnp.ones(m)) - model.input_force(q, qd, jnp.zeros(m)))
        ref = unit if ref is None else ref
        if not (
            np.allclose(driven, unit * np.asarray(u)[0], rtol=1e-8, atol=1e-12)
            and np.allclose(unit, ref, rtol=1e-8, atol=1e-12)
        ):
            raise ValueError(
                "model: its input force is not B·u + f(q, q̇) with a constant B; the "
                "diagnosis of a given model needs that form"
            )


def is_physical(layout: ParameterLayout, theta) -> bool:
    """Positive-definite mass matrix for every angle and non-negative declared damping (a given
    model's own physics is taken as it is: only its scale, held at 1, is a base parameter)."""
    if layout.learned is not None:
        return bool(theta[0] > 0)
    p = {b: theta[i] for i, b in enumerate(layout.base)}
    return system_definition(layout.system).lumped.is_physical(p)


def non_physical(layout: ParameterLayout, theta, effects) -> list[str]:
    """Keys of ``effects`` whose coefficient in ``theta`` has the non-physical sign."""
    return [c.key for c in effects if c.kind.physically_positive and theta[layout.index(c.key)] <= 0]
