"""Equation-error fit of :class:`~._library.LumpedModel` on measured segments (the output-error
fit on open-loop windows, which starts from it, is :mod:`._windows`).

* Equation error: the integral inverse residual Z̄ − Ā (paper eq. 8-10) over intervals of
  ``stride`` samples is ``R θ`` with ``R`` the per-interval Jacobian (exact: the residual is linear
  in θ). Fixed parameters (the scale anchor) go to the right-hand side; the rest is weighted least
  squares, one weight per joint.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from scipy.linalg import eigh
from scipy.signal import lfilter

from ..effects import dead_band
from ..lagrangian import (
    interval_difference,
    interval_integral,
    inverse_dynamics,
    momentum,
    potential_derived_force,
)
from ..systems import get_spec
from ._library import ParameterLayout

__all__ = [
    "Segment",
    "InputDynamics",
    "DeadBandInput",
    "build_regressors",
    "ee_fit",
    "delay_input",
    "lag_input",
]

_CHUNK = 2048


@dataclasses.dataclass
class Segment:
    """A contiguous piece of one trajectory with velocities and its equation-error regressors."""

    name: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    u: np.ndarray  # (T, m) as measured (the fit may shift it by a delay)
    dt: float
    group: int  # cross-validation group (one per segment)
    held_out: bool
    # filled by build_regressors
    A: np.ndarray | None = None  # (N, n, P) Jacobian of Ā w.r.t. θ per interval
    D: np.ndarray | None = None  # (N, n, P) Jacobian of the momentum change Δ(∂L/∂q̇) per interval
    Uint: np.ndarray | None = None  # (N,) ∫u over each interval
    dU: np.ndarray | None = None  # (N,) d/d(delay) of ∫u(t − d) at d = 0
    block: np.ndarray | None = None  # (N,) block index for paired held-out comparisons
    rest: np.ndarray | None = None  # (N, n) True where a joint's measured position never changes
    #: _held_stops' answers by their arguments: they hang on the measured log alone, so the
    #: regressors rebuilt for each trial input delay or lag ask the same question again
    held_stops: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    def residual_jacobian(self, c_input: np.ndarray, u_int: np.ndarray | None = None) -> np.ndarray:
        """(N, n, P): Z̄ − Ā = R θ, with Z̄ = ∫u · c_input (c_input = ∂τ_u/∂θ at u = 1)."""
        u_int = self.Uint if u_int is None else u_int
        return u_int[:, None, None] * c_input[None] - self.A


_COMPILED: dict = {}


def _compiled(kind: str, layout: ParameterLayout, *args, build):
    """One compiled function per (kind, layout's model family, args); the value keeps the layout
    alive, so the id of a learned model in its key is never reused."""
    key = (kind, layout.cache_key, *args)
    if key not in _COMPILED:
        _COMPILED[key] = (build(), layout)
    return _COMPILED[key][0]


def _sample_jacobians(layout: ParameterLayout):
    def per_sample(theta, q, qd):
        def p_of(th):
            return momentum(layout.model(th), q, qd)

        def f_of(th):
            m = layout.model(th)
            return potential_derived_force(m, q, qd) + m.nonconservative_force(q, qd)

        return jax.jacfwd(p_of)(theta), jax.jacfwd(f_of)(theta)

    return _compiled("jacobians", layout, build=lambda: jax.jit(jax.vmap(per_sample, in_axes=(None, 0, 0))))


def input_direction(layout: ParameterLayout, theta0: np.ndarray) -> np.ndarray:
    """∂τ_u/∂θ at u = 1 (n, P), linearised at ``theta0`` (the input gain effect is bilinear)."""
    spec = get_spec(layout.system)
    n, m = spec.n_dof, len(spec.input_names)

    def c(theta):
        return jax.jacfwd(lambda th: layout.model(th).input_force(jnp.zeros(n), jnp.zeros(n), jnp.ones(m)))(theta)

    return np.asarray(_compiled("input", layout, build=lambda: jax.jit(c))(jnp.asarray(theta0)))


def _per_sample(layout: ParameterLayout, theta0: np.ndarray, q: np.ndarray, qd: np.ndarray):
    fn = _sample_jacobians(layout)
    T = q.shape[0]
    outs_p, outs_f = [], []
    for s in range(0, T, _CHUNK):
        qq, vv = q[s : s + _CHUNK], qd[s : s + _CHUNK]
        k = qq.shape[0]
        if k < _CHUNK:  # pad to one compiled shape
            qq = np.concatenate([qq, np.repeat(qq[-1:], _CHUNK - k, 0)])
            vv = np.concatenate([vv, np.repeat(vv[-1:], _CHUNK - k, 0)])
        jp, jf = fn(jnp.asarray(theta0), jnp.asarray(qq), jnp.asarray(vv))
        outs_p.append(np.asarray(jp)[:k])
        outs_f.append(np.asarray(jf)[:k])
    return np.concatenate(outs_p), np.concatenate(outs_f)


def input_integral(u: np.ndarray, dt: float, hold: str) -> np.ndarray:
    """∫u over each sample interval: held input (``"zoh"``) or linear interpolation (trapezoid)."""
    u = u[:, 0]
    if hold == "zoh":
        return dt * u[:-1]
    return np.asarray(interval_integral(u, dt, "trapezoid"))


def delay_input(u: np.ndarray, delay: float, dt: float) -> np.ndarray:
    """The held input as the plant sees it ``delay`` seconds later (period-averaged; exact ∫)."""
    if delay <= 0:
        return u
    m = int(np.floor(delay / dt))
    phi = delay / dt - m
    pad = np.concatenate([np.repeat(u[:1], m + 1, 0), u], axis=0)
    shifted = pad[1 : 1 + u.shape[0]]  # u[k − m]
    shifted_more = pad[: u.shape[0]]  # u[k − m − 1]
    return (1.0 - phi) * shifted + phi * shifted_more


def lag_input(u: np.ndarray, tau: float, dt: float) -> np.ndarray:
    """The held input after a first-order lag τ·u̇_m = u − u_m, averaged over each sample period
    (exact for an input held over the period; u_m starts at the first sample's value)."""
    if tau <= 0:
        return u
    a = np.exp(-dt / tau)
    um = np.empty_like(u, dtype=float)
    um[0] = u[0]
    if u.shape[0] > 1:  # u_m,k+1 = a·u_m,k + (1 − a)·u_k
        um[1:] = lfilter([1.0 - a], [1.0, -a], u[:-1], axis=0, zi=a * u[:1])[0]
    return u + (um - u) * (tau / dt) * (1.0 - a)


@dataclasses.dataclass(frozen=True)
class InputDynamics:
    """What stands between the logged input and the plant: nothing, a delay or a first-order lag."""

    kind: str = "none"  # "none", "delay" (input_delay) or "lag" (actuator_lag)
    seconds: float = 0.0

    def apply(self, u: np.ndarray, dt: float) -> np.ndarray:
        if self.kind == "delay":
            return delay_input(u, self.seconds, dt)
        if self.kind == "lag":
            return lag_input(u, self.seconds, dt)
        return u

    @staticmethod
    def of_effects(effects) -> "InputDynamics":
        """What a plant's ``effects`` put between the logged input and the plant: their input
        delay or lag (the first), then their input dead band, if any (:class:`DeadBandInput`)."""
        found = [InputDynamics(e.kind.input_dynamics, float(e.coefficient)) for e in effects if e.kind.input_dynamics]
        dyn = found[0] if found else NO_INPUT_DYNAMICS
        bands = [float(e.coefficient) for e in effects if e.kind.shapes_input]
        return DeadBandInput(dyn.kind, dyn.seconds, bands[0]) if bands else dyn


NO_INPUT_DYNAMICS = InputDynamics()


@dataclasses.dataclass(frozen=True)
class DeadBandInput(InputDynamics):
    """The input dynamics followed by an ``input_dead_band``: u_eff = sgn(u)·max(|u| − d, 0)
    (:func:`~furuta_gym.effects.dead_band`), after the delay as the plant applies it. It acts
    on the input, not on the rotor's velocity (the rotor's Coulomb friction)."""

    dead_band: float = 0.0  # the input's unit (V)

    def apply(self, u: np.ndarray, dt: float) -> np.ndarray:
        return dead_band(super().apply(u, dt), self.dead_band, np)


def _group(x: np.ndarray, stride: int) -> np.ndarray:
    n = (x.shape[0] // stride) * stride
    return x[:n].reshape((n // stride, stride) + x.shape[1:]).sum(axis=1)


def _at_rest(q: np.ndarray, stride: int, n_intervals: int, dwell: int) -> np.ndarray:
    """(N, n): the joint stops within the interval: its logged position stays on one value for
    at least ``dwell`` consecutive samples (the whole interval if ``dwell`` > ``stride``). A
    quantised encoder that does not move for that long leaves the joint at rest to within one
    count, its velocity below what the estimate resolves: while it stops, dry friction holds it
    with any force up to breakaway, and sgn(q̇) of the estimate is a guess."""
    n = q.shape[1]
    idx = np.arange(n_intervals)[:, None] * stride + np.arange(stride + 1)[None, :]
    window = q[np.minimum(idx, q.shape[0] - 1)]  # (N, stride + 1, n)
    run = min(max(dwell, 2), stride + 1) - 1  # equal neighbours in a run of that many samples
    same = np.concatenate([np.zeros((n_intervals, 1, n)), np.cumsum(window[:, 1:] == window[:, :-1], axis=1)], 1)
    return np.any(same[:, run:] - same[:, :-run] == run, axis=1).reshape(n_intervals, n)


def _free_acceleration(layout: ParameterLayout, j: int):
    """Batched acceleration of joint ``j`` from rest under every force but its dry friction: the
    model without dry friction at (q, q̇ with q̇_j = 0, q̈ with q̈_j = 0), what the input and the
    other forces leave unbalanced on joint ``j``, over its inertia."""

    def build():
        def one(theta, q, qd, qdd, u):
            model = layout.model(theta, dry_friction=False)
            qd, qdd = qd.at[j].set(0.0), qdd.at[j].set(0.0)
            unbalanced = model.input_force(q, qd, u) - inverse_dynamics(model, q, qd, qdd)
            return unbalanced[j] / model.mass_matrix(q)[j, j]

        return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0, 0)))

    return _compiled("free_acceleration", layout, j, build=build)


def free_acceleration_along(layout: ParameterLayout, theta, q, qd, u, dt: float, j: int) -> np.ndarray:
    """(T,) :func:`_free_acceleration` of joint ``j`` along a measured run, q̈ by central
    differences of ``qd``."""
    qdd = np.gradient(qd, dt, axis=0)
    args = [jnp.asarray(x) for x in (q, qd, qdd, u)]
    return np.asarray(_free_acceleration(layout, j)(jnp.asarray(theta), *args))


def value_runs(q_j: np.ndarray) -> np.ndarray:
    """Bounds [0, …, T] of the runs of ``q_j`` on one logged value: run k is ``bounds[k]:bounds[k + 1]``."""
    change = np.flatnonzero(np.diff(q_j) != 0) + 1
    return np.concatenate([[0], change, [q_j.size]])


def _lower_hull(t: np.ndarray, x: np.ndarray) -> list[int]:
    """Indices of the lower convex hull of the points (t, x), t increasing (Andrew's chain)."""
    hull: list[int] = []
    for k in range(t.size):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            if (t[b] - t[a]) * (x[k] - x[a]) - (x[b] - x[a]) * (t[k] - t[a]) > 0:
                break
            hull.pop()
        hull.append(k)
    return hull


def free_excursion(a: np.ndarray, dt: float) -> float:
    """The least range of positions that a joint free of friction, under the acceleration ``a``
    (one value per sample), covers over the stretch, over every start velocity. Under a constant
    ``a`` over a time T it is |a|·T²/8: the parabola through a reversal in its middle, one count
    δ wide for at most T = 2·sqrt(2δ/|a|)."""
    if a.size < 3:
        return 0.0
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)])
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    t = np.arange(a.size) * dt
    # the least vertical width of the points (t, x) is taken along an edge of their convex hull
    slopes = []
    for sign in (1.0, -1.0):
        h = _lower_hull(t, sign * x)
        slopes += [(x[b] - x[a]) / (t[b] - t[a]) for a, b in zip(h[:-1], h[1:], strict=True)]
    y = x[None, :] - np.asarray(slopes)[:, None] * t[None, :]
    return float((y.max(axis=1) - y.min(axis=1)).min())


