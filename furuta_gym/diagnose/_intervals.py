"""Confidence intervals of a diagnosis' fitted parameters and effect coefficients.

MuJoCo's system identification (``mujoco.sysid.calculate_intervals``) reports intervals from the
Jacobian J at the optimum: s²(JᵀJ)⁻¹ with one iid noise variance s², Student-t quantiles, and an
eigen decomposition of JᵀJ in which an eigenvalue that is numerically zero makes the interval of
every parameter with a non-zero component along its eigenvector infinite — a null direction, a
combination of parameters the data do not pin down. We take that eigen handling from it (or from
:func:`own_calculate_intervals`, the same algorithm, when mujoco's optional ``sysid`` extra is
absent) to decide which intervals are unbounded, and nothing else: its variance assumes
independent residuals, and ours are not. The position errors of one open-loop prediction window
share the window's start-state error (an estimated velocity) and grow along it: positively
correlated, so s²(JᵀJ)⁻¹ is far too narrow. Consecutive equation-error residuals share the
momentum estimate at their common interval end with opposite signs, which telescopes over a
block: negatively correlated, so there it is too wide. Either way the covariance is cluster-robust
instead, windows (or blocks) as clusters (:func:`cluster_intervals`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from scipy.special import stdtrit

from ..effects import INPUT_DYNAMICS_EFFECTS
from . import _fit, _windows

__all__ = [
    "Interval",
    "Intervals",
    "cluster_intervals",
    "sysid_calculate_intervals",
    "own_calculate_intervals",
    "LEVEL",
    "NEAR_NULL",
]

LEVEL = 0.95
# A direction is near-null when its eigenvalue of the column-normalised JᵀJ is below this share of
# the largest (singular-value ratio 1e-5): the forward-difference Jacobians of the output-error fit
# carry relative errors of about 1e-6, so smaller singular values are not resolved by J itself.
NEAR_NULL = 1e-10
# mujoco.sysid's default: an eigenvector component below this share of the eigenvector's largest
# does not make a null direction's infinite variance reach that parameter
V_ZERO = 1e-8


def _mujoco_calculate_intervals():
    """``mujoco.sysid.calculate_intervals``, or None: ``mujoco.sysid`` is missing on older MuJoCo
    and empty without its optional dependencies (``mujoco[sysid]``)."""
    try:
        from mujoco.sysid import calculate_intervals  # noqa: PLC0415  the optional [sysid] extra
    except ImportError:
        return None
    return calculate_intervals


def own_calculate_intervals(residuals_star, J, alpha=0.05, lambda_zero_thresh=1e-15, v_zero_thresh=1e-8):
    """The algorithm of ``mujoco.sysid.calculate_intervals`` (MuJoCo 4.0), vectorised: returns
    (s²·(JᵀJ)⁻¹, half-widths), a half-width infinite where a null eigenvalue's eigenvector has a
    non-zero component on that parameter. Kept identical, including which eigenvector's largest
    entry a component is compared with, so that both paths flag the same null directions."""
    if J is None or J.size == 0:
        return np.empty((0, 0)), np.empty((0,))
    r = np.concatenate(residuals_star)
    dof = r.size - J.shape[1]
    s2 = float(r @ r) / dof
    lam, V = np.linalg.eigh(J.T @ J)
    null = lam / np.max(lam) < lambda_zero_thresh
    # component (j, i) is compared with the largest entry of eigenvector j, as in mujoco.sysid
    comp = np.where(np.abs(V / np.max(np.abs(V), axis=0)[:, None]) < v_zero_thresh, 0.0, V)
    unbounded = np.any(null[None, :] & (comp != 0.0), axis=1)
    finite = np.sum(np.where(null[None, :], 0.0, comp**2 / np.where(null, 1.0, lam)[None, :]), axis=1)
    diag_inv = np.where(unbounded, np.inf, finite)
    lam = np.where(lam == 0, lambda_zero_thresh, lam)
    sigma = s2 * (V / lam) @ V.T
    with np.errstate(invalid="ignore"):  # s² = 0 on an unbounded parameter: nan, as mujoco.sysid gives
        half = np.sqrt(diag_inv * s2) * stdtrit(dof, 1 - alpha / 2)
    return sigma, half


def sysid_calculate_intervals(residuals, J, alpha=0.05, lambda_zero_thresh=1e-15, v_zero_thresh=1e-8):
    """(covariance, half-widths, backend name): mujoco.sysid's iid intervals, or our copy."""
    fn = _mujoco_calculate_intervals()
    if fn is None:
        return (*own_calculate_intervals(residuals, J, alpha, lambda_zero_thresh, v_zero_thresh), "own")
    sigma, half = fn(residuals, J, alpha, lambda_zero_thresh, v_zero_thresh)
    return np.asarray(sigma), np.asarray(half, dtype=float), "mujoco.sysid"


