"""Shared pieces of the learned Lagrangian models: MLPs, coordinate features, physical scales.

Every learned model (DeLaN, APHYNITY, augmented DeLaN) is an Equinox module implementing the
Lagrangian-system protocol, with two extras the training code relies on:

* ``scale`` — one scalar multiplying the learned Lagrangian *and* the learned non-conservative
  force (never the known input force). On free (u = 0) data the dynamics do not change when
  L and τ_NC are multiplied by the same constant, so this overall scale is unidentifiable; it is
  excluded from gradient training and fitted afterwards by least squares on one forced
  trajectory (:func:`furuta_gym.training.fit_scale`), as the paper does.
* ``hparams`` — the keyword arguments that rebuild the module's skeleton with
  :func:`furuta_gym.models.make_model` (checkpoints store them in their JSON header).

Units: in SI the Furuta potential is ~100× its mass-matrix entries,
so networks output O(1) numbers multiplied by a physical magnitude per quantity
(``mass_scale`` ≈ J1, ``potential_scale`` ≈ mp·g·Lp, ``force_scale`` ≈ friction torques).
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from .._x64 import ensure_x64
from ..lagrangian import AbstractLagrangianSystem, SystemSpec
from ..systems import get_spec
from ._definitions import SYSTEM_DEFINITIONS

__all__ = ["MLP", "AbstractLearnedSystem", "SYSTEM_DEFAULTS", "coordinate_features", "system_defaults"]

_ACTIVATIONS: dict[str, Callable] = {
    "tanh": jnp.tanh,
    "softplus": jax.nn.softplus,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
}

#: the learned models' default hyper-parameters per system (each system's definition holds its own)
SYSTEM_DEFAULTS: dict[str, dict[str, Any]] = {name: d.learned_defaults for name, d in SYSTEM_DEFINITIONS.items()}


#: optional hyper-parameters of the models with DeLaN's networks, outside the system defaults (a
#: model saved before one existed rebuilds without it): eps, activation, springs (joint names)
LEARNED_EXTRAS = ("activation", "eps", "springs")


def system_defaults(system: str) -> dict[str, Any]:
    """A copy of the default hyper-parameters of ``system`` ("furuta" or "nmsd")."""
    return dict(SYSTEM_DEFAULTS[get_spec(system).name])


def with_given(model: str, defaults: dict[str, Any], given: dict[str, Any], extras=()) -> dict[str, Any]:
    """``defaults`` updated by the ``given`` hyper-parameters of a ``model`` (its name, for the
    error), which may also name the optional ``extras``; one error lists what it does not know."""
    unknown = set(given) - set(defaults) - set(extras)
    if unknown:
        known = sorted(defaults) + sorted(extras)
        raise ValueError(f"unknown {model} hyper-parameters {sorted(unknown)}; known: {known}")
    return {**defaults, **given}


class MLP(eqx.Module):
    """A plain multilayer perceptron with a smooth activation (second derivatives are needed:
    the Coriolis force differentiates M, and training differentiates the dynamics again)."""

    layers: tuple[eqx.nn.Linear, ...]
    activation: str = eqx.field(static=True)

    def __init__(
        self,
        in_size: int,
        out_size: int,
        hidden: tuple[int, ...],
        *,
        key: PRNGKeyArray,
        activation: str = "tanh",
        final_scale: float = 1.0,
    ):
        if activation not in _ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(_ACTIVATIONS)}, got {activation!r}")
        sizes = (in_size, *hidden, out_size)
        keys = jax.random.split(key, len(sizes) - 1)
        layers = [eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys, strict=True)]
        # A small last layer starts the model near its physical reference (outputs ≈ bias ≈ 0).
        last = layers[-1]
        layers[-1] = eqx.tree_at(lambda l: (l.weight, l.bias), last, (last.weight * final_scale, last.bias * 0.0))
        self.layers = tuple(layers)
        self.activation = activation

    def __call__(self, x: Float[Array, " i"]) -> Float[Array, " o"]:
        act = _ACTIVATIONS[self.activation]
        for layer in self.layers[:-1]:
            x = act(layer(x))
        return self.layers[-1](x)


def coordinate_features(spec: SystemSpec, q: Float[Array, " n"], position_scale: float) -> Float[Array, " f"]:
    """Network input for q: (cos, sin) of every angle, linear coordinates divided by a scale."""
    angular = np.asarray(spec.angular)
    if angular.all():
        # (cos q0, sin q0, cos q1, ...) without per-coordinate slices: vmapped, it stays
        # copy-major, so no transposes around the first layer's matrix product
        cos, sin = cos_sin(q)
        return jnp.stack([cos, sin], axis=-1).reshape(-1)
    angles = [i for i, a in enumerate(spec.angular) if a]
    if angles:
        cos, sin = cos_sin(jnp.stack([q[i] for i in angles]))
    parts = []
    for i, a in enumerate(spec.angular):
        if a:
            k = angles.index(i)
            parts += [cos[k], sin[k]]
        else:
            parts.append(q[i] / position_scale)
    return jnp.stack(parts, axis=-1)


@jax.custom_jvp
def cos_sin(a: Float[Array, " k"]) -> tuple[Float[Array, " k"], Float[Array, " k"]]:
    """(cos a, sin a), with derivatives that reuse these values instead of recomputing them.

    Why: JAX's jvp rules of cos and sin call sin and cos again, and XLA:CPU then evaluates the
    transcendentals afresh inside every kernel consuming a tangent. The jvp below takes
    (−sin, cos) from the primal values through a constant rotation (a matrix product reads its
    operand from memory rather than recomputing it). With the copy-major feature layout, the
    batched DeLaN RK4 step went from 9 sin/cos per angle and stage to 3 (docs/batched.md, "Speed").
    Identical numbers: the rotation's entries are 0 and ±1.
    """
    return jnp.cos(a), jnp.sin(a)


@cos_sin.defjvp
def _cos_sin_jvp(primals, tangents):
    (a,), (t,) = primals, tangents
    cos, sin = cos_sin(a)
    rotation = jnp.asarray([[0.0, -1.0], [1.0, 0.0]], dtype=cos.dtype)
    rotated = rotation @ jnp.stack([cos, sin])
    return (cos, sin), (rotated[0] * t, rotated[1] * t)


def feature_size(spec: SystemSpec) -> int:
    return sum(2 if a else 1 for a in spec.angular)


def _hashable(value):
    if isinstance(value, (list, tuple)):
        return tuple(_hashable(v) for v in value)
    if isinstance(value, np.ndarray):
        return tuple(value.tolist())
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


def freeze_hparams(hparams: dict[str, Any]) -> tuple[tuple[str, Any], ...]:
    """Hyper-parameters as a hashable, sorted tuple (Equinox static fields must hash)."""
    return tuple(sorted((k, _hashable(v)) for k, v in hparams.items()))


class AbstractLearnedSystem(AbstractLagrangianSystem):
    """Base of the learned models: an overall ``scale`` and the hyper-parameters that rebuild it.

    Each subclass is one model kind (:data:`furuta_gym.models.MODEL_KINDS`) and carries what
    differs between kinds, so code elsewhere asks the kind, never compares its name."""

    #: the public spelling ("dln", "aph", "adln"): ``make_model``, ``--model``, checkpoints
    kind: ClassVar[str]
    #: its label in the reproduction's tables and figures
    label: ClassVar[str]
    #: M and V are an analytic prior's (physical parameters learned, no networks): the paper
    #: scores no energy or force decomposition for it (N/A) and no learned spring fits its potential
    analytic_prior: ClassVar[bool] = False
    spec: eqx.AbstractVar[SystemSpec]
    scale: eqx.AbstractVar[Float[Array, ""]]
    hparams: eqx.AbstractVar[tuple[tuple[str, Any], ...]]

    @property
    def hyperparameters(self) -> dict[str, Any]:
        """The keyword arguments of :func:`make_model` that rebuild this module's skeleton."""
        return dict(self.hparams)

    def with_scale(self, scale) -> "AbstractLearnedSystem":
        """The same model with its learned Lagrangian and τ_NC multiplied by ``scale / self.scale``."""
        return eqx.tree_at(lambda m: m.scale, self, jnp.asarray(scale, dtype=float))

    def trainable(self) -> Any:
        """A filter spec (pytree of bools) of the leaves gradient training may change.

        Everything inexact except ``scale`` (fitted separately; see the module docstring).
        """
        spec = jax.tree_util.tree_map(eqx.is_inexact_array, self)
        return eqx.tree_at(lambda m: m.scale, spec, False)

    def decayed(self) -> Any:
        """A pytree of bools: which trainable leaves get weight decay (network weights only;
        physical parameters and log-coefficients are not pulled towards zero)."""
        spec = jax.tree_util.tree_map(lambda _: False, self)
        return eqx.tree_at(
            lambda m: [l.weight for net in m.networks() for l in net.layers],
            spec,
            replace_fn=lambda _: True,
        )

    @abc.abstractmethod
    def networks(self) -> tuple[MLP, ...]:
        """The MLPs of this model (for weight decay and parameter counts)."""

    def augmentation(self, q: Float[Array, " n"], qd: Float[Array, " n"]) -> Float[Array, " n"]:
        """The data-driven force F_a (APHYNITY's additive term); models without one raise."""
        raise NotImplementedError(f"{type(self).__name__} has no data-driven force F_a")

    @property
    def has_augmentation(self) -> bool:
        return False

    @classmethod
    def form_1_hparams(cls, hparams: dict[str, Any]) -> dict[str, Any]:
        """A form-1 checkpoint header's hyper-parameters (written before some options existed)
        completed with what a model of this kind was then built with (models/checkpoint.py)."""
        return dict(hparams)


def _positive(x) -> jnp.ndarray:
    ensure_x64()
    return jnp.asarray(x, dtype=float)
