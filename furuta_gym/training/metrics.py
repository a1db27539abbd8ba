"""The paper's evaluation metrics (Laiche et al. 2026, §6): log10 RMSE, lower is better.

For one model and one test set (a list of trajectories with velocities):

* **Prediction** (one number per state, e.g. α, β, α̇, β̇): the model is simulated open loop from
  each test trajectory's x0 under its recorded input (linearly interpolated, diffrax Tsit5 at the
  evaluation tolerances below) and compared with the recorded states; squared errors are pooled
  over all trajectories and samples of the set. If any trajectory's prediction diverges
  (non-finite, larger than ``divergence_bound``, or the solver gives up) the set's prediction
  cells are :data:`DIVERGED` ("X"), as in the paper's tables.
* **Force decomposition** (inertial M(q)q̈, Coriolis (∂²L/∂q∂q̇)q̇, potential-derived ∂L/∂q; one
  number each, pooled over joints and samples, in N·m or N): the learned and the true terms
  evaluated along the *recorded* states, with the ground-truth acceleration q̈ from the true
  model's forward dynamics at (q, q̇, u) (the same q̈ enters both inertial terms, so the inertial
  error measures M only).
* **Energy** (one number): E(t)/E(0) of the learned model against that of the true model along the
  recorded states, pooled over samples. The learned Lagrangian carries an arbitrary additive
  constant in V and an overall scale; we align them by (i) shifting V so that V(q_rest) = 0 at
  the rest configuration (q = 0: hanging pendulum / unstretched spring, where the true V is 0)
  and (ii) normalising by E(0) per trajectory, which cancels any remaining overall scale. (The
  scale itself is fitted after training on one forced trajectory — see
  :func:`furuta_gym.training.fit_scale` — and matters for the force-decomposition metric.)

Everything is float64; a test set is evaluated with one compiled, vmapped solve per
(model structure, set shape).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..data import DataError, Trajectory
from ..lagrangian import AbstractLagrangianSystem, energy, forward_dynamics, inverse_dynamics_terms
from ..models import analytic_model
from ..simulate import DIVERGED, simulate

__all__ = [
    "DIVERGED",
    "FORCE_TERMS",
    "EvaluationSettings",
    "log10_rmse",
    "predict",
    "prediction_errors",
    "force_decomposition_errors",
    "energy_along",
    "energy_error",
    "evaluate_model",
    "format_value",
    "metrics_to_json",
]

FORCE_TERMS = ("inertial", "coriolis", "potential")


@dataclasses.dataclass(frozen=True)
class EvaluationSettings:
    """Solver settings of the open-loop predictions and the divergence bound.

    Far tighter than training's 1e-3 / 1e-6 so the metric measures the model, not the solver:
    the true model then scores ≈ −5.5 on the chaotic 20 s forced Furuta set (≈ −4 at 1e-7).
    """

    rtol: float = 1e-9
    atol: float = 1e-11
    max_steps: int = 500_000
    divergence_bound: float = 1e6


def log10_rmse(errors) -> float:
    """log10 of the root-mean-square of ``errors`` (any shape); −inf for exactly zero errors."""
    errors = np.asarray(errors, dtype=float)
    rms = math.sqrt(float(np.mean(errors**2)))
    return -math.inf if rms == 0.0 else math.log10(rms)


def _stack_set(trajs: Sequence[Trajectory], n_dof: int):
    if not trajs:
        raise ValueError("the test set is empty")
    for tr in trajs:
        if tr.qd is None:
            raise DataError(
                f"trajectory {tr.name!r} has no velocities; evaluation needs q̇ (generate data "
                "with velocities or estimate them with furuta_gym.signals.zero_phase_velocity)"
            )
        if np.asarray(tr.q).shape[1] != n_dof:
            raise DataError(f"trajectory {tr.name!r} has {np.asarray(tr.q).shape[1]} joint(s); the model has {n_dof}")
    return trajs


_PREDICT_CACHE: dict = {}


def predict(
    model: AbstractLagrangianSystem,
    trajs: Sequence[Trajectory],
    settings: EvaluationSettings = EvaluationSettings(),
) -> list[np.ndarray]:
    """Open-loop predictions (T, 2n) of ``model`` from each trajectory's x0 under its input.

    Non-finite where the solve failed. Trajectories of equal length and time grid are solved
    together in one vmapped call.
    """
    trajs = _stack_set(trajs, model.spec.n_dof)
    out: list[np.ndarray | None] = [None] * len(trajs)
    groups: dict[tuple, list[int]] = {}
    for i, tr in enumerate(trajs):
        groups.setdefault((len(tr), float(tr.t[0]), round(tr.dt, 12)), []).append(i)
    params, static = eqx.partition(model, eqx.is_array)
    for key, idx in groups.items():
        cache_key = (static, jax.tree_util.tree_structure(params), key, len(idx), settings)
        fn = _PREDICT_CACHE.get(cache_key)
        if fn is None:
            ts = jnp.asarray(trajs[idx[0]].t)

            def one(p, x0, us, ts=ts):
                m = eqx.combine(p, static)
                return simulate(
                    m,
                    x0,
                    ts,
                    us,
                    rtol=settings.rtol,
                    atol=settings.atol,
                    max_steps=settings.max_steps,
                    throw=False,
                )

            fn = jax.jit(jax.vmap(one, in_axes=(None, 0, 0)))
            _PREDICT_CACHE[cache_key] = fn
        x0 = jnp.asarray(np.stack([trajs[i].x[0] for i in idx]))
        us = jnp.asarray(np.stack([np.asarray(trajs[i].u, dtype=float).reshape(len(trajs[i]), -1) for i in idx]))
        xs = np.asarray(fn(params, x0, us))
        for j, i in enumerate(idx):
            out[i] = xs[j]
    return out  # type: ignore[return-value]


def prediction_errors(
    model: AbstractLagrangianSystem,
    trajs: Sequence[Trajectory],
    settings: EvaluationSettings = EvaluationSettings(),
    predictions: Sequence[np.ndarray] | None = None,
) -> dict[str, float | str]:
    """log10 RMSE per state name (``spec.state_names``), or :data:`DIVERGED` for every state if
    any trajectory's prediction diverged."""
    preds = predictions if predictions is not None else predict(model, trajs, settings)
    names = model.spec.state_names
    diverged = any((not np.all(np.isfinite(p))) or np.max(np.abs(p)) > settings.divergence_bound for p in preds)
    if diverged:
        return {name: DIVERGED for name in names}
    err = np.concatenate([p - tr.x for p, tr in zip(preds, trajs, strict=True)], axis=0)
    return {name: log10_rmse(err[:, k]) for k, name in enumerate(names)}


