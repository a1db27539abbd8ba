"""Clean trajectories on the sensor grid: the building blocks of every system's data recipe.

A ground truth maps x0 (B, 2n), sample times t (T,) and inputs u (B, T, m) to states (B, T, 2n);
the recipes (``_furuta_data.py``, ``_nmsd_data.py``) say which initial states and inputs.
"""

from __future__ import annotations

import dataclasses
import hashlib
from typing import Callable

import numpy as np

__all__ = ["DATA_RATE_HZ", "Clean", "GroundTruth", "run_batch", "run_each", "uniform", "stream"]

DATA_RATE_HZ = 100.0

GroundTruth = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclasses.dataclass
class Clean:
    """Noise-free states on the sensor grid."""

    t: np.ndarray  # (T,)
    x: np.ndarray  # (T, 2n)
    u: np.ndarray  # (T, m)
    name: str


def _grid(duration: float, rate: float) -> np.ndarray:
    n = int(round(duration * rate))
    return np.arange(n + 1) / rate


def _inputs_at(u_fn, t_data: np.ndarray, oversample: int) -> tuple[np.ndarray, np.ndarray]:
    """The sensor grid and the input on it: sampled at the data rate, linearly interpolated."""
    u_data = np.asarray(u_fn(t_data), dtype=float)
    t_fine = np.arange((len(t_data) - 1) * oversample + 1) / (oversample / (t_data[1] - t_data[0]))
    t_fine = t_data[0] + t_fine
    return t_fine, np.interp(t_fine, t_data, u_data)


def run_batch(gt: GroundTruth, x0s, duration, u_fn, oversample, names) -> list[Clean]:
    """One trajectory per row of ``x0s``, all under the input ``u_fn(t)`` (sampled at
    :data:`DATA_RATE_HZ`, linear in between)."""
    t_data = _grid(duration, DATA_RATE_HZ)
    t_fine, u_fine = _inputs_at(u_fn, t_data, oversample)
    us = np.broadcast_to(u_fine[None, :, None], (len(x0s), len(t_fine), 1)).copy()
    xs = gt(np.asarray(x0s, dtype=float), t_fine, us)
    return [Clean(t=t_fine, x=xs[b], u=us[b], name=names[b]) for b in range(len(x0s))]


def uniform(rng, n, ranges):
    """``n`` states drawn uniformly in ±``ranges`` (one range per state variable)."""
    ranges = np.asarray(ranges, dtype=float)
    return rng.uniform(-ranges, ranges, size=(n, len(ranges)))


def stream(seed: int, dataset: str) -> np.random.Generator:
    """The random stream of one dataset."""
    # one independent stream per dataset, stable under recipe changes of the other datasets
    digest = int(hashlib.sha256(dataset.encode()).hexdigest()[:8], 16)
    return np.random.default_rng([seed, digest])


def run_each(gt, name, seed, n, ranges, duration, make_u, oversample) -> list[Clean]:
    """``n`` trajectories of dataset ``name``, each with its own x0 and its own draw of the input
    signal ``make_u(rng)`` (one seeded stream per dataset)."""
    rng = stream(seed, name)
    x0s = uniform(rng, n, ranges)
    return [run_batch(gt, x0s[k : k + 1], duration, make_u(rng), oversample, [f"{name}{k}"])[0] for k in range(n)]
