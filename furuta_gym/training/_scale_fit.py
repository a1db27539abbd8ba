"""The overall scale of a learned model fitted on forced trajectories by least squares
(:func:`fit_scale`: on free data the scale of L and τ_NC is unidentifiable); part of :mod:`.train`."""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._x64 import ensure_x64
from ..data import Trajectory
from ..lagrangian import QuadratureRule, integral_terms
from .losses import span_sum


class ScaleFitWarning(UserWarning):
    """The overall-scale fit on the forced trajectory failed; the trained model is kept unscaled."""


@dataclasses.dataclass
class ScaleFit:
    """Result of :func:`fit_scale`: the factor applied and the relative residual before/after."""

    factor: float
    relative_residual_before: float
    relative_residual_after: float

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


# jitted (model as an argument): traced op by op, the few hundred primitives of one model's terms
# would be compiled one by one, at every fit
_integral_terms_jit = eqx.filter_jit(integral_terms)


def fit_scale(model, trajs: Sequence[Trajectory], rule: QuadratureRule = "trapezoid", span: int = 1):
    """Fit the overall scale of a learned model's (L, τ_NC) on forced trajectories.

    The integral residual of the model with its Lagrangian and τ_NC multiplied by s is Z̄ − s·Ā
    (τ_u is known and not scaled), so s = ⟨Z̄, Ā⟩ / ⟨Ā, Ā⟩ by least squares. Returns
    ``(model_with_scale, ScaleFit)``. Needs a nonzero input in ``trajs``.

    ``span``: Z̄ and Ā summed over that many consecutive intervals first, as L_Iτ's
    (:func:`~furuta_gym.training.losses.span_sum`). Ā holds the momentum at the interval ends,
    so an error in estimated velocities is an error in the regressor, which biases s towards
    zero (regression dilution); over a longer interval that error weighs less against Ā.
    """
    ensure_x64()
    As, Zs = [], []
    for tr in trajs:
        if tr.qd is None:
            raise ValueError(f"trajectory {tr.name!r} has no velocities; the scale fit needs q̇")
        terms = _integral_terms_jit(
            model, jnp.asarray(tr.q), jnp.asarray(tr.qd), jnp.asarray(tr.u).reshape(len(tr), -1), tr.dt, rule
        )
        As.append(np.asarray(span_sum(terms.A, span)))
        Zs.append(np.asarray(span_sum(terms.Z, span)))
    A = np.concatenate(As).ravel()
    Z = np.concatenate(Zs).ravel()
    if not np.any(np.concatenate([np.asarray(tr.u).ravel() for tr in trajs]) != 0):
        raise ValueError("the scale fit needs a forced trajectory (nonzero input u); got u ≡ 0")
    denom = _dot(A, A)
    if not np.isfinite(denom) or denom == 0.0:
        raise ValueError("the scale fit failed: the model's integral terms are zero or not finite")
    s = _dot(Z, A) / denom
    if not s > 0:
        raise ValueError(
            f"the scale fit gave a non-positive scale {s:.3g}: the model does not explain the "
            "forced trajectory's input (wrong sign convention of u?)"
        )
    zn = math.sqrt(_dot(Z, Z))
    before = math.sqrt(_dot(Z - A, Z - A)) / zn
    after = math.sqrt(_dot(Z - s * A, Z - s * A)) / zn
    return model.with_scale(model.scale * s), ScaleFit(s, before, after)


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """⟨a, b⟩ rounded once (``math.fsum`` of the products): a BLAS dot sums in an order set by
    the kernels it picks for the CPU, so the scale, and every number after it, would differ
    between machines in the last bits (docs/conventions.md, "Same numbers on every machine")."""
    return math.fsum((a * b).tolist())
