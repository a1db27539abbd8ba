"""Measured (or generated) trajectory data: one loader and one writer for every file format.

The format (DEVELOPERS.md "Conventions"): long form, one row per sample, columns
``traj, t, <joints>, u`` — ``traj,t,alpha,beta,u`` for the Furuta, ``traj,t,p,u`` for the N-MSD —
with optional velocity columns ``alpha_dot, beta_dot`` / ``p_dot``. CSV, NPZ (one array per
column) and MAT (one variable per column) hold the same columns; ``*.csv.gz`` is read as a
gzip-compressed CSV. Other names come in through a ``column_map`` ({canonical: name in the
file}), with per-column ``signs`` and ``offsets`` applied as ``canonical = sign · raw + offset``.
A file without a ``traj`` column is one trajectory.

Every check names the file and the column and says what was expected; loading never modifies
the file, and saving refuses to overwrite unless asked.
"""

from __future__ import annotations

import csv
import dataclasses
import gzip
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.io import loadmat
from scipy.io.matlab import MatReadError

from .lagrangian import SystemSpec
from .systems import SYSTEMS, get_spec

__all__ = ["Trajectory", "DataError", "load_trajectories", "save_trajectories", "columns_for"]


class DataError(ValueError):
    """Bad data: says which file, which column and what was expected."""


@dataclasses.dataclass
class Trajectory:
    """One uniformly sampled trajectory. Arrays are float64 numpy.

    ``t`` (T,), ``q`` (T, n_dof), ``u`` (T, n_inputs), ``qd`` (T, n_dof) or None when velocities
    were not measured (estimate them with :mod:`furuta_gym.signals`).
    """

    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    qd: np.ndarray | None = None
    name: str = "0"

    @property
    def dt(self) -> float:
        """Sample period (median of the time steps), s."""
        return float(np.median(np.diff(self.t)))

    @property
    def x(self) -> np.ndarray:
        """State (q, q̇) stacked, (T, 2 n_dof); requires velocities."""
        if self.qd is None:
            raise DataError(f"trajectory {self.name!r} has no velocities; estimate them first")
        return np.concatenate([self.q, self.qd], axis=1)

    def __len__(self) -> int:
        return int(self.t.shape[0])


def columns_for(spec: SystemSpec, velocities: bool = True) -> list[str]:
    """Canonical column names of ``spec``'s data format, in file order."""
    cols = ["traj", "t", *spec.joint_names, *spec.input_names]
    if velocities:
        cols += [f"{j}_dot" for j in spec.joint_names]
    return cols


def _read_columns(path: Path) -> dict[str, np.ndarray]:
    suffix = path.suffix.lower()
    gzipped = path.name.lower().endswith(".csv.gz")
    if suffix == ".csv" or gzipped:
        # ``*.csv.gz`` is a gzip-compressed CSV, parsed exactly like ``*.csv``.
        try:
            with gzip.open(path, "rt", newline="") if gzipped else path.open(newline="") as fh:
                reader = csv.reader(fh)
                try:
                    header = [h.strip() for h in next(reader)]
                except StopIteration:
                    raise DataError(f"{path}: the file is empty; expected a header row") from None
                rows = [r for r in reader if r and any(c.strip() for c in r)]
        except (gzip.BadGzipFile, EOFError) as err:
            raise DataError(f"{path}: not a readable gzip file ({err}); expected a gzip-compressed CSV") from None
        if not rows:
            raise DataError(f"{path}: no data rows after the header")
        out: dict[str, np.ndarray] = {}
        for i, name in enumerate(header):
            raw = [r[i].strip() if i < len(r) else "" for r in rows]
            try:
                out[name] = np.array([float(v) if v != "" else np.nan for v in raw])
            except ValueError:
                if name == "traj":
                    out[name] = np.array(raw, dtype=object)
                else:
                    bad = next(v for v in raw if not _is_float(v))
                    raise DataError(f"{path}: column {name!r} holds {bad!r}, expected numbers") from None
        return out
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            return {k: np.ravel(z[k]) for k in z.files}
    if suffix == ".mat":
        try:
            m = loadmat(path, squeeze_me=True)
        except NotImplementedError:  # scipy reads MAT v4-v7.2, not the HDF5-based v7.3
            raise DataError(
                f"{path}: a MATLAB v7.3 (HDF5) file, which cannot be read here; save it "
                "with save(..., '-v7') or export CSV"
            ) from None
        except (ValueError, MatReadError) as err:
            raise DataError(f"{path}: not a readable MAT file ({err})") from None
        return {k: np.ravel(np.asarray(v)) for k, v in m.items() if not k.startswith("__")}
    raise DataError(f"{path}: unsupported file type {suffix!r}; expected .csv, .csv.gz, .npz or .mat")


