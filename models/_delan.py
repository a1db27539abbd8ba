"""Deep Lagrangian Networks (Lutter et al. 2019) as in Laiche et al. 2026, §3 and appendix A.1.

M(q) = mass_scale · L(q) L(q)ᵀ with L lower-triangular from a network (diagonal through
softplus + ε, so M is symmetric positive definite by construction); V(q) = potential_scale ·
(net(q) − net(0)), so V(0) = 0 like the analytic models; angles enter the networks as (cos, sin).
τ_NC has the known structure with learnable positive coefficients (log-parameterised):

* Furuta: (−d_r α̇, −c_p β̇);
* N-MSD: −b1 ṗ − b2 ṗ³.

τ_u is known: N-MSD u; Furuta (kt/Rm)·u.

**Where the rotor's damping lives (Furuta).** The motor's back-EMF torque −(kt·km/Rm)·α̇ and the
rotor friction −c_r·α̇ are the same regressor: on free (u = 0) data nothing separates them. The
learned models therefore hold one *lumped* rotor damping d_r = c_r + kt·km/Rm in τ_NC and keep only
the voltage term (kt/Rm)·u in τ_u. The forward dynamics are identical to the analytic model's; on
free data the learned (L, τ_NC) pair then has an exact scale symmetry, which the scale fit on one
forced trajectory resolves. The physical friction is ``rotor_friction = d_r − kt·km/Rm``.
"""

from __future__ import annotations

from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..effects import EFFECT_KINDS, Effect, effects_potential
from ..lagrangian import SystemSpec
from ..systems import get_spec
from ._definitions import system_definition
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

__all__ = ["LagrangianNetworks", "DeLaN", "known_damping_force"]


