"""Measured logs as training and test data: velocities, elementary trajectories, short windows.

A measured log is rarely usable as it comes: it has no velocities, starts with a transient, and
is one long record where training wants many short trajectories. This module turns logs into
training and test data the way the paper's appendix does for its experimental Furuta pendulum
("Data Generation", "Experimental data"): velocities estimated from the encoder angles (the paper
uses the derivative filter F(s) = ω0²s/(s² + 2ξω0s + ω0²), :func:`~furuta_gym.signals.derivative_filter`;
offline, :func:`~furuta_gym.signals.zero_phase_velocity` has no lag and is the default here, as in
``furuta-gym diagnose``) and "all the data split into elementary trajectories of 1 s"
(:data:`SPLIT_SECONDS`; the paper has no measured N-MSD, whose simulated trajectories are 2 s).

:func:`prepare_log` refuses a log that cannot serve with one :class:`~furuta_gym.data.DataError`
naming the log and the problem: shorter than one elementary trajectory, or no excitation (no
joint moved more than a few encoder counts: nothing about the dynamics is in it).

:func:`window_errors` scores a model on short open-loop windows started from the measured state
(measured angles, estimated velocities) with the logged input held over each sample period, as a
digital controller drives the motor: on an inverted pendulum a long open-loop prediction
diverges whatever the model (a 0.1 s window is about one e-folding time of the QUBE's upright
pendulum), so short windows are what tells models apart.
"""

from __future__ import annotations

import math
from typing import Sequence

import equinox as eqx
import jax
import numpy as np

from .data import DataError, Trajectory
from .models import SYSTEM_DEFINITIONS
from .signals import ENCODER_COUNTS_PER_REV, derivative_filter, zero_phase_velocity
from .simulate import DIVERGED, rollout_zoh

__all__ = [
    "SPLIT_SECONDS",
    "VELOCITY_METHODS",
    "MIN_MOTION",
    "estimate_velocities",
    "skip_start",
    "split_elementary",
    "check_log",
    "prepare_log",
    "prediction_windows",
    "window_predictions",
    "window_errors",
]

#: Length of the elementary trajectories measured logs are cut into, s, per system
#: (``SystemDefinition.elementary_seconds``).
SPLIT_SECONDS = {name: d.elementary_seconds for name, d in SYSTEM_DEFINITIONS.items()}
VELOCITY_METHODS = ("zero_phase", "derivative_filter")
#: Below this range on every joint a log has no excitation, rad: 5 counts of the QUBE's
#: 2048-count encoders, the size of encoder noise on a joint that does not move.
MIN_MOTION = 5 * 2.0 * math.pi / ENCODER_COUNTS_PER_REV


def estimate_velocities(tr: Trajectory, method: str = "zero_phase", cutoff_hz: float | None = None) -> Trajectory:
    """``tr`` with velocities; measured ones are kept, absent ones estimated by ``method``.

    ``"zero_phase"``: Butterworth low-pass forwards and backwards, then central differences; the
    cutoff defaults to min(25 Hz, 0.08·fs), as ``furuta-gym diagnose`` takes it (25 Hz at 500 Hz,
    well above the QUBE's motion bandwidth and below encoder noise). ``"derivative_filter"``: the
    paper's causal filter (ω0 = 100 rad/s, ξ = 0.8), which lags by ~16 ms and starts at rest.
    """
    if tr.qd is not None:
        return tr
    if method == "zero_phase":
        cutoff = cutoff_hz or min(25.0, 0.08 / tr.dt)
        qd = zero_phase_velocity(tr.q, tr.dt, cutoff_hz=cutoff)
    elif method == "derivative_filter":
        qd = derivative_filter(tr.q, tr.dt)
    else:
        raise ValueError(f"velocity: expected one of {VELOCITY_METHODS}, got {method!r}")
    return Trajectory(t=tr.t, q=tr.q, u=tr.u, qd=qd, name=tr.name)