def held_samples(q_j: np.ndarray, a_j: np.ndarray, dt: float, counts: float) -> np.ndarray:
    """(T,) True in each run on one logged value of ``q_j`` over which a free joint under ``a_j``
    would have moved by more than ``counts`` of the position quantum (the smallest logged step):
    dry friction held it there. Through a reversal or a slow pass a free joint stays within one
    count (the excursion is at most one quantum), so shorter stops are motion and keep their
    equations."""
    held = np.zeros(q_j.size, bool)
    steps = np.abs(np.diff(q_j))
    steps = steps[steps > 0]
    if steps.size == 0:
        return held
    bounds = value_runs(q_j)
    for s, e in zip(bounds[:-1], bounds[1:], strict=True):
        if e - s >= 3 and _excursion_exceeds(a_j[s:e], dt, counts * steps.min()):
            held[s:e] = True
    return held


def _excursion_exceeds(a: np.ndarray, dt: float, limit: float) -> bool:
    """``free_excursion(a, dt) > limit``, decided without the hull when the chord says: the
    positions' deviation d from the chord of their ends bounds the least width w, max|d| ≤ w ≤
    max d − min d (a strip of any slope holds the ends and the farthest point, whose deviation
    from their chord does not depend on the slope; the chord's own strip is one strip)."""
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)])
    x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    d = x - x[-1] * np.arange(a.size) / (a.size - 1)
    # decided by a bound only well clear of the limit, so that round-off cannot flip the answer
    if np.max(np.abs(d)) > limit * (1 + 1e-9):
        return True
    if np.max(d) - np.min(d) < limit * (1 - 1e-9):
        return False
    return free_excursion(a, dt) > limit