# These run once per model and test set. Traced op by op (an eager vmap), each of their few
# hundred primitives compiled on its own: a large share of a quick-reproduction model. Jitted with
# the model as an argument, they compile once per model structure and shape, and every model of
# that structure (through the persistent cache, in every worker process too) reuses it.


@eqx.filter_jit
def _terms_along(system, q, qd, qdd):
    return jax.vmap(lambda a, b, c: inverse_dynamics_terms(system, a, b, c))(q, qd, qdd)


@eqx.filter_jit
def _true_accelerations(truth, q, qd, u):
    return jax.vmap(lambda a, b, c: forward_dynamics(truth, a, b, c))(q, qd, u)


@eqx.filter_jit
def _shifted_energies(system, q, qd, q_rest):
    return jax.vmap(lambda a, b: energy(system, a, b))(q, qd) - system.potential(q_rest)


def force_decomposition_errors(
    model: AbstractLagrangianSystem,
    trajs: Sequence[Trajectory],
    truth: AbstractLagrangianSystem,
) -> dict[str, float]:
    """log10 RMSE of the inertial, Coriolis and potential-derived terms against ``truth`` along
    the recorded states, with q̈ from ``truth``'s forward dynamics (pooled over joints)."""
    trajs = _stack_set(trajs, model.spec.n_dof)
    q = jnp.asarray(np.concatenate([tr.q for tr in trajs]))
    qd = jnp.asarray(np.concatenate([np.asarray(tr.qd) for tr in trajs]))
    u = jnp.asarray(np.concatenate([np.asarray(tr.u, dtype=float).reshape(len(tr), -1) for tr in trajs]))
    qdd = _true_accelerations(truth, q, qd, u)
    learned = _terms_along(model, q, qd, qdd)
    true = _terms_along(truth, q, qd, qdd)
    return {
        name: log10_rmse(np.asarray(getattr(learned, name)) - np.asarray(getattr(true, name))) for name in FORCE_TERMS
    }