def skip_start(tr: Trajectory, seconds: float) -> Trajectory:
    """``tr`` without its first ``seconds`` (a start transient)."""
    if not seconds > 0:
        return tr
    keep = tr.t >= tr.t[0] + seconds - 1e-9
    return Trajectory(t=tr.t[keep], q=tr.q[keep], u=tr.u[keep], qd=None if tr.qd is None else tr.qd[keep], name=tr.name)


def split_elementary(tr: Trajectory, seconds: float | None) -> list[Trajectory]:
    """Consecutive, non-overlapping pieces of ``round(seconds / dt)`` samples each (the paper's
    1 s at 100 Hz are 100 samples); a remainder shorter than one piece is dropped. ``None`` or
    0: the whole trajectory. Pieces are named ``<name>:<k>``."""
    if not seconds:
        return [tr]
    n = int(round(seconds / tr.dt))
    if n < 3:
        raise ValueError(f"split: {seconds!r} s is fewer than 3 samples at dt = {tr.dt:.6g} s")
    out = []
    for k in range(len(tr) // n):
        s = slice(k * n, (k + 1) * n)
        out.append(
            Trajectory(t=tr.t[s], q=tr.q[s], u=tr.u[s], qd=None if tr.qd is None else tr.qd[s], name=f"{tr.name}:{k}")
        )
    return out


def check_log(tr: Trajectory, source: str, min_seconds: float = 0.0, min_motion: float = MIN_MOTION) -> None:
    """Raise :class:`DataError` naming ``source`` if ``tr`` cannot serve: shorter than
    ``min_seconds`` (one elementary trajectory / window) or no joint moved more than
    ``min_motion`` rad (no excitation)."""
    duration = len(tr) * tr.dt if len(tr) > 1 else 0.0  # n samples hold n sample periods
    if len(tr) < max(3, round(min_seconds / tr.dt) if len(tr) > 1 else 3):
        raise DataError(
            f"{source}: trajectory {tr.name!r} is too short: {duration:.3g} s ({len(tr)} samples) "
            f"after the skipped start; expected at least {min_seconds:.3g} s (one elementary "
            "trajectory / window; lower --split or --skip)"
        )
    ranges = np.ptp(np.asarray(tr.q, dtype=float), axis=0)
    if float(np.max(ranges)) < min_motion:
        moved = ", ".join(f"{r:.2g}" for r in ranges)
        raise DataError(
            f"{source}: trajectory {tr.name!r} has no excitation: its joints moved over ranges of "
            f"({moved}) rad in {duration:.3g} s, below {min_motion:.3g} rad (5 encoder counts); "
            "nothing about the dynamics can be learned or scored from it"
        )


def prepare_log(
    tr: Trajectory,
    source: str,
    *,
    velocity: str = "zero_phase",
    cutoff_hz: float | None = None,
    skip: float = 0.0,
    split: float | None = None,
    min_seconds: float = 0.0,
) -> list[Trajectory]:
    """One log as training/test trajectories: velocities estimated on the whole log (a filter's
    start-up then falls into the skipped start, and no piece is filtered on its own), start
    skipped, checked (:func:`check_log`), cut into elementary trajectories of ``split`` s."""
    tr = skip_start(estimate_velocities(tr, velocity, cutoff_hz), skip)
    check_log(tr, source, max(min_seconds, split or 0.0))
    return split_elementary(tr, split)


# ----------------------------------------------------------------------------- short windows


def prediction_windows(trajs: Sequence[Trajectory], seconds: float, stride: float | None = None):
    """Windows of ``round(seconds / dt)`` sample periods cut from ``trajs`` (one every ``stride``
    s, default back to back). Returns ``(x0 (W, 2n), us (W, L, m), xs (W, L + 1, 2n))``: the
    measured start state, the L inputs held over the window's periods, the measured states."""
    dt = float(np.median([tr.dt for tr in trajs]))
    n = int(round(seconds / dt))
    step = n if stride is None else max(1, int(round(stride / dt)))
    if n < 1:
        raise ValueError(f"window: {seconds!r} s is shorter than one sample period ({dt:.6g} s)")
    x0, us, xs = [], [], []
    for tr in trajs:
        x = tr.x
        u = np.asarray(tr.u, dtype=float).reshape(len(tr), -1)
        for a in range(0, len(tr) - n, step):
            x0.append(x[a])
            us.append(u[a : a + n])
            xs.append(x[a : a + n + 1])
    if not x0:
        raise DataError(f"window: every trajectory is shorter than one {seconds:.3g} s window")
    return np.asarray(x0), np.asarray(us), np.asarray(xs)


_ROLLOUTS: dict = {}


def window_predictions(model, x0, us, dt: float, substeps: int = 4, batch: int = 256) -> np.ndarray:
    """Open-loop states (W, L + 1, 2n) of ``model`` from each ``x0`` with ``us`` held over each
    period (fixed-step RK4, ``substeps`` per period: the envs' scheme, and one that steps over a
    Coulomb friction's sign change where an adaptive solver would crawl). Non-finite where a
    prediction blew up. Windows go through in padded batches of ``batch``, so one compiled call
    serves every window set of the same length."""
    params, static = eqx.partition(model, eqx.is_array)
    key = (static, jax.tree_util.tree_structure(params), us.shape[1:], float(dt), substeps, batch)
    fn = _ROLLOUTS.get(key)
    if fn is None:

        def one(p, x, u):
            return rollout_zoh(eqx.combine(p, static), x, u, dt, substeps)

        fn = _ROLLOUTS[key] = jax.jit(jax.vmap(one, in_axes=(None, 0, 0)))
    out = []
    for s in range(0, len(x0), batch):
        idx = np.arange(s, min(s + batch, len(x0)))
        pad = np.concatenate([idx, np.full(batch - idx.size, idx[-1])])  # one shape for all
        out.append(np.asarray(fn(params, x0[pad], us[pad]))[: idx.size])
    return np.concatenate(out)


def window_errors(
    model,
    trajs: Sequence[Trajectory],
    seconds: float,
    *,
    stride: float | None = None,
    substeps: int = 4,
    divergence_bound: float = 1e6,
) -> dict:
    """Per-state errors of ``model``'s open-loop predictions over short windows of ``trajs``
    (:func:`prediction_windows`, :func:`window_predictions`), pooled over windows and samples.

    Returns ``{"log10_rmse": {state: value}, "rmse": {state: value}, "n_windows", "n_diverged",
    "window_seconds"}``; RMSE in the states' units (rad, rad/s). As in the paper's tables, a
    model whose prediction diverges on any window scores ``"X"`` on every state (``rmse``
    then holds the RMSE over the windows that did not)."""
    x0, us, xs = prediction_windows(trajs, seconds, stride)
    dt = float(np.median([tr.dt for tr in trajs]))
    pred = window_predictions(model, x0, us, dt, substeps)
    bad = ~np.all(np.isfinite(pred) & (np.abs(pred) < divergence_bound), axis=(1, 2))
    # the start sample is the measured state itself: left out, it would only dilute the error
    err = (pred - xs)[~bad][:, 1:].reshape(-1, xs.shape[-1])
    names = model.spec.state_names
    rmse = {k: (float(np.sqrt(np.mean(err[:, i] ** 2))) if err.size else None) for i, k in enumerate(names)}
    log10 = {k: DIVERGED if bad.any() else (math.log10(v) if v else -math.inf) for k, v in rmse.items()}
    return {
        "log10_rmse": log10,
        "rmse": rmse,
        "n_windows": int(len(x0)),
        "n_diverged": int(bad.sum()),
        "window_seconds": float(seconds),
    }
