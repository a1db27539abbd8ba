"""Measured (or generated) trajectory data: one loader and one writer for every file format.

The format (docs/conventions.md): long form, one row per sample, columns
``traj, t, <joints>, u`` — ``traj,t,alpha,beta,u`` for the Furuta, ``traj,t,p,u`` for the N-MSD —
with optional velocity columns ``alpha_dot, beta_dot`` / ``p_dot``. CSV, NPZ (one array per
column) and MAT (one variable per column) hold the same columns; ``*.csv.gz`` is read as a
gzip-compressed CSV. Other names come in through a ``column_map`` ({canonical: name in the
file}), with per-column ``signs`` and ``offsets`` applied as ``canonical = sign · raw + offset``.
A file without a ``traj`` column is one trajectory.

Before anything uses a log, :mod:`furuta_gym.reading` reads what it says about itself (its units,
wrapping, gaps, repeated rows, missing values) and acts and says so, or stops naming the flag
that fixes it. Every check names the file and the column and says what was expected; loading
never modifies the file, and saving refuses to overwrite unless asked.
"""

from __future__ import annotations

import csv
import dataclasses
import gzip
import warnings
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.io import loadmat
from scipy.io.matlab import MatReadError

from .lagrangian import SystemSpec
from .reading import Columns, DataError, DataNote, parse_units, read_columns, time_factor
from .systems import SYSTEMS, get_spec

__all__ = [
    "Trajectory",
    "DataError",
    "DataNote",
    "LogReading",
    "load_trajectories",
    "read_log",
    "read_trajectories",
    "save_trajectories",
    "columns_for",
]

#: the column of trajectory labels (a data-format name; no relation to the L_traj loss)
LABEL_COLUMN = "traj"


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
    cols = [LABEL_COLUMN, "t", *spec.joint_names, *spec.input_names]
    if velocities:
        cols += [f"{j}_dot" for j in spec.joint_names]
    return cols


def _read_columns(path: Path) -> dict[str, np.ndarray]:
    suffix = path.suffix.lower()
    gzipped = path.name.lower().endswith(".csv.gz")
    if suffix == ".csv" or gzipped:
        return _read_csv_columns(path, gzipped)
    if suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            return {k: np.ravel(z[k]) for k in z.files}
    if suffix == ".mat":
        return _read_mat_columns(path)
    raise DataError(f"{path}: unsupported file type {suffix!r}; expected .csv, .csv.gz, .npz or .mat")


def _read_csv_columns(path: Path, gzipped: bool) -> dict[str, np.ndarray]:
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
            if name == LABEL_COLUMN:  # trajectory labels may be names
                out[name] = np.array(raw, dtype=object)
            else:
                bad = next(v for v in raw if not _is_float(v))
                raise DataError(f"{path}: column {name!r} holds {bad!r}, expected numbers") from None
    return out


def _read_mat_columns(path: Path) -> dict[str, np.ndarray]:
    try:
        m = loadmat(path, squeeze_me=True)
    except NotImplementedError:  # scipy reads MAT v4-v7.2, not the HDF5-based v7.3
        raise DataError(
            f"{path}: a MATLAB v7.3 (HDF5) file, which cannot be read here; save it with save(..., '-v7') or export CSV"
        ) from None
    except (ValueError, MatReadError) as err:
        raise DataError(f"{path}: not a readable MAT file ({err})") from None
    return {k: np.ravel(np.asarray(v)) for k, v in m.items() if not k.startswith("__")}


def _is_float(v: str) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


@dataclasses.dataclass
class LogReading:
    """What reading one log gave: its trajectories (pieces, where it was split), notes on what
    was done to it, and, read with ``strict=False``, the findings that would have stopped it."""

    trajectories: list[Trajectory]
    notes: list[str]
    problems: list[str] = dataclasses.field(default_factory=list)


def load_trajectories(
    path: str | Path,
    system: str | SystemSpec,
    *,
    column_map: Mapping[str, str] | None = None,
    signs: Mapping[str, float] | None = None,
    offsets: Mapping[str, float] | None = None,
    units: Mapping[str, str] | str | None = None,
    time_unit: str | None = None,
    require_velocities: bool = False,
    min_samples: int = 3,
    dt_tolerance: float = 1e-3,
) -> list[Trajectory]:
    """Load trajectories of ``system`` from a CSV (or gzip-compressed ``.csv.gz``) / NPZ / MAT
    file in the long format, read as :func:`read_log` reads it; what the reading did (unwrapped
    an angle, split at a gap or at missing values, dropped repeated rows) is said in one
    :class:`~furuta_gym.reading.DataNote` warning each.

    ``units``: {joint: ``"rad"``, ``"deg"`` or ``"counts:N"``} (lengths: ``"m"``, ``"cm"``,
    ``"mm"``), applied before ``signs`` and ``offsets``; ``time_unit``: ``"s"``, ``"ms"`` or
    ``"us"``. Raises :class:`DataError` naming the file and column when a column is missing or
    holds non-numbers, time is not increasing or not uniformly sampled between gaps (relative
    tolerance ``dt_tolerance``), no piece has ``min_samples``, the file belongs to the other
    system, or its steps say an angle or the time is in another unit than given.
    """
    reading = read_log(
        path,
        system,
        column_map=column_map,
        signs=signs,
        offsets=offsets,
        units=units,
        time_unit=time_unit,
        require_velocities=require_velocities,
        min_samples=min_samples,
        dt_tolerance=dt_tolerance,
    )
    for note in reading.notes:
        warnings.warn(note, DataNote, stacklevel=2)
    return reading.trajectories