@dataclasses.dataclass(frozen=True)
class Intervals:
    """Cluster-robust intervals of the columns of one fit's Jacobian (see :func:`cluster_intervals`)."""

    estimate: np.ndarray
    half_width: np.ndarray  # inf: unbounded (a near-null direction reaches the parameter)
    covariance: np.ndarray  # the sandwich covariance on the identified subspace (original units)
    iid_half_width: np.ndarray  # mujoco.sysid's s²(JᵀJ)⁻¹ intervals, for comparison
    null_directions: np.ndarray  # (k, P) unit eigenvectors of the column-normalised JᵀJ
    level: float
    clusters: int
    dof: int
    backend: str  # whose eigen handling flagged the null directions: "mujoco.sysid" or "own"

    @property
    def unbounded(self) -> np.ndarray:
        return ~np.isfinite(self.half_width)

    @property
    def lower(self) -> np.ndarray:
        return self.estimate - self.half_width

    @property
    def upper(self) -> np.ndarray:
        return self.estimate + self.half_width


def _cluster_scores(Jn: np.ndarray, r: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """(G, P): each cluster's score Σ_{i∈g} J_i r_i (the meat is SᵀS)."""
    _, inv = np.unique(clusters, return_inverse=True)
    scores = np.zeros((int(inv.max()) + 1, Jn.shape[1]))
    np.add.at(scores, inv.ravel(), Jn * r[:, None])
    return scores


def cluster_intervals(J, r, clusters, estimate, level: float = LEVEL, near_null: float = NEAR_NULL) -> Intervals:
    """Intervals of a least-squares estimate from its residuals ``r`` (N,) and Jacobian ``J``
    (N, P) at the estimate, the residuals grouped into independent ``clusters`` (N,) labels.

    Covariance (JᵀJ)⁻¹ (Σ_g J_gᵀ r_g r_gᵀ J_g) (JᵀJ)⁻¹ (the sandwich of Liang and Zeger), with the
    CR1 small-sample factor G/(G−1)·(N−1)/(N−P) and Student-t quantiles with G−1 degrees of
    freedom: with a few dozen windows the meat is estimated from G scores, not N residuals.
    Columns are normalised first, so that "near-null" does not depend on the parameters' units;
    near-null directions (eigenvalue < ``near_null`` × the largest) are left out of the inverse,
    and a parameter they reach gets an infinite half-width (mujoco.sysid's eigen handling).
    """
    J, r = np.asarray(J, float), np.asarray(r, float)
    N, P = J.shape
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)  # a zero column is a null direction of its own
    Jn = J / norms
    _, iid_half, backend = sysid_calculate_intervals([r], Jn, 1.0 - level, near_null, V_ZERO)
    lam, V = np.linalg.eigh(Jn.T @ Jn)
    keep = lam / np.max(lam) >= near_null if np.max(lam) > 0 else np.zeros(P, bool)
    h_inv = (V[:, keep] / lam[keep]) @ V[:, keep].T
    scores = _cluster_scores(Jn, r, np.asarray(clusters).ravel())
    G, p = scores.shape[0], int(keep.sum())
    unbounded = ~np.isfinite(iid_half)
    if G < 2 or N <= p:  # no spread between clusters to estimate
        unbounded = np.ones(P, bool)
    factor = G / max(G - 1, 1) * (N - 1) / max(N - p, 1)
    cov = factor * h_inv @ (scores.T @ scores) @ h_inv / np.outer(norms, norms)
    t = float(stdtrit(max(G - 1, 1), 0.5 + level / 2))
    half = np.where(unbounded, np.inf, t * np.sqrt(np.maximum(np.diag(cov), 0.0)))
    return Intervals(
        np.asarray(estimate, float), half, cov, iid_half / norms, V[:, ~keep].T, level, G, max(G - 1, 1), backend
    )


