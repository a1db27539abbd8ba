"""Output error: open-loop windows started from measured states (measured angle, estimated
velocity) with the measured input held (RK4, :func:`furuta_gym.simulate.rollout_zoh`; dry friction
that holds a joint at rest, :func:`furuta_gym.lagrangian.forward_dynamics_with_dry_friction`),
position error only, and the Gauss-Newton fit (scipy ``least_squares``) of θ on them, started from
the equation-error estimate of :mod:`._fit`. It removes the errors-in-variables bias the noisy
velocity estimates put into the equation-error fit.
"""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares

from ..lagrangian import forward_dynamics_with_dry_friction
from ..simulate import rollout_zoh
from ..systems import get_spec
from ._fit import NO_INPUT_DYNAMICS, InputDynamics, Segment, _compiled
from ._library import ParameterLayout

__all__ = [
    "Windows",
    "make_windows",
    "oe_fit",
    "position_rmse",
    "predict_windows",
    "predict_windows_at",
    "window_errors",
    "window_residuals",
    "window_square_sums",
]


@dataclasses.dataclass
class Windows:
    """Open-loop windows: start states, held inputs and measured positions after each step."""

    x0: np.ndarray  # (W, 2n)
    us: np.ndarray  # (W, L, m)
    q: np.ndarray  # (W, L, n) measured positions at steps 1..L
    segment: np.ndarray  # (W,) index of the segment each window came from
    dt: float
    length: int

    def take(self, idx) -> "Windows":
        """The windows ``idx`` (indices or a mask) of these."""
        return Windows(self.x0[idx], self.us[idx], self.q[idx], self.segment[idx], self.dt, self.length)


def make_windows(
    segments: list[Segment], length: int, dynamics: InputDynamics = NO_INPUT_DYNAMICS, max_windows=None, rng=None
):
    """Non-overlapping windows of ``length`` steps from each segment (start at measured states)."""
    x0, us, qs, seg_idx = [], [], [], []
    for i, s in enumerate(segments):
        u = dynamics.apply(s.u, s.dt)
        for start in range(0, s.q.shape[0] - length, length):
            x0.append(np.concatenate([s.q[start], s.qd[start]]))
            us.append(u[start : start + length])
            qs.append(s.q[start + 1 : start + length + 1])
            seg_idx.append(i)
    if not x0:
        return None
    w = Windows(np.array(x0), np.array(us), np.array(qs), np.array(seg_idx), segments[0].dt, length)
    if max_windows is not None and len(w.x0) > max_windows:
        rng = rng or np.random.default_rng(0)
        keep = np.sort(rng.choice(len(w.x0), max_windows, replace=False))
        w = w.take(keep)
    return w


_BATCH = 64  # (θ, window) pairs per compiled call: every window set reuses one compiled shape


def _refined_positions(positions, v, x, u, q_measured, iterations: int):
    """A window's predicted positions after Gauss-Newton steps on its start velocity: the velocity
    that best explains the window's measured positions under the model. A step that does not
    lower the window's error is not taken; the last rollout is reused as the prediction."""
    if not iterations:
        return positions(v, x, u)
    n = v.shape[0]
    for _ in range(iterations):
        # the rollout and its n tangents in one pass (2-3x faster than jax.linearize, which stores
        # every step's residuals and replays them per tangent)
        def with_tangent(t, v=v):
            return jax.jvp(lambda vv: positions(vv, x, u), (v,), (t,))

        p, J = jax.vmap(with_tangent, out_axes=(None, -1))(jnp.eye(n))
        r = (p - q_measured).reshape(-1)
        J = J.reshape(-1, n)
        JtJ = J.T @ J
        v_new = v - jnp.linalg.solve(JtJ + (1e-9 * jnp.trace(JtJ) + 1e-300) * jnp.eye(n), J.T @ r)
        p_new = positions(v_new, x, u)
        better = jnp.sum((p_new - q_measured) ** 2) < r @ r  # False for a non-finite rollout
        v, p = jnp.where(better, v_new, v), jnp.where(better, p_new, p)
    return p


