"""Augmented DeLaN (Wu et al. 2024) as in Laiche et al. 2026, §3 and appendix A.1.

DeLaN's conservative part (Cholesky-factor mass matrix, potential network) plus a network for the
whole non-conservative force, τ_NC = F_a(q, q̇) = force_scale · net(features(q), q̇ / velocity_scale),
trained with L_aph (‖F_a‖ + λ·L_traj) or L_prop. As in :mod:`._delan`, the Furuta motor's
back-EMF is not in τ_u (only (kt/Rm)·u is): F_a learns it together with the rotor friction.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..lagrangian import SystemSpec
from ..systems import get_spec
from ._definitions import SYSTEM_DEFINITIONS
from ._delan import LagrangianNetworks
from ._learned import (
    LEARNED_EXTRAS,
    MLP,
    AbstractLearnedSystem,
    coordinate_features,
    feature_size,
    freeze_hparams,
    system_defaults,
    with_given,
)
from ._system import first_joint_input

__all__ = ["AugmentedDeLaN", "AbstractAugmentedSystem", "ForceNetwork", "FORCE_DEFAULTS"]


#: F_a's design per system and model kind (APHYNITY, augmented DeLaN), as ForceNetwork's
#: hyper-parameters: W's unit (``damping_scale``: W = 1 is this damping, N·m·s/rad or N·s/m),
#: the network's activation, odd in q̇ or general. Chosen on validation data (docs/reproduce.md,
#: decision log); each system's definition holds its own.
FORCE_DEFAULTS = {name: d.force_defaults for name, d in SYSTEM_DEFINITIONS.items()}


class ForceNetwork(eqx.Module):
    """F_a(q, q̇) = force_scale · net(x) + damping_scale · W·q̇, x = ((cos, sin) / scaled q,
    q̇ / velocity_scale).

    The linear term W (starts at zero) is there for extrapolation in velocity: a tanh network
    saturates outside the velocities it was trained on, while viscous friction and back-EMF keep
    growing linearly. The paper's Furuta test sets start at |q̇| up to 20 rad/s, four times the
    training range, where a network without W under-damped the rotor.

    ``odd_in_velocity``: the network part becomes ½(net(q, q̇) − net(q, −q̇)), odd in q̇ by
    construction, so F_a(q, 0) = 0: a force of friction type (viscous, cubic, Coulomb are all odd)
    and nothing even in q̇ — no spring, no gravity, no constant torque — which a general F_a can
    take over from V at no cost to L_Iτ. Off unless a model asks for it (the paper's F_a is
    general; augmented DeLaN on the N-MSD asks, :data:`FORCE_DEFAULTS`); it rules out
    real even effects such as a cable's spring, which the diagnosis loop looks for.

    ``linear_velocity``: ``"diagonal"`` (the models' default) one viscous coefficient per joint,
    each joint's friction from its own velocity, as in a bearing; ``True`` a full n × n matrix;
    ``False`` no linear term. The full matrix's off-diagonal entries are not friction: on the
    Furuta they fitted an α̇ → β torque (4.9e-6 N·m·s/rad) that does not exist, and augmented
    DeLaN predicted validation trajectories better per joint (docs/reproduce.md, "Training
    recipe"). The network part stays fully general.
    """

    net: MLP
    linear: Float[Array, "n n"] | Float[Array, " n"] | None
    spec: SystemSpec = eqx.field(static=True)
    force_scale: float = eqx.field(static=True)
    position_scale: float = eqx.field(static=True)
    velocity_scale: float = eqx.field(static=True)
    damping_scale: float = eqx.field(static=True)
    odd_in_velocity: bool = eqx.field(static=True)

    def __init__(
        self,
        spec,
        *,
        key,
        hidden,
        force_scale,
        position_scale,
        velocity_scale,
        activation="tanh",
        linear_velocity=True,
        damping_scale=None,
        odd_in_velocity=False,
    ):
        n = spec.n_dof
        self.net = MLP(feature_size(spec) + n, n, tuple(hidden), key=key, activation=activation, final_scale=0.1)
        # a string must name the per-joint term; anything else is read as a flag (hyper-parameters
        # from older checkpoint headers are JSON booleans)
        if isinstance(linear_velocity, str) and linear_velocity != "diagonal":
            raise ValueError(f"linear_velocity must be True, False or 'diagonal', got {linear_velocity!r}")
        if linear_velocity == "diagonal":
            self.linear = jnp.zeros(n)  # one viscous coefficient per joint, from its own velocity
        else:
            self.linear = jnp.zeros((n, n)) if linear_velocity else None
        self.spec = spec
        self.force_scale = float(force_scale)
        self.position_scale = float(position_scale)
        self.velocity_scale = float(velocity_scale)
        # None: the scale models saved before damping_scale existed were trained with
        self.damping_scale = float(force_scale / velocity_scale if damping_scale is None else damping_scale)
        if not isinstance(odd_in_velocity, bool):
            raise ValueError(f"odd_in_velocity must be True or False, got {odd_in_velocity!r}")
        self.odd_in_velocity = odd_in_velocity

    @classmethod
    def from_hparams(cls, spec, hp: dict[str, Any], *, hidden, key) -> "ForceNetwork":
        """The F_a of a model whose hyper-parameters ``hp`` hold :func:`force_hparams`' keys and
        the feature scales; ``hidden`` its layer widths."""
        return cls(
            spec,
            key=key,
            hidden=tuple(hidden),
            force_scale=hp["force_scale"],
            position_scale=hp["position_scale"],
            velocity_scale=hp["velocity_scale"],
            activation=hp["force_activation"],
            linear_velocity=hp["linear_velocity"],
            damping_scale=hp["damping_scale"],
            odd_in_velocity=hp["odd_in_velocity"],
        )

    def __call__(self, q, qd):
        out = self.beyond_linear(q, qd)
        if self.linear is not None:
            viscous = self.linear * qd if self.linear.ndim == 1 else self.linear @ qd
            out = out + self.damping_scale * viscous
        return out

    def beyond_linear(self, q, qd):
        """The network's part of F_a: F_a without the linear viscous term W·q̇."""
        features = coordinate_features(self.spec, q, self.position_scale)
        out = self.net(jnp.concatenate([features, qd / self.velocity_scale]))
        if self.odd_in_velocity:
            out = 0.5 * (out - self.net(jnp.concatenate([features, -qd / self.velocity_scale])))
        return self.force_scale * out


def force_hparams(spec: SystemSpec, kind: str) -> dict[str, Any]:
    """F_a's default hyper-parameters for model ``kind`` on ``spec``'s system: W per joint, then
    the system's :data:`FORCE_DEFAULTS` (W's unit, activation, odd in q̇)."""
    return {"linear_velocity": "diagonal", **FORCE_DEFAULTS[spec.name][kind]}


class AbstractAugmentedSystem(AbstractLearnedSystem):
    """A learned model whose whole τ_NC is the data-driven force F_a (APHYNITY, augmented DeLaN):
    a subclass holds it as its field ``force_net``, a :class:`ForceNetwork`. (Not declared here
    as an abstract field: that would move it in the subclasses' field order, which saved
    checkpoints' leaves follow.)"""

    if TYPE_CHECKING:
        force_net: ForceNetwork

    @property
    def has_augmentation(self) -> bool:
        return True

    @classmethod
    def form_1_hparams(cls, hparams: dict[str, Any]) -> dict[str, Any]:
        """Form 1 had no linear W (so no scale of its own) and an F_a even in q̇."""
        out = dict(hparams)
        out.setdefault("linear_velocity", False)
        out.setdefault("damping_scale", None)  # W in units of force_scale / velocity_scale
        out.setdefault("odd_in_velocity", False)
        if "force_activation" not in out:
            out["force_activation"] = cls._form_1_force_activation(out)
        return out

    @classmethod
    def _form_1_force_activation(cls, hparams: dict[str, Any]) -> str:
        """Form 1's F_a activation: the model's ``activation`` (augmented DeLaN's networks share it)."""
        return hparams.get("activation", "tanh")

    def augmentation(self, q, qd):
        return self.scale * self.force_net(q, qd)

    def augmentation_beyond_linear(self, q, qd):
        """F_a less its linear viscous term W·q̇ (what L_prop's minimum-norm term P_a measures)."""
        return self.scale * self.force_net.beyond_linear(q, qd)

    def nonconservative_force(self, q, qd):
        return self.augmentation(q, qd)


class AugmentedDeLaN(AbstractAugmentedSystem):
    """Augmented DeLaN (adln): learned M, V and a learned τ_NC network; known τ_u."""

    kind: ClassVar[str] = "adln"
    label: ClassVar[str] = "ADLN"
    lagrangian_nets: LagrangianNetworks
    force_net: ForceNetwork
    scale: Float[Array, ""]
    spec: SystemSpec = eqx.field(static=True)
    input_gain: float = eqx.field(static=True)
    hparams: tuple[tuple[str, Any], ...] = eqx.field(static=True)

    def __init__(self, system: str, *, key: PRNGKeyArray, **hparams):
        spec = get_spec(system)
        hp = system_defaults(spec.name)
        hp.pop("damping_init")
        hp["force_hidden"] = hp["hidden"]
        hp.update(force_hparams(spec, "adln"))
        hp = with_given("augmented-DeLaN", hp, hparams, LEARNED_EXTRAS)
        kl, kf = jax.random.split(key)
        self.lagrangian_nets = LagrangianNetworks.from_hparams(spec, hp, key=kl)
        self.force_net = ForceNetwork.from_hparams(spec, hp, hidden=hp["force_hidden"], key=kf)
        self.scale = jnp.asarray(1.0)
        self.spec = spec
        self.input_gain = float(hp["input_gain"])
        self.hparams = freeze_hparams(hp)

    def networks(self):
        return (self.lagrangian_nets.mass_net, self.lagrangian_nets.potential_net, self.force_net.net)

    def mass_matrix(self, q):
        return self.scale * self.lagrangian_nets.mass_matrix(q)

    def potential(self, q):
        return self.scale * self.lagrangian_nets.potential(q)

    def input_force(self, q, qd, u):
        return first_joint_input(self.spec, self.input_gain, u)