def _held_stops(layout, theta0, seg: Segment, stride: int, n_intervals: int, counts: float) -> np.ndarray:
    """(N, n): the joint was held within the interval (:func:`held_samples`). The measured input
    drives it, not one through a trial delay or lag: which equations are left out must not change
    between the input dynamics the search compares."""
    key = (layout.cache_key, layout.candidates, np.asarray(theta0, dtype=float).tobytes(), stride, n_intervals, counts)
    if key in seg.held_stops:
        return seg.held_stops[key]
    out = np.zeros((n_intervals, seg.q.shape[1]), bool)
    idx = np.arange(n_intervals)[:, None] * stride + np.arange(stride + 1)[None, :]
    for j in range(seg.q.shape[1]):
        a = free_acceleration_along(layout, theta0, seg.q, seg.qd, seg.u, seg.dt, j)
        held = held_samples(seg.q[:, j], a, seg.dt, counts)
        out[:, j] = held[np.minimum(idx, seg.q.shape[0] - 1)].any(axis=1)
    out.flags.writeable = False  # shared by every build that asks
    seg.held_stops[key] = out
    return out


def build_regressors(
    segments: list[Segment],
    layout: ParameterLayout,
    theta0: np.ndarray,
    stride: int,
    hold: str,
    block_seconds: float = 1.0,
    dynamics: InputDynamics = NO_INPUT_DYNAMICS,
    exclude_rest: bool = True,
    stop_dwell: float | None = None,
    held_stop: float | None = None,
) -> None:
    """Fill each segment's Ā Jacobian, ∫u and delay regressor over intervals of ``stride``, and
    which joints stop in each (``exclude_rest``: on one logged value for ``stop_dwell`` s, None: the
    whole interval; or, given ``held_stop``, held by dry friction there: :func:`held_samples`
    with ``counts = held_stop``, the model at ``theta0``)."""
    for seg in segments:
        jp, jf = _per_sample(layout, theta0, seg.q, seg.qd)
        a = np.asarray(interval_difference(jp)) - np.asarray(interval_integral(jf, seg.dt))
        u = dynamics.apply(seg.u, seg.dt)
        ui = input_integral(u, seg.dt, hold)
        du_s = np.diff(u[:, 0], prepend=u[0, 0])
        du = -(du_s[:-1] if hold == "zoh" else du_s[1:])
        seg.A = _group(a, stride)
        seg.D = _group(np.asarray(interval_difference(jp)), stride)
        seg.Uint = _group(ui, stride)
        seg.dU = _group(du, stride)
        dwell = stride + 1 if stop_dwell is None else int(round(stop_dwell / seg.dt))
        seg.rest = _at_rest(seg.q, stride, seg.A.shape[0], dwell) if exclude_rest else np.zeros(seg.A.shape[:2], bool)
        if exclude_rest and held_stop is not None:
            seg.rest |= _held_stops(layout, theta0, seg, stride, seg.A.shape[0], held_stop)
        per_block = max(1, int(round(block_seconds / (stride * seg.dt))))
        seg.block = np.arange(seg.A.shape[0]) // per_block