def _predictor(layout: ParameterLayout, dt: float, length: int, substeps: int, start_iterations: int = 0):
    """The compiled open-loop predictor of a batch of windows, each under its own θ."""
    n = get_spec(layout.system).n_dof
    h = dt / substeps

    def one(theta, x, u, q_measured):
        model = layout.model(theta, dry_friction=False)

        def field(x, u):  # dry friction that holds a joint at rest, as a real one does
            q, qd = x[:n], x[n:]
            limit = layout.dry_friction_limit(theta, qd)
            return jnp.concatenate([qd, forward_dynamics_with_dry_friction(model, limit, q, qd, u, h)])

        def positions(v, x, u):
            return rollout_zoh(model, jnp.concatenate([x[:n], v]), u, dt, substeps, field)[1:, :n]

        return _refined_positions(positions, x[n:], x, u, q_measured, start_iterations)

    return _compiled("predict", layout, dt, length, substeps, start_iterations, build=lambda: jax.jit(jax.vmap(one)))


def predict_windows(layout, theta, win: Windows, substeps: int = 1, start_iterations: int = 0) -> np.ndarray:
    """Open-loop position predictions of each window; with ``start_iterations`` > 0 each window's
    start velocity is first re-estimated from its own positions (Gauss-Newton steps)."""
    return predict_windows_at(layout, np.asarray(theta, dtype=float)[None], win, substeps, start_iterations)[0]


def predict_windows_at(layout, thetas, win: Windows, substeps: int = 1, start_iterations: int = 0) -> np.ndarray:
    """:func:`predict_windows` under each of ``thetas`` (K, P) at once: (K, W, L, n). The (θ,
    window) pairs share padded batches of one compiled shape: a finite-difference Jacobian's
    columns run together, and a wide batch costs far less per window than a narrow one."""
    predict = _predictor(layout, win.dt, win.length, substeps, start_iterations)
    thetas = np.asarray(thetas, dtype=float)
    W = win.x0.shape[0]
    which, window = np.divmod(np.arange(len(thetas) * W), W)

    def batch(s: int) -> np.ndarray:
        real = np.arange(s, min(s + _BATCH, which.size))
        pad = np.concatenate([real, np.full(_BATCH - real.size, real[-1])])  # repeats; masked out
        k, w = which[pad], window[pad]
        return np.asarray(predict(*map(jnp.asarray, (thetas[k], win.x0[w], win.us[w], win.q[w]))))[: real.size]

    # the batches run side by side: one batch keeps about one core busy, and each gives the same
    # numbers on any thread (one compiled shape, the same pairs in it)
    starts = range(0, which.size, _BATCH)
    out = list(_batch_pool().map(batch, starts)) if len(starts) > 1 else [batch(0)]
    return np.concatenate(out).reshape(len(thetas), *win.q.shape)


_POOL: list[ThreadPoolExecutor] = []
if hasattr(os, "register_at_fork"):  # a forked child has none of the parent's threads: a new pool
    os.register_at_fork(after_in_child=_POOL.clear)


def _batch_pool() -> ThreadPoolExecutor:
    """Threads for :func:`predict_windows_at`'s batches, one per core this process may use."""
    if not _POOL:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        _POOL.append(ThreadPoolExecutor(max(1, cores), thread_name_prefix="furuta-gym-windows"))
    return _POOL[0]


def window_residuals(layout, theta, win: Windows, substeps: int = 1, start_iterations: int = 0) -> np.ndarray:
    """(W·L·n,) predicted − measured positions of every window, window by window (the output-error
    fit's residual, non-finite where a rollout blew up)."""
    return (predict_windows(layout, theta, win, substeps, start_iterations) - win.q).reshape(-1)