def _is_float(v: str) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


def load_trajectories(
    path: str | Path,
    system: str | SystemSpec,
    *,
    column_map: Mapping[str, str] | None = None,
    signs: Mapping[str, float] | None = None,
    offsets: Mapping[str, float] | None = None,
    require_velocities: bool = False,
    min_samples: int = 3,
    dt_tolerance: float = 1e-3,
) -> list[Trajectory]:
    """Load trajectories of ``system`` from a CSV (or gzip-compressed ``.csv.gz``) / NPZ / MAT
    file in the long format.

    Raises :class:`DataError` naming the file and column when a column is missing, holds NaN or
    non-numbers, time is not strictly increasing or not uniformly sampled (relative tolerance
    ``dt_tolerance``), a trajectory is shorter than ``min_samples``, or the file belongs to the
    other system.
    """
    path = Path(path)
    spec = get_spec(system) if isinstance(system, str) else system
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such data file")
    column_map, signs, offsets = dict(column_map or {}), dict(signs or {}), dict(offsets or {})
    _check_mapping_names(path, spec, [*column_map, *signs, *offsets])
    raw = _read_columns(path)

    def source(name: str) -> str:
        return column_map.get(name, name)

    has_vel = _check_columns_present(path, spec, raw, source, require_velocities)

    def column(name: str) -> np.ndarray:
        return signs.get(name, 1.0) * _finite_column(path, raw, source(name)) + offsets.get(name, 0.0)

    t = column("t")
    q = np.stack([column(j) for j in spec.joint_names], axis=1)
    u = np.stack([column(c) for c in spec.input_names], axis=1)
    qd = np.stack([column(f"{j}_dot") for j in spec.joint_names], axis=1) if has_vel else None
    labels = raw[source("traj")] if source("traj") in raw else np.zeros(t.shape[0])
    trajectories = []
    for label in _unique_in_order(labels):
        idx = np.flatnonzero(labels == label)
        name = _label_name(label)
        _check_time(path, source("t"), name, t[idx], idx, min_samples, dt_tolerance)
        trajectories.append(Trajectory(t=t[idx], q=q[idx], u=u[idx], qd=None if qd is None else qd[idx], name=name))
    return trajectories


def _check_mapping_names(path: Path, spec: SystemSpec, keys) -> None:
    canonical = columns_for(spec, velocities=True)
    for key in keys:
        if key not in canonical:
            raise DataError(
                f"{path}: column map / sign / offset names unknown column {key!r}; {spec.name} columns are {canonical}"
            )