def read_log(
    path: str | Path,
    system: str | SystemSpec,
    *,
    column_map: Mapping[str, str] | None = None,
    signs: Mapping[str, float] | None = None,
    offsets: Mapping[str, float] | None = None,
    units: Mapping[str, str] | str | None = None,
    time_unit: str | None = None,
    require_velocities: bool = False,
    min_samples: int = 3,
    dt_tolerance: float = 1e-3,
    strict: bool = True,
) -> LogReading:
    """:func:`load_trajectories`' reading with its notes returned (:class:`LogReading`), for a
    caller that reports them; ``strict=False`` returns the findings that would stop it
    (``furuta-gym inspect``) and reads the log as it is."""
    path = Path(path)
    spec = get_spec(system) if isinstance(system, str) else system
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such data file")
    column_map, signs, offsets = dict(column_map or {}), dict(signs or {}), dict(offsets or {})
    _check_mapping_names(path, spec, [*column_map, *signs, *offsets])
    factors, seconds = parse_units(units, spec), time_factor(time_unit)
    raw = _read_columns(path)

    def source(name: str) -> str:
        return column_map.get(name, name)

    has_vel = _check_columns_present(path, spec, raw, source, require_velocities)

    def column(name: str, scale: float = 1.0) -> np.ndarray:
        return signs.get(name, 1.0) * scale * np.asarray(raw[source(name)], dtype=float) + offsets.get(name, 0.0)

    t = column("t", seconds)
    q = np.stack([column(j, factors.get(j, 1.0)) for j in spec.joint_names], axis=1)
    u = np.stack([column(c) for c in spec.input_names], axis=1)
    qd = (
        np.stack([column(f"{j}_dot", factors.get(j, 1.0) / seconds) for j in spec.joint_names], axis=1)
        if has_vel
        else None
    )
    labels = raw[source(LABEL_COLUMN)] if source(LABEL_COLUMN) in raw else np.zeros(t.shape[0])
    groups = []
    for label in _unique_in_order(labels):
        idx = np.flatnonzero(labels == label)
        groups.append(Columns(_label_name(label), t[idx], q[idx], u[idx], None if qd is None else qd[idx], idx + 1))
    names = {c: source(c) for c in columns_for(spec, velocities=True)}
    return _read(str(path), spec, groups, names, factors, time_unit, min_samples, dt_tolerance, strict)


def read_trajectories(
    trajectories: Sequence[Trajectory],
    system: str | SystemSpec,
    *,
    units: Mapping[str, str] | str | None = None,
    time_unit: str | None = None,
    source: str = "data",
    strict: bool = True,
) -> LogReading:
    """Trajectories already in memory, read as a file is (:func:`read_log`); the given
    trajectories are left as they were."""
    spec = get_spec(system) if isinstance(system, str) else system
    factors, seconds = parse_units(units, spec), time_factor(time_unit)
    scale = np.array([factors.get(j, 1.0) for j in spec.joint_names])
    groups = []
    for tr in trajectories:
        q, u = np.asarray(tr.q, dtype=float), np.asarray(tr.u, dtype=float)
        if q.ndim != 2 or q.shape[1] != spec.n_dof:
            raise DataError(
                f"{source}: trajectory {tr.name!r}: q has shape {q.shape}, expected (T, {spec.n_dof}) "
                f"columns {list(spec.joint_names)}"
            )
        qd = None if tr.qd is None else np.asarray(tr.qd, dtype=float) * scale / seconds
        t = np.asarray(tr.t, dtype=float) * seconds
        groups.append(Columns(tr.name, t, q * scale, u.reshape(len(t), -1), qd, np.arange(1, len(t) + 1)))
    return _read(source, spec, groups, {}, factors, time_unit, 3, 1e-3, strict)


def _read(source, spec, groups, names, factors, time_unit, min_samples, dt_tolerance, strict) -> LogReading:
    pieces, notes, problems = read_columns(
        source,
        spec,
        groups,
        names=names,
        given_units=list(factors),
        time_given=time_unit is not None,
        min_samples=min_samples,
        dt_tolerance=dt_tolerance,
        strict=strict,
    )
    trajectories = [Trajectory(t=p.t, q=p.q, u=p.u, qd=p.qd, name=p.name) for p in pieces]
    return LogReading(trajectories, notes, problems)


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
            for label, row in zip(labels, table, strict=True):
                w.writerow([label, *(repr(float(v)) for v in row)])
    elif suffix == ".npz":
        arrays: dict[str, Any] = {c: table[:, i] for i, c in enumerate(cols[1:])}
        label_arr = np.array(labels)
        try:
            arrays[LABEL_COLUMN] = label_arr.astype(float)
        except ValueError:
            arrays[LABEL_COLUMN] = label_arr.astype(str)
        np.savez(path, **arrays)
    else:
        raise DataError(f"{path}: unsupported output type {suffix!r}; expected .csv or .npz")
    return path