@dataclasses.dataclass(frozen=True)
class Interval:
    """One reported parameter's interval: [lower, upper] at ``level`` (infinite: unbounded)."""

    lower: float
    upper: float
    source: str  # "output_error" or "equation_error": the fit whose estimate is reported
    iid_half_width: float = float("nan")  # mujoco.sysid's s²(JᵀJ)⁻¹ interval, for comparison only

    @property
    def unbounded(self) -> bool:
        return not (np.isfinite(self.lower) and np.isfinite(self.upper))

    def to_json(self):
        return "unbounded" if self.unbounded else [float(self.lower), float(self.upper)]

    def contains(self, value: float) -> bool:
        return bool(self.lower <= value <= self.upper)


# ----------------------------------------------------------------------------- a diagnosis' fits


@dataclasses.dataclass(frozen=True)
class FitOrigin:
    """Which fit a reported θ came from, and where that fit's Jacobian is taken.

    ``theta`` is the fit's own estimate (the point where its residual is stationary), ``free`` its
    free parameters, ``dynamics`` the input dynamics its data were transformed with. ``held``:
    entries the reported θ does not take from this fit, with why (the nominal values kept, a
    stiction set from what the rests held): they get no interval."""

    kind: str  # "output_error" or "equation_error"
    theta: np.ndarray
    free: np.ndarray
    dynamics: Any  # _fit.InputDynamics
    start_iterations: int = 0
    held: tuple = ()  # ((index, why), ...)
    recorded: bool = True  # False: no fit's recorded estimate; the Jacobian is taken at the reported θ

    def holding(self, indices, why: str) -> "FitOrigin":
        return dataclasses.replace(self, held=self.held + tuple((int(i), why) for i in indices))