def energy_along(system: AbstractLagrangianSystem, q, qd, q_rest=None, normalize: bool = True) -> np.ndarray:
    """E(t) of ``system`` along (q, q̇) with V shifted so V(q_rest) = 0 (q_rest defaults to 0),
    divided by E(t = 0) when ``normalize``."""
    q = jnp.asarray(q, dtype=float)
    qd = jnp.asarray(qd, dtype=float)
    q_rest = jnp.zeros(q.shape[1]) if q_rest is None else jnp.asarray(q_rest, dtype=float)
    e = np.asarray(_shifted_energies(system, q, qd, q_rest))
    if normalize:
        if not np.isfinite(e[0]) or abs(e[0]) < 1e-300:
            raise ValueError("energy normalisation: E(t = 0) is zero or not finite")
        e = e / e[0]
    return e


def energy_error(
    model: AbstractLagrangianSystem,
    trajs: Sequence[Trajectory],
    truth: AbstractLagrangianSystem,
    q_rest=None,
) -> float:
    """log10 RMSE of E/E(0) (learned vs true) along the recorded states; see the module doc."""
    trajs = _stack_set(trajs, model.spec.n_dof)
    errs = []
    for tr in trajs:
        e_true = energy_along(truth, tr.q, tr.qd, q_rest)
        e_model = energy_along(model, tr.q, tr.qd, q_rest)
        errs.append(e_model - e_true)
    return log10_rmse(np.concatenate(errs))


def evaluate_model(
    model: AbstractLagrangianSystem,
    trajs: Sequence[Trajectory],
    truth: AbstractLagrangianSystem | None = None,
    *,
    settings: EvaluationSettings = EvaluationSettings(),
    physics: bool = True,
    return_predictions: bool = False,
) -> dict[str, Any]:
    """All metrics of one test set: ``{state name: value, "inertial", "coriolis", "potential",
    "energy"}`` (log10 RMSE floats, or "X" for diverged predictions), plus ``"n_trajectories"``.

    ``truth`` defaults to the analytic model of the model's system; ``physics=False`` skips the
    force and energy metrics (e.g. for a model whose prior fixes them). With
    ``return_predictions`` the open-loop predictions are returned under ``"predictions"``.
    """
    if truth is None:
        truth = analytic_model(model.spec.name)
    if truth.spec.name != model.spec.name:
        raise ValueError(f"truth is a {truth.spec.name} model but the model is a {model.spec.name} model")
    preds = predict(model, trajs, settings)
    result: dict[str, Any] = dict(prediction_errors(model, trajs, settings, preds))
    if physics:
        result.update(force_decomposition_errors(model, trajs, truth))
        result["energy"] = energy_error(model, trajs, truth)
    result["n_trajectories"] = len(trajs)
    if return_predictions:
        result["predictions"] = preds
    return result


def format_value(value) -> str:
    """A metric as the tables print it: 4 decimals, "X" for diverged, "N/A" for None."""
    if value is None:
        return "N/A"
    if isinstance(value, str):
        return value
    return f"{value:.4f}"


def metrics_to_json(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """Drop arrays and make ±inf JSON-safe strings."""
    out = {}
    for k, v in metrics.items():
        if k == "predictions":
            continue
        if isinstance(v, float) and not math.isfinite(v):
            out[k] = str(v)
        else:
            out[k] = v
    return out
