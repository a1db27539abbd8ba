"""Log → prepared data, the diagnosis's first step: the logs read as every log is, checked, their
velocities estimated, cut into fit / held-out / test segments; the encoders' resolution."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..data import DataError, Trajectory, read_log, read_trajectories
from ..measured import estimate_velocities
from ..signals import ENCODER_COUNTS_PER_REV
from . import _fit
from ._settings import DiagnosisSettings


def _as_trajectories(data, spec, reading: dict, notes: list[str]) -> list[Trajectory]:
    """``data`` (paths or trajectories) read as every log is (:func:`furuta_gym.data.read_log`),
    what the reading did added to ``notes``."""
    one_path = isinstance(data, (str, Path))
    items = [data] if isinstance(data, (str, Path, Trajectory)) else list(data)
    paths = [d for d in items if isinstance(d, (str, Path))]
    trajs = [d for d in items if isinstance(d, Trajectory)]
    if paths and len(paths) == len(items):
        out = []
        for path in paths:
            read = read_log(path, spec, **reading)
            notes += read.notes
            for tr in read.trajectories:
                if not one_path:  # several files: their trajectories named by file
                    tr.name = f"{Path(path).stem}:{tr.name}"
                out.append(tr)
        return out
    if not trajs or len(trajs) != len(items):
        raise DataError("data: expected a file path or a list of furuta_gym.data.Trajectory")
    read = read_trajectories(trajs, spec, units=reading.get("units"), time_unit=reading.get("time_unit"))
    notes += read.notes
    return read.trajectories


def _velocities(tr: Trajectory, settings: DiagnosisSettings) -> np.ndarray:
    """Measured velocities, or estimated as train and evaluate estimate them."""
    return np.asarray(
        estimate_velocities(tr, settings.reading.velocity, settings.reading.velocity_cutoff_hz).qd, dtype=float
    )


def _check_data(trajs: list[Trajectory], spec, settings: DiagnosisSettings) -> None:
    dts = [tr.dt for tr in trajs]
    if max(dts) > 1.001 * min(dts):
        raise DataError(f"trajectories have different sample periods {sorted(set(dts))}; expected one")
    dt = dts[0]
    total = sum(len(tr) for tr in trajs) * dt
    assert settings.output_error.window is not None  # resolved settings
    need = 10 * settings.output_error.window + 2 * settings.reading.trim_seconds * len(trajs)
    if total < need:
        raise DataError(
            f"too short: {total:.2f} s of data in {len(trajs)} trajectory(ies); diagnosing a "
            f"{spec.name} needs at least {need:.1f} s (10 open-loop windows of {settings.output_error.window} s "
            f"for fitting and held-out errors)"
        )
    if not any(len(tr) * dt > settings.output_error.window + 2 * settings.reading.trim_seconds + dt for tr in trajs):
        raise DataError(f"too short: every trajectory is shorter than one {settings.output_error.window} s window")
    q_all = np.concatenate([tr.q for tr in trajs])
    for j, name in enumerate(spec.joint_names):
        rng = float(np.ptp(q_all[:, j]))
        floor = 3 * 2 * np.pi / ENCODER_COUNTS_PER_REV if spec.angular[j] else 1e-6
        if rng <= floor:
            raise DataError(
                f"no excitation: joint {name!r} only moves {rng:.3g} {spec.joint_units[j]} over all "
                f"data; the fit needs it to move (more than {floor:.3g}). Excite it (input or "
                f"initial conditions)"
            )


def _runs(trajs) -> list[list[int]]:
    """Indices of ``trajs`` grouped by the trajectory they were cut from: consecutive pieces
    ``<name>/1``, ``<name>/2``, ... of one log its reading split at a gap or at missing values."""
    out: list[list[int]] = []
    for k, tr in enumerate(trajs):
        base = tr.name.rpartition("/")[0]
        prev = trajs[out[-1][-1]] if out else None
        if prev is not None and base and prev.name.rpartition("/")[0] == base and tr.t[0] > prev.t[-1]:
            out[-1].append(k)
        else:
            out.append([k])
    return out


def _pieces(trajs, qds, settings: DiagnosisSettings):
    """Trajectories cut into segments of about ``segment_seconds`` (ends trimmed), each with the
    index of its segment on its trajectory's grid. The pieces of a split log are cut on the
    whole log's grid, so a gap only removes the segments it falls in (trimmed at its edges too)
    and the rest are fitted or held out as in the log without it."""
    dt = trajs[0].dt
    trim = int(round(settings.reading.trim_seconds / dt))
    seg_len = int(round(settings.reading.segment_seconds / dt))
    min_len = int(round(settings.output_error.window / dt)) + 2
    pieces, i = [], 0
    for run in _runs(trajs):
        first, last = trajs[run[0]], trajs[run[-1]]
        grid = [
            np.arange(len(trajs[j])) if len(run) == 1 else np.round((trajs[j].t - first.t[0]) / first.dt).astype(int)
            for j in run
        ]
        lo, hi = trim, int(grid[-1][-1]) + 1 - trim
        if hi - lo < min_len:
            continue
        n_seg = max(1, (hi - lo) // seg_len)
        bounds = np.linspace(lo, hi, n_seg + 1).astype(int)
        for k in range(n_seg):
            for j, n in zip(run, grid, strict=True):
                tr, qd = trajs[j], qds[j]
                a = max(bounds[k], n[0] + (trim if tr is not first else 0))
                b = min(bounds[k + 1], n[-1] + 1 - (trim if tr is not last else 0))
                if b - a >= min_len:
                    s = slice(a - n[0], b - n[0])
                    pieces.append((f"{tr.name}[{k}]", tr.t[s], tr.q[s], qd[s], np.asarray(tr.u[s], float), i))
            i += 1
    return pieces


def _segments(trajs, qds, settings: DiagnosisSettings) -> list[_fit.Segment]:
    """Fit and held-out segments: every ``holdout_every``-th segment is held out."""
    dt = trajs[0].dt
    every = settings.reading.holdout_every
    segs = [
        _fit.Segment(name, t, q, qd, u, dt, i, (k % every) == (every - 1))
        for i, (name, t, q, qd, u, k) in enumerate(_pieces(trajs, qds, settings))
    ]
    if not any(s.held_out for s in segs) and len(segs) > 1:
        segs[-1].held_out = True
    if sum(s.held_out for s in segs) == 0 or sum(not s.held_out for s in segs) < 2:
        raise DataError(
            f"too short: {len(segs)} usable segment(s) of about {settings.reading.segment_seconds} s; "
            f"need at least 3 (two to fit, one held out)"
        )
    return segs


def _test_segments(test, spec, settings, reading: dict, dt, notes) -> list[_fit.Segment]:
    """Segments of the test logs (``diagnose(test=...)``): never fitted, only scored."""
    if test is None:
        return []
    trajs = _as_trajectories(test, spec, reading, notes)
    if abs(trajs[0].dt - dt) > 1e-3 * dt:
        raise DataError(f"test: sample period {trajs[0].dt:.6g} s differs from the fit data's {dt:.6g} s; expected one")
    qds = [_velocities(tr, settings) for tr in trajs]
    segs = [
        _fit.Segment(name, t, q, qd, u, dt, -1 - i, True)
        for i, (name, t, q, qd, u, _) in enumerate(_pieces(trajs, qds, settings))
    ]
    if not segs:
        raise DataError(
            f"test: too short; every test trajectory is shorter than one {settings.output_error.window} s window"
        )
    return segs


def sensor_resolution(trajs: Sequence[Trajectory], spec) -> dict[str, float]:
    """{joint: the position quantum} for joints whose logged positions only move by whole counts
    of an encoder (the smallest step; every step a multiple of it), else nothing for that joint."""
    out = {}
    for j, name in enumerate(spec.joint_names):
        steps = np.abs(np.concatenate([np.diff(tr.q[:, j]) for tr in trajs]))
        steps = steps[steps > 1e-12]
        if steps.size == 0:
            continue
        quantum = float(steps.min())
        if np.allclose(steps / quantum, np.round(steps / quantum), atol=1e-6):
            out[name] = quantum
    return out


def prepare(data, spec, settings, reading: dict, notes: list[str]):
    """The logs read, checked and their velocities estimated: (trajectories, velocities, the
    settings resolved for their system and sample period)."""
    trajs = _as_trajectories(data, spec, reading, notes)
    settings = settings.resolved(spec.name, trajs[0].dt)
    try:
        _check_data(trajs, spec, settings)
    except DataError as err:  # what reading did to the logs may be why
        raise DataError("; ".join([str(err), *notes])) from None
    qds = [_velocities(tr, settings) for tr in trajs]
    return trajs, qds, settings
