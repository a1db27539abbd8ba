"""Episode metrics of a swing-up/balance run (numpy; shared by tests, the CLI and the benchmark).

Success: the pendulum is upright, |wrap(β − π)| < ``upright_tol`` (0.1 rad), and stays so for
``hold`` seconds (2 s) without interruption. Time to upright: the start of the first such
held interval. Divergence: a non-finite state, or |α̇| or |β̇| beyond 200 rad/s.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["EpisodeMetrics", "episode_metrics"]


@dataclasses.dataclass
class EpisodeMetrics:
    """One episode's numbers (SI units, volts)."""

    success: bool
    time_to_upright: float | None  # s, start of the first held upright interval
    peak_voltage: float  # V
    control_energy: float  # ∫ u² dt, V²·s
    peak_abs_alpha: float  # rad
    diverged: bool

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def episode_metrics(
    xs: ArrayLike,
    us: ArrayLike,
    dt: float,
    upright_tol: float = 0.1,
    hold: float = 2.0,
    divergence_speed: float = 200.0,
) -> EpisodeMetrics:
    """Metrics of one trajectory: ``xs`` (T+1, 4) states at control instants, ``us`` (T, 1)."""
    xs = np.asarray(xs, dtype=float)
    us = np.asarray(us, dtype=float).reshape(-1)
    finite = np.all(np.isfinite(xs), axis=1)
    diverged = bool((~finite).any() or (np.abs(xs[finite][:, 2:]) > divergence_speed).any())
    if (~finite).any():
        xs = xs[: int(np.argmin(finite))]
    err = np.abs(np.mod(xs[:, 1] - np.pi + np.pi, 2 * np.pi) - np.pi)
    up = err < upright_tol
    need = int(round(hold / dt))
    time_to_upright, success = None, False
    run = 0
    for i, flag in enumerate(up):  # first run of ≥ need consecutive upright samples
        run = run + 1 if flag else 0
        if run >= need + 1:
            success, time_to_upright = True, (i - need) * dt
            break
    return EpisodeMetrics(
        success=bool(success) and not diverged,
        time_to_upright=time_to_upright,
        peak_voltage=float(np.max(np.abs(us))) if us.size else 0.0,
        control_energy=float(np.sum(us**2) * dt),
        peak_abs_alpha=float(np.max(np.abs(xs[:, 0]))) if xs.size else 0.0,
        diverged=diverged,
    )
