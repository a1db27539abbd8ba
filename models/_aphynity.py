"""APHYNITY (Yin et al. 2021) as in Laiche et al. 2026, §3 and appendix A.1.

The prior F_p is the analytic model *without friction* (Furuta: c_r = c_p = 0; N-MSD: b1 = b2 = 0)
whose physical parameters are learnable, plus an additive network F_a(q, q̇) for the missing
generalized force, so τ_NC = F_a. Physical parameters are learned as log-ratios to their nominal
values (param = nominal · exp(θ)): Adam's steps are then relative, whatever the parameter's unit.
Learnable: Furuta mr, Lr, mp, Lp (g and the motor constants kt, km, Rm are known); N-MSD m, k1, k2.
The Furuta prior's input force is the motor gain alone, (kt/Rm)·u; the back-EMF −(kt·km/Rm)·α̇
is left to F_a with the rotor friction, as DeLaN and augmented DeLaN do (``prior_back_emf=True``
puts it back in the prior). On free data the two are one regressor, and the overall scale fitted
afterwards on a forced trajectory (:func:`furuta_gym.training.fit_scale`) multiplies M, V and
F_a: a back-EMF left unscaled in the prior breaks that symmetry and the fitted model's rotor
damping comes out wrong (measured: −25 %, the scale fit's residual 7–11 % instead of < 1 %).
Trained with L_aph = ‖F_a‖² + λ·L_traj, λ by dual ascent (:mod:`furuta_gym.training.losses`),
or L_prop (with the same minimum-norm principle for F_a).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..lagrangian import SystemSpec
from ..systems import get_spec
from ._augmented import AbstractAugmentedSystem, ForceNetwork, force_hparams
from ._definitions import SYSTEM_DEFINITIONS, system_definition
from ._learned import freeze_hparams, system_defaults, with_given

__all__ = ["Aphynity", "LEARNABLE_PHYSICAL_PARAMETERS"]

LEARNABLE_PHYSICAL_PARAMETERS = {name: d.learnable_parameters for name, d in SYSTEM_DEFINITIONS.items()}


class Aphynity(AbstractAugmentedSystem):
    """APHYNITY (aph): frictionless analytic prior with learnable parameters + F_a network."""

    kind: ClassVar[str] = "aph"
    label: ClassVar[str] = "APH"
    analytic_prior: ClassVar[bool] = True
    log_ratios: Float[Array, " k"]
    force_net: ForceNetwork
    scale: Float[Array, ""]
    spec: SystemSpec = eqx.field(static=True)
    nominal: tuple[tuple[str, float], ...] = eqx.field(static=True)
    hparams: tuple[tuple[str, Any], ...] = eqx.field(static=True)

    @classmethod
    def form_1_hparams(cls, hparams: dict[str, Any]) -> dict[str, Any]:
        """Form 1 kept the back-EMF in the prior."""
        out = dict(hparams)
        out.setdefault("prior_back_emf", True)
        return super().form_1_hparams(out)

    @classmethod
    def _form_1_force_activation(cls, hparams: dict[str, Any]) -> str:
        # form 1's ``activation`` was F_a's own (APHYNITY has no other network): renamed
        return hparams.pop("activation", "tanh")

    def __init__(self, system: str, *, key: PRNGKeyArray, **hparams):
        spec = get_spec(system)
        hp = system_defaults(spec.name)
        for k in ("damping_init", "mass_scale", "potential_scale", "input_gain"):
            hp.pop(k)
        hp["prior"] = ()  # overrides of nominal parameter values, e.g. (("mp", 0.03),)
        hp["prior_back_emf"] = False  # Furuta: keep −(kt·km/Rm)·α̇ in the prior's τ_u
        hp.update(force_hparams(spec, "aph"))
        hp = with_given("APHYNITY", hp, hparams)
        definition = system_definition(spec)
        params = definition.parameters()
        overrides = dict(hp["prior"])
        nominal = {}
        for name in dataclass_fields(params):
            value = float(overrides.pop(name, getattr(params, name)))
            nominal[name] = value
        if overrides:
            raise ValueError(f"prior names unknown physical parameters {sorted(overrides)}")
        # friction is what the network must find: the prior has none
        for name in definition.friction_parameters:
            nominal[name] = 0.0
        if definition.back_emf_parameter is not None and not hp["prior_back_emf"]:
            nominal[definition.back_emf_parameter] = 0.0  # the back-EMF −(kt·km/Rm)·α̇ is F_a's (module docstring)
        self.nominal = tuple(nominal.items())
        self.log_ratios = jnp.zeros(len(definition.learnable_parameters))
        self.force_net = ForceNetwork.from_hparams(spec, hp, hidden=hp["hidden"], key=key)
        self.scale = jnp.asarray(1.0)
        self.spec = spec
        self.hparams = freeze_hparams(hp)

    def networks(self):
        return (self.force_net.net,)

    @property
    def physical_parameters(self) -> dict[str, Any]:
        """The prior's current physical parameter values (learned ones included)."""
        values: dict[str, Any] = dict(self.nominal)
        for i, name in enumerate(system_definition(self.spec).learnable_parameters):
            values[name] = values[name] * jnp.exp(self.log_ratios[i])
        return values

    @property
    def prior(self):
        """The frictionless analytic model with the current physical parameters."""
        values = self.physical_parameters
        definition = system_definition(self.spec)
        return definition.model(params=definition.parameters(**values))

    def mass_matrix(self, q):
        return self.scale * self.prior.mass_matrix(q)

    def potential(self, q):
        return self.scale * self.prior.potential(q)

    def input_force(self, q, qd, u):
        return self.prior.input_force(q, qd, u)


def dataclass_fields(module) -> list[str]:
    return [f.name for f in dataclasses.fields(module)]