class LagrangianNetworks(eqx.Module):
    """The conservative part shared by DeLaN and augmented DeLaN: Cholesky-factor and potential nets.

    ``springs`` (joint names, default none) adds a learned spring ½k(q_j − q_ref)² per joint to V,
    the registry's ``spring`` law with k = k_typical·e^z > 0 and q_ref learned. On an angle the
    potential network sees (cos, sin) and is periodic, so it cannot hold a cable that winds up
    over several turns of the rotor; the diagnosis says which joints have one.
    """

    mass_net: MLP
    potential_net: MLP
    spec: SystemSpec = eqx.field(static=True)
    mass_scale: float = eqx.field(static=True)
    potential_scale: float = eqx.field(static=True)
    position_scale: float = eqx.field(static=True)
    eps: float = eqx.field(static=True)
    # after the fields above, and None without springs: saved checkpoints' leaves keep their order
    spring_log_stiffness: Float[Array, " s"] | None = None
    spring_reference: Float[Array, " s"] | None = None
    springs: tuple[str, ...] = eqx.field(static=True, default=())

    def __init__(
        self,
        spec: SystemSpec,
        *,
        key: PRNGKeyArray,
        hidden: tuple[int, ...],
        mass_scale: float,
        potential_scale: float,
        position_scale: float,
        eps: float = 1e-3,
        activation: str = "tanh",
        springs: tuple[str, ...] = (),
    ):
        n = spec.n_dof
        km, kv = jax.random.split(key)
        f = feature_size(spec)
        self.mass_net = MLP(f, n * (n + 1) // 2, tuple(hidden), key=km, activation=activation, final_scale=0.1)
        self.potential_net = MLP(f, 1, tuple(hidden), key=kv, activation=activation)
        self.spec = spec
        self.mass_scale = float(mass_scale)
        self.potential_scale = float(potential_scale)
        self.position_scale = float(position_scale)
        self.eps = float(eps)
        self.springs = tuple(springs)
        for joint in self.springs:
            if joint not in spec.joint_names:
                raise ValueError(f"springs: {joint!r} is not a joint of {spec.name} (joints: {list(spec.joint_names)})")
        if len(set(self.springs)) != len(self.springs):
            raise ValueError(f"springs: each joint at most once, got {list(self.springs)}")
        if self.springs:
            self.spring_log_stiffness = jnp.zeros(len(self.springs))
            self.spring_reference = jnp.zeros(len(self.springs))

    @classmethod
    def from_hparams(cls, spec: SystemSpec, hp: dict, *, key: PRNGKeyArray) -> "LagrangianNetworks":
        """The networks a model's hyper-parameters ``hp`` describe (the optional ones defaulted)."""
        return cls(
            spec,
            key=key,
            hidden=tuple(hp["hidden"]),
            mass_scale=hp["mass_scale"],
            potential_scale=hp["potential_scale"],
            position_scale=hp["position_scale"],
            eps=hp.get("eps", 1e-3),
            activation=hp.get("activation", "tanh"),
            springs=tuple(hp.get("springs", ())),
        )

    def cholesky_factor(self, q: Float[Array, " n"]) -> Float[Array, "n n"]:
        """Lower-triangular L(q) with diagonal softplus(·) + ε (> 0)."""
        n = self.spec.n_dof
        out = self.mass_net(coordinate_features(self.spec, q, self.position_scale))
        # softplus(x + 0.5413) = 1 at x = 0: the untrained M starts near mass_scale · I.
        diag = jax.nn.softplus(out[:n] + 0.5413248546129181) + self.eps
        # Assembled from its entries at static positions rather than scattered into zeros with
        # .at[tril_indices].set: the scatter cost XLA:CPU ~15 extra kernels of index arithmetic
        # per evaluation (a fixed cost each, which dominates a single-copy env step).
        below = {(int(r), int(c)): out[n + k] for k, (r, c) in enumerate(zip(*np.tril_indices(n, -1), strict=True))}
        zero = jnp.zeros_like(diag[0])
        return jnp.stack(
            [jnp.stack([diag[i] if i == j else below.get((i, j), zero) for j in range(n)]) for i in range(n)]
        )

    def mass_matrix(self, q):
        L = self.cholesky_factor(q)
        # L Lᵀ as a broadcast product and sum (the same sums): at n ≤ 2 a dot is a kernel of its
        # own on XLA:CPU, the product fuses with the assembly of L
        return self.mass_scale * jnp.sum(L[:, None, :] * L[None, :, :], axis=-1)

    def potential(self, q):
        return effects_potential(self.network_potential, self.spring_effects(), q, self.spec)

    def network_potential(self, q):
        zero = jnp.zeros_like(q)
        feats = coordinate_features(self.spec, q, self.position_scale)
        feats0 = coordinate_features(self.spec, zero, self.position_scale)
        return self.potential_scale * (self.potential_net(feats)[0] - self.potential_net(feats0)[0])

    def spring_effects(self) -> tuple[Effect, ...]:
        """The learned springs as effects of the registry (coefficients are arrays)."""
        if not self.springs:
            return ()
        assert self.spring_log_stiffness is not None and self.spring_reference is not None
        typical = EFFECT_KINDS["spring"].typical
        assert typical is not None
        unit = np.array([typical[0 if self.spec.angular[self.spec.joint_names.index(j)] else 1] for j in self.springs])
        stiffness = unit * jnp.exp(self.spring_log_stiffness)
        return tuple(
            Effect("spring", joint, stiffness[i], reference=self.spring_reference[i])  # type: ignore[arg-type]
            for i, joint in enumerate(self.springs)
        )


def known_damping_force(spec: SystemSpec, coefficients, qd):
    """The paper's non-conservative structure with given coefficients (Furuta / N-MSD)."""
    return system_definition(spec).known_damping_force(coefficients, qd)


class DeLaN(AbstractLearnedSystem):
    """DeLaN (dln): learned M and V, known τ_NC structure with learned coefficients, known τ_u.

    Build it with :func:`furuta_gym.models.make_model` (``make_model("nmsd", "dln", key)``).
    """

    kind: ClassVar[str] = "dln"
    label: ClassVar[str] = "DLN"
    lagrangian_nets: LagrangianNetworks
    log_damping: Float[Array, " k"]
    scale: Float[Array, ""]
    spec: SystemSpec = eqx.field(static=True)
    damping_ref: tuple[float, ...] = eqx.field(static=True)
    input_gain: float = eqx.field(static=True)
    hparams: tuple[tuple[str, Any], ...] = eqx.field(static=True)

    def __init__(self, system: str, *, key: PRNGKeyArray, **hparams):

        spec = get_spec(system)
        hp = system_defaults(spec.name)
        hp = with_given("DeLaN", hp, hparams, LEARNED_EXTRAS)
        self.lagrangian_nets = LagrangianNetworks.from_hparams(spec, hp, key=key)
        self.damping_ref = tuple(float(c) for c in hp["damping_init"])
        if len(self.damping_ref) != 2 or min(self.damping_ref) <= 0:
            raise ValueError(f"damping_init must be two positive numbers, got {hp['damping_init']!r}")
        self.log_damping = jnp.zeros(2)
        self.scale = jnp.asarray(1.0)
        self.spec = spec
        self.input_gain = float(hp["input_gain"])
        self.hparams = freeze_hparams(hp)

    def networks(self):
        return (self.lagrangian_nets.mass_net, self.lagrangian_nets.potential_net)

    @property
    def damping(self) -> Float[Array, " 2"]:
        """Positive damping coefficients (Furuta: lumped d_r, c_p; N-MSD: b1, b2), scale included."""
        return self.scale * jnp.asarray(self.damping_ref) * jnp.exp(self.log_damping)

    @property
    def rotor_friction(self):
        """Furuta only: c_r = d_r − kt·km/Rm (the lumped damping minus the pinned back-EMF)."""
        back_emf = system_definition(self.spec).back_emf_damping
        if back_emf is None:
            raise AttributeError("rotor_friction is defined for the Furuta model only")
        return self.damping[0] - back_emf

    def mass_matrix(self, q):
        return self.scale * self.lagrangian_nets.mass_matrix(q)

    def potential(self, q):
        return self.scale * self.lagrangian_nets.potential(q)

    def nonconservative_force(self, q, qd):
        return known_damping_force(self.spec, self.damping, qd)

    def input_force(self, q, qd, u):
        return first_joint_input(self.spec, self.input_gain, u)
