"""Simulated data several test modules train on (written once)."""

from __future__ import annotations

import numpy as np

from furuta_gym.data import Trajectory
from furuta_gym.models import NMSD
from furuta_gym.signals import chirp
from furuta_gym.simulate import simulate

DT = 0.01


def nmsd_chirp_segments(amplitude: float) -> list[Trajectory]:
    """One tight N-MSD solve under an ``amplitude`` N chirp of 0.1 -> 1.1 Hz over 8 s from
    (0.5 m, -1 m/s), cut into eight 1 s segments at 100 Hz, with exact velocities."""
    t = np.arange(0.0, 8.0 + DT / 2, DT)
    u = amplitude * chirp(t, 0.1, 1.1, 8.0)[:, None]
    xs = np.asarray(simulate(NMSD(), np.array([0.5, -1.0]), t, u, rtol=1e-10, atol=1e-12))
    n = 100
    return [
        Trajectory(
            t[k * n : k * n + n + 1] - t[k * n],
            xs[k * n : k * n + n + 1, :1],
            u[k * n : k * n + n + 1],
            xs[k * n : k * n + n + 1, 1:],
            name=str(k),
        )
        for k in range(8)
    ]