def ee_fit(
    R: np.ndarray,
    D: np.ndarray,
    free: np.ndarray,
    theta_fixed: np.ndarray,
    weights: np.ndarray,
    scale: np.ndarray,
    extra: np.ndarray | None = None,
):
    """Scale-free equation-error fit: min ‖W R θ‖² / ‖W D θ‖², then the anchor fixes the scale.

    The integral residual is homogeneous in θ, so plain least squares with a fixed anchor is
    pulled towards a smaller overall scale whenever a candidate can mimic the anchor (noise in the
    estimated velocities scales with θ). Normalising by the momentum changes ``D θ`` (the
    pitfalls' Σ‖Δp‖²) removes that pull: the minimiser is the smallest generalized eigenvector.
    The non-free entries of ``theta_fixed`` set one direction ``s·θ_fixed``; ``s = 1`` afterwards.
    ``R``, ``D`` (N, n, P); ``extra`` (N, n, E) are extra residual columns (an input delay) that
    scale with the model (their coefficients are returned divided by ``s``).
    Returns (θ, extra coefficients).
    """
    w = weights[None, :, None]
    fixed_dir = np.where(free, 0.0, theta_fixed)
    cols_R = [(R @ fixed_dir)[..., None], R[:, :, free] * scale[free]]
    cols_D = [(D @ fixed_dir)[..., None], D[:, :, free] * scale[free]]
    if extra is not None:
        cols_R.append(extra)
        cols_D.append(np.zeros_like(extra))
    X = (np.concatenate(cols_R, axis=2) * w).reshape(-1, sum(c.shape[2] for c in cols_R))
    Y = (np.concatenate(cols_D, axis=2) * w).reshape(X.shape)
    norms = np.linalg.norm(X, axis=0)
    norms[norms == 0] = 1.0
    X, Y = X / norms, Y / norms
    A, B = X.T @ X, Y.T @ Y
    B = B + 1e-10 * np.trace(B) / B.shape[0] * np.eye(B.shape[0])
    vals, vecs = eigh(A, B)
    v = vecs[:, 0] / norms
    if abs(v[0]) < 1e-300:
        v = v + 1e-300
    v = v / v[0]
    theta = theta_fixed.copy()
    nf = int(free.sum())
    theta[free] = v[1 : 1 + nf] * scale[free]
    return theta, v[1 + nf :]


def residual(R: np.ndarray, theta: np.ndarray, extra=None, extra_coef=None) -> np.ndarray:
    r = R @ theta
    if extra is not None and extra_coef is not None and len(extra_coef):
        r = r + extra @ extra_coef
    return r