def _oe_problem(fx, origin: FitOrigin):
    """(r, J, clusters) of the output-error fit: position errors of its windows at its estimate,
    central differences (steps as the fit's), one cluster per window; the input dynamics' seconds
    as a last column (forward difference: the windows' inputs are transformed again)."""
    win = fx.fit_windows(origin.dynamics, fx.oe_idx)

    def res(theta, w=win):
        return _windows.window_residuals(fx.layout, theta, w, fx.substeps, origin.start_iterations)

    theta = np.asarray(origin.theta, float)
    r = res(theta)
    steps = 1e-6 * np.maximum(np.abs(theta), fx.layout.typical_scale() * 1e-2)
    cols = []
    for i in np.flatnonzero(origin.free):
        e = np.zeros_like(theta)
        e[i] = steps[i]
        cols.append((res(theta + e) - res(theta - e)) / (2.0 * steps[i]))
    dyn = origin.dynamics
    if dyn.kind != "none":
        h = 0.01 * win.dt
        moved = fx.fit_windows(_fit.InputDynamics(dyn.kind, dyn.seconds + h), fx.oe_idx)
        cols.append((res(theta, moved) - r) / h)
    clusters = np.repeat(np.arange(win.x0.shape[0]), r.size // win.x0.shape[0])
    return r, np.stack(cols, axis=1), clusters


def _ee_problem(fx, origin: FitOrigin):
    """(r, J, clusters) of the equation-error fit: its weighted residuals W·R·θ per interval and
    joint (intervals at rest left out, as the fit leaves them out), one cluster per block of the
    evidence (``block_seconds``); the input dynamics' seconds by the linear test's column (−d·u̇).
    The fit minimises ‖WRθ‖²/‖WDθ‖² with an anchor: to first order in that ratio (small when the
    model fits) a least-squares fit with the anchor held, whose Jacobian is W·R on the free columns."""
    if fx.dynamics != origin.dynamics:  # the regressors that fit saw
        fx.build(origin.dynamics)
    prob, w, theta = fx.fit_prob, fx.weights, np.asarray(origin.theta, float)
    keep = prob.keep.reshape(-1) > 0
    r = ((prob.R @ theta) * w[None]).reshape(-1)[keep]
    cols = [(prob.R[:, :, origin.free] * w[None, :, None]).reshape(keep.size, -1)[keep]]
    if origin.dynamics.kind != "none":
        cols.append((prob.delay_column(theta)[:, :, 0] * w[None]).reshape(-1, 1)[keep])
    _, block = np.unique(prob.block_key, axis=0, return_inverse=True)
    clusters = np.repeat(block.ravel(), prob.R.shape[1])[keep]
    return r, np.concatenate(cols, axis=1), clusters


def _null_note(iv: Intervals, names: list[str], source: str) -> list[str]:
    """One note per near-null direction: which parameters it combines (components ≥ 0.1)."""
    out = []
    for v in iv.null_directions:
        involved = [n for n, c in zip(names, v, strict=True) if abs(c) >= 0.1]
        out.append(
            f"interval unbounded for {', '.join(involved)}: a near-null direction of the {source} "
            f"Jacobian (these data do not pin down that combination)"
        )
    return out


def fit_intervals(fx, theta, origin: FitOrigin):
    """({parameter or effect key: Interval or None}, notes, method) of the reported ``theta``
    from the fit ``origin``. Fixed and held parameters get None (held ones with a note); a
    parameter reached by a near-null direction gets an unbounded Interval and a note."""
    names_all = list(fx.layout.base) + [c.key for c in fx.layout.candidates]
    kind = origin.dynamics.kind
    dyn_key = f"{INPUT_DYNAMICS_EFFECTS[kind]}:u" if kind != "none" else None
    if origin.kind == "output_error":
        r, J, clusters = _oe_problem(fx, origin)
    else:
        r, J, clusters = _ee_problem(fx, origin)
    idx = list(np.flatnonzero(origin.free))
    names = [names_all[i] for i in idx] + ([dyn_key] if dyn_key else [])
    estimate = [theta[i] for i in idx] + ([origin.dynamics.seconds] if dyn_key else [])
    notes = []
    if not names:  # nothing was fitted (a given model, nothing added): no interval to give
        iv = None
    elif not np.all(np.isfinite(r)) or not np.all(np.isfinite(J)):
        iv = None
        notes.append(f"no intervals: the {origin.kind.replace('_', '-')} residual is not finite at the estimate")
    else:
        iv = cluster_intervals(J, r, clusters, estimate)
        notes += _null_note(iv, names, origin.kind.replace("_", "-"))
    out = {
        n: None
        if iv is None
        else Interval(float(iv.lower[k]), float(iv.upper[k]), origin.kind, float(iv.iid_half_width[k]))
        for k, n in enumerate(names)
    }
    held = {}
    for i, why in origin.held:
        out[names_all[i]] = None
        held.setdefault(why, []).append(names_all[i])
    notes += [f"no interval for {', '.join(v)}: {why}" for why, v in held.items()]
    if not origin.recorded:
        notes.append(
            "the reported parameters are not a recorded fit's estimate; their intervals are "
            "taken from the output-error Jacobian at the reported values"
        )
    return out, notes, _method(origin, iv)


def _method(origin: FitOrigin, iv: Intervals | None) -> dict:
    """How the intervals were made, for the JSON."""
    return {
        "level": LEVEL,
        "source": origin.kind,
        "covariance": "cluster-robust sandwich (CR1 small-sample factor)",
        "clusters": "open-loop windows" if origin.kind == "output_error" else "equation-error blocks",
        "n_clusters": None if iv is None else iv.clusters,
        "quantile": None if iv is None else f"Student-t, {iv.dof} degrees of freedom",
        "null_directions": None if iv is None else f"eigen handling of {iv.backend}",
    }