def _check_columns_present(path: Path, spec: SystemSpec, raw, source, require_velocities: bool) -> bool:
    """Raise unless the system's columns are there (hinting at the other system's file); True
    if the velocity columns are there too."""
    required = ["t", *spec.joint_names, *spec.input_names]
    missing = [c for c in required if source(c) not in raw]
    if missing:
        other = [s.name for s in SYSTEMS.values() if s.name != spec.name and all(j in raw for j in s.joint_names)]
        hint = f"; it looks like a {other[0]} file" if other else ""
        mapped = {c: source(c) for c in missing if source(c) != c}
        raise DataError(
            f"{path}: missing column(s) {[source(c) for c in missing]}"
            + (f" (mapped from {mapped})" if mapped else "")
            + f"; a {spec.name} file needs columns {['traj (optional)', *required]}, "
            f"found {sorted(raw)}{hint}"
        )
    vel_names = [f"{j}_dot" for j in spec.joint_names]
    has_vel = all(source(c) in raw for c in vel_names)
    if require_velocities and not has_vel:
        raise DataError(f"{path}: velocity columns {[source(c) for c in vel_names]} are required here")
    return has_vel


def _finite_column(path: Path, raw, name: str) -> np.ndarray:
    values = np.asarray(raw[name], dtype=float)
    bad = ~np.isfinite(values)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise DataError(
            f"{path}: column {name!r} has {bad.sum()} non-finite value(s) "
            f"(NaN/inf), first at data row {rows[0] + 1}; expected finite numbers"
        )
    return values


def _check_time(
    path: Path, t_name: str, name: str, tt: np.ndarray, idx: np.ndarray, min_samples: int, dt_tolerance: float
) -> None:
    """One trajectory's time column: enough samples, strictly increasing, uniformly sampled."""
    if idx.size < min_samples:
        raise DataError(f"{path}: trajectory {name!r} has {idx.size} sample(s); expected at least {min_samples}")
    steps = np.diff(tt)
    if np.any(steps <= 0):
        row = idx[1:][steps <= 0][0]
        raise DataError(
            f"{path}: column {t_name!r} is not strictly increasing in trajectory "
            f"{name!r} (data row {row + 1}); expected increasing time"
        )
    dt = np.median(steps)
    if np.max(np.abs(steps - dt)) > dt_tolerance * dt + 1e-12:
        row = idx[1:][np.argmax(np.abs(steps - dt))]
        raise DataError(
            f"{path}: column {t_name!r} is not uniformly sampled in trajectory "
            f"{name!r} (step {steps.max():.6g} s vs median {dt:.6g} s near data row "
            f"{row + 1}); expected a constant sample period — resample first"
        )


def _unique_in_order(labels: np.ndarray) -> list:
    seen: dict = {}
    for v in labels.tolist():
        seen.setdefault(v, None)
    return list(seen)


def _label_name(label) -> str:
    if isinstance(label, float) and label.is_integer():
        return str(int(label))
    return str(label)


def save_trajectories(
    path: str | Path,
    trajectories: Sequence[Trajectory],
    system: str | SystemSpec,
    *,
    overwrite: bool = False,
) -> Path:
    """Write trajectories in the long format (CSV, or NPZ by suffix). Refuses to overwrite an
    existing file unless ``overwrite=True``."""
    path = Path(path)
    spec = get_spec(system) if isinstance(system, str) else system
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; refusing to overwrite (pass overwrite=True)")
    with_vel = all(tr.qd is not None for tr in trajectories)
    cols = columns_for(spec, velocities=with_vel)
    blocks = []
    labels = []
    for k, tr in enumerate(trajectories):
        parts = [tr.t[:, None], tr.q, tr.u]
        if with_vel:
            parts.append(np.asarray(tr.qd))
        blocks.append(np.concatenate(parts, axis=1))
        labels += [tr.name if tr.name is not None else str(k)] * len(tr)
    table = np.concatenate(blocks, axis=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            for label, row in zip(labels, table):
                w.writerow([label, *(repr(float(v)) for v in row)])
    elif suffix == ".npz":
        arrays: dict[str, Any] = {c: table[:, i] for i, c in enumerate(cols[1:])}
        label_arr = np.array(labels)
        try:
            arrays["traj"] = label_arr.astype(float)
        except ValueError:
            arrays["traj"] = label_arr.astype(str)
        np.savez(path, **arrays)
    else:
        raise DataError(f"{path}: unsupported output type {suffix!r}; expected .csv or .npz")
    return path
