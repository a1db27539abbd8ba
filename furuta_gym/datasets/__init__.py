"""Real measured data shipped with the package.

``qube_servo_closed_loop/``: fifteen 20 s runs of a real Quanser QUBE-Servo balancing its
pendulum upright under a PD controller with a ±0.5 V excitation, logged at 500 Hz. From the
public repository decargroup/closed_loop_koopman (commit 0b64a62e, folder
dataset/controller_20230828/), collected for "Closed-Loop Koopman Operator Approximation"
(Lortie & Forbes, 2023). MIT licence, Copyright (c) 2023 DECAR: the licence text ships beside the
data (``qube_servo_closed_loop/LICENSE``); the README.md there lists what was changed.

The files keep their own names and convention (``theta`` arm, ``alpha`` pendulum with 0 upright);
:data:`QUBE_CLOSED_LOOP_MAPPING` converts them to this project's (``alpha`` arm, ``beta`` = π
upright, ``u`` = motor voltage)::

    from furuta_gym.datasets import load_qube_closed_loop
    runs = load_qube_closed_loop()          # 15 Trajectory objects, run01 .. run15
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import Iterable

from ..data import Trajectory, load_trajectories
from ..systems import FURUTA

__all__ = [
    "QUBE_CLOSED_LOOP_SYSTEM",
    "QUBE_CLOSED_LOOP_RUNS",
    "QUBE_CLOSED_LOOP_MAPPING",
    "qube_closed_loop_files",
    "load_qube_closed_loop",
]

QUBE_CLOSED_LOOP_SYSTEM = FURUTA
"""The system the vendored runs are logs of."""

QUBE_CLOSED_LOOP_RUNS = 15
"""Number of vendored runs; run numbers are 1-based."""

QUBE_CLOSED_LOOP_MAPPING = {
    "column_map": {"alpha": "theta", "beta": "alpha", "u": "plant_input"},
    "signs": {"beta": -1.0},
    "offsets": {"beta": math.pi},
}
"""Keyword arguments of :func:`furuta_gym.data.load_trajectories` for these files:
alpha = theta, beta = π − alpha(file), u = plant_input (V)."""

_QUBE_DIR = Path(__file__).resolve().parent / "qube_servo_closed_loop"


def qube_closed_loop_files(runs: Iterable[int] | None = None) -> list[Path]:
    """Paths of the vendored runs for the 1-based run numbers ``runs`` (None: all 15, in order)."""
    if runs is None:
        run_numbers = list(range(1, QUBE_CLOSED_LOOP_RUNS + 1))
    else:
        if isinstance(runs, (int, str)):
            raise ValueError(f"runs must be a list of run numbers 1..{QUBE_CLOSED_LOOP_RUNS} or None, got {runs!r}")
        run_numbers = list(runs)
        bad = [
            r
            for r in run_numbers
            if isinstance(r, bool) or not isinstance(r, numbers.Integral) or not 1 <= r <= QUBE_CLOSED_LOOP_RUNS
        ]
        if bad:
            raise ValueError(f"runs holds {bad!r}; valid run numbers are 1..{QUBE_CLOSED_LOOP_RUNS} (1-based)")
    paths = [_QUBE_DIR / f"run{int(r):02d}.csv.gz" for r in run_numbers]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"vendored data file(s) missing from the package: {missing}")
    return paths


def load_qube_closed_loop(runs: Iterable[int] | None = None, skip_seconds: float = 0.5) -> list[Trajectory]:
    """Load the vendored QUBE-Servo runs as Furuta trajectories in the project's convention.

    ``runs``: 1-based run numbers (None: all 15). The first ``skip_seconds`` of each run (the
    controller's start transient) are dropped; time stamps stay as in the file (the first kept
    sample is at t ≈ ``skip_seconds``). Each trajectory is named ``runNN``. Velocities are not
    logged (``qd`` is None): estimate them with :mod:`furuta_gym.signals`.
    """
    if not skip_seconds >= 0:
        raise ValueError(f"skip_seconds must be >= 0, got {skip_seconds!r}")
    out = []
    for path in qube_closed_loop_files(runs):
        (tr,) = load_trajectories(path, QUBE_CLOSED_LOOP_SYSTEM.name, **QUBE_CLOSED_LOOP_MAPPING)
        keep = tr.t >= tr.t[0] + skip_seconds - 1e-9
        if keep.sum() < 3:
            raise ValueError(f"skip_seconds={skip_seconds!r} leaves fewer than 3 samples of {path.name}")
        out.append(
            Trajectory(
                t=tr.t[keep],
                q=tr.q[keep],
                u=tr.u[keep],
                qd=None if tr.qd is None else tr.qd[keep],
                name=path.name.split(".")[0],
            )
        )
    return out