def position_rmse(sums, length: int, n: int) -> float:
    """Position RMSE over every joint (``n``) and step (``length``) of the windows whose squared
    errors sum to ``sums``, one per window."""
    sums = np.asarray(sums, dtype=float)
    return float(np.sqrt(sums.sum() / (sums.size * length * n)))


def window_square_sums(layout, theta, win: Windows, substeps: int = 1, start_iterations: int = 0) -> np.ndarray:
    """(W,) sum of squared position errors of each open-loop window (inf where it blew up)."""
    err = predict_windows(layout, theta, win, substeps, start_iterations) - win.q
    ss = np.sum(err**2, axis=(1, 2))
    return np.where(np.isfinite(ss), ss, np.inf)


def window_errors(layout, theta, win: Windows, substeps: int = 1, start_iterations: int = 0):
    """Per-joint RMS position error of open-loop window predictions, and the combined RMS."""
    pred = predict_windows(layout, theta, win, substeps, start_iterations)
    err = pred - win.q
    if not np.all(np.isfinite(err)):
        per = np.full(err.shape[-1], np.inf)
        return per, float("inf")
    per = np.sqrt(np.mean(err**2, axis=(0, 1)))
    return per, float(np.sqrt(np.mean(err**2)))


def oe_fit(
    layout: ParameterLayout,
    theta_start: np.ndarray,
    free: np.ndarray,
    win: Windows,
    substeps: int = 1,
    max_nfev: int = 10,
    start_iterations: int = 0,
):
    """Refine the free entries of θ by output error (Gauss-Newton / trust region).

    Returns (θ, improved flag): the start is returned unchanged with ``False`` if it does not
    simulate or the fit does not lower the output error. Base parameters are bounded below by 0.
    """
    if not np.any(free):
        return theta_start, False
    scale = np.maximum(np.abs(theta_start), layout.typical_scale() * 1e-2)
    scale = np.where(free, scale, 1.0)

    def full(z):
        th = theta_start.copy()
        th[free] = z * scale[free]
        return th

    latest: list = [None, None]  # the point last evaluated (its bytes) and its residual

    def f(z):
        r = (predict_windows(layout, full(z), win, substeps, start_iterations) - win.q).reshape(-1)
        latest[:] = [z.tobytes(), np.where(np.isfinite(r), r, 1e3)]
        return latest[1].copy()  # the kept one stays as computed whatever the solver does with its copy

    def J(z):
        # forward differences, every column in one batched prediction (an autodiff Jacobian
        # through the RK4 scan costs far more to compile than it saves here); the trust region
        # asks for the Jacobian where it has just evaluated the residual
        r0 = latest[1] if latest[0] == z.tobytes() else f(z)
        h = 1e-6 * np.maximum(1.0, np.abs(z))
        stepped = np.stack([full(z + step) for step in np.diag(h)])
        r = (predict_windows_at(layout, stepped, win, substeps, start_iterations) - win.q).reshape(z.size, -1)
        return (np.where(np.isfinite(r), r, 1e3) - r0).T / h

    z0 = theta_start[free] / scale[free]
    r0 = f(z0)
    if np.any(r0 >= 1e3):
        return theta_start, False
    # physical bounds: the declared model's inertias, masses and damping stay non-negative
    n_base = len(layout.base)
    lower = np.full(layout.size, -np.inf)
    lower[:n_base] = 0.0
    lo = lower[free] / scale[free]
    z0 = np.maximum(z0, lo + 1e-9)
    # scipy's annotation of jac leaves out the callable it takes
    sol = least_squares(
        f,
        z0,
        jac=J,  # pyright: ignore[reportArgumentType]
        method="trf",
        bounds=(lo, np.inf),
        max_nfev=max_nfev,
        x_scale="jac",
    )
    if sol.cost >= 0.5 * float(r0 @ r0):  # never return something worse than the start
        return theta_start, False
    return full(sol.x), True
