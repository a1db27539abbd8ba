"""Reading what a log says about itself, before anything is fitted (issue 67).

Real logs come with the angle wrapped to one turn, in degrees or in raw encoder counts, with time
in milliseconds, with dropped samples, repeated rows and runs of missing values. Read as if they
were clean, they give a diagnosis that looks right and is not. :func:`read_columns` looks at a
log's columns once, for :func:`furuta_gym.data.load_trajectories` and everything built on it,
and for each finding either acts and says so (a note) or stops with one :class:`DataError`
naming the file, the column, what it saw and the flag that fixes it:

* the encoder's quantum shows an angle's unit: steps of 2π/N are radians; steps of 360/N are
  degrees and whole numbers are raw counts, both stop (``--units alpha=deg``,
  ``--units alpha=counts:2048``); without a quantum, an angle moving faster than
  :data:`MAX_ANGLE_RATE` read as radians gets a note (degrees, or noise: nothing tells which);
* the sample period shows the time unit: one longer than :data:`MAX_SAMPLE_PERIOD` read as
  seconds stops (``--time-unit ms``);
* exact repeated rows are dropped; missing values (NaN) and gaps in time split a trajectory into
  pieces, every good sample kept; pieces too short to be a trajectory are dropped and counted;
* an angle that jumps by more than π between two samples while staying within one turn was
  wrapped: it is unwrapped.

A unit given (``units``, ``time_unit``) is the user's word: it is applied and not second-guessed.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Sequence

import numpy as np

from .lagrangian import SystemSpec

__all__ = [
    "DataError",
    "DataNote",
    "Columns",
    "TIME_UNITS",
    "MAX_SAMPLE_PERIOD",
    "MAX_ANGLE_RATE",
    "GAP_PERIODS",
    "parse_units",
    "time_factor",
    "quantum",
    "implied_unit",
    "read_columns",
]


class DataError(ValueError):
    """Bad data: says which file, which column and what was expected."""


class DataNote(UserWarning):
    """What reading a log did to it (unwrapped an angle, split at a gap, dropped repeated rows)."""


TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
#: A sample period longer than this, s, is no log of a mechanical system's dynamics: its time
#: column is in another unit (a 500 Hz log in milliseconds steps by 2).
MAX_SAMPLE_PERIOD = 0.1
#: Faster than this, rad/s (99th percentile of the sample-to-sample rate), an angle without an
#: encoder quantum is taken for degrees read as radians (a pendulum swinging at 10 rad/s reads 573).
MAX_ANGLE_RATE = 300.0
#: A time step longer than this many sample periods is a gap (samples dropped), not jitter.
GAP_PERIODS = 1.5
_LINEAR_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


@dataclasses.dataclass
class Columns:
    """One trajectory's canonical columns as read; ``rows``: the file's data row of each sample."""

    name: str
    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    qd: np.ndarray | None
    rows: np.ndarray

    def take(self, idx: np.ndarray, name: str | None = None) -> "Columns":
        qd = None if self.qd is None else self.qd[idx]
        return Columns(name or self.name, self.t[idx], self.q[idx], self.u[idx], qd, self.rows[idx])


def _unit_factor(joint: str, text: str, angular: bool) -> float:
    word = str(text).strip().lower()
    if angular and word.startswith("counts:"):
        try:
            per_turn = float(word.partition(":")[2])
        except ValueError:
            per_turn = 0.0
        if per_turn > 0:
            return 2.0 * math.pi / per_turn
    if angular and word in ("rad", "deg"):
        return 1.0 if word == "rad" else math.pi / 180.0
    if not angular and word in _LINEAR_UNITS:
        return _LINEAR_UNITS[word]
    expected = "rad, deg or counts:N (N counts per turn)" if angular else ", ".join(_LINEAR_UNITS)
    raise ValueError(f"units: {joint}={text!r}; expected {expected}")


def parse_units(units: Mapping[str, str] | str | None, spec: SystemSpec) -> dict[str, float]:
    """{joint: factor to the canonical unit} from ``{"alpha": "deg"}`` or ``"alpha=deg,beta=deg"``
    (angles: ``rad``, ``deg``, ``counts:N``; lengths: ``m``, ``cm``, ``mm``)."""
    if isinstance(units, str):
        items = [item.split("=", 1) for item in units.split(",") if item.strip()]
        if any(len(item) != 2 for item in items):
            raise ValueError(f"units: expected JOINT=UNIT[,JOINT=UNIT...], got {units!r}")
        units = {k.strip(): v.strip() for k, v in items}
    out = {}
    for joint, text in (units or {}).items():
        if joint not in spec.joint_names:
            raise ValueError(f"units: unknown joint {joint!r}; {spec.name} joints are {list(spec.joint_names)}")
        out[joint] = _unit_factor(joint, text, spec.angular[spec.joint_names.index(joint)])
    return out


def time_factor(time_unit: str | None) -> float:
    """Seconds per unit of the time column (``None``: seconds, and the period is checked)."""
    if time_unit is None:
        return 1.0
    if time_unit not in TIME_UNITS:
        raise ValueError(f"time unit: expected one of {list(TIME_UNITS)}, got {time_unit!r}")
    return TIME_UNITS[time_unit]


def quantum(values: np.ndarray) -> float | None:
    """The smallest step of ``values`` if every step is a whole multiple of it (an encoder's
    count), else None. Runs of missing values are skipped."""
    steps = np.abs(np.diff(np.asarray(values, dtype=float)))
    steps = steps[np.isfinite(steps) & (steps > 1e-12)]
    if steps.size < 10:
        return None
    step = float(steps.min())
    ratio = steps / step
    # a file printed to ten digits keeps whole multiples within 1e-7 of a count per count
    return step if np.all(np.abs(ratio - np.round(ratio)) < 1e-3) else None


def _whole(n: float) -> bool:
    return n >= 8 and abs(n - round(n)) < 1e-2


def implied_unit(step: float | None, values: np.ndarray) -> tuple[str | None, int | None]:
    """The unit an angle's quantum implies, with counts per turn: ``("rad", 2048)``,
    ``("deg", 2048)``, ``("counts", None)``, or ``(None, None)`` when it implies none."""
    if step is None:
        return None, None
    finite = values[np.isfinite(values)]
    if step >= 1 - 1e-9 and np.allclose(finite, np.round(finite), atol=1e-9):
        return "counts", None
    if abs(math.log10(step) - round(math.log10(step))) < 1e-6:
        return None, None  # a power of ten: the digits the log was printed with, not an encoder
    per_rad, per_deg = 2.0 * math.pi / step, 360.0 / step
    if _whole(per_rad) and (not _whole(per_deg) or round(per_rad) % 4 == 0):
        return "rad", int(round(per_rad))
    if _whole(per_deg):
        return "deg", int(round(per_deg))
    return None, None


def _col(names: Mapping[str, str], canonical: str) -> str:
    file_name = names.get(canonical, canonical)
    return repr(file_name) if file_name == canonical else f"{file_name!r} ({canonical})"


def _drop_repeats(source: str, g: Columns, notes: list[str]) -> Columns:
    """``g`` without rows repeated exactly (time and every value), kept in order."""
    table = np.column_stack([g.t, g.q, g.u] + ([g.qd] if g.qd is not None else []))
    table = np.ascontiguousarray(table)
    rows = table.view(np.dtype((np.void, table.dtype.itemsize * table.shape[1]))).ravel()
    _, first = np.unique(rows, return_index=True)
    keep = np.sort(first)
    if keep.size == len(g.t):
        return g
    dropped = np.setdiff1d(np.arange(len(g.t)), keep)
    notes.append(
        f"{source}: trajectory {g.name!r}: {dropped.size} exact repeated row(s) dropped "
        f"(first at data row {g.rows[dropped[0]]})"
    )
    return g.take(keep)


def _sample_period(groups: Sequence[Columns]) -> float:
    steps = np.concatenate([np.diff(g.t) for g in groups])
    steps = steps[np.isfinite(steps) & (steps > 0)]
    return float(np.median(steps)) if steps.size else float("nan")


def _time_problem(names: Mapping[str, str], dt: float) -> tuple[str, str, str] | None:
    """(what was seen, flag, keyword) when the period read as seconds is no mechanical log's."""
    if not dt > MAX_SAMPLE_PERIOD:
        return None
    unit = next((u for u, f in TIME_UNITS.items() if f < 1 and dt * f <= MAX_SAMPLE_PERIOD), "ms")
    seen = (
        f"column {_col(names, 't')} steps by {dt:.6g} per sample: read as seconds that is a "
        f"{1 / dt:.3g} Hz log, too slow for a mechanical system's dynamics, and in {unit} a "
        f"{1 / (dt * TIME_UNITS[unit]):.4g} Hz one"
    )
    return seen, f"--time-unit {unit}", f"time_unit={unit!r}"


def _unit_problems(spec: SystemSpec, names, groups: Sequence[Columns], given):
    """(what was seen, flag item, keyword item) per angle whose steps say it is not in radians."""
    out = []
    for j, joint in enumerate(spec.joint_names):
        if not spec.angular[j] or joint in given:
            continue
        values = np.concatenate([g.q[:, j] for g in groups])
        step = quantum(np.concatenate([np.append(g.q[:, j], np.nan) for g in groups]))
        unit, per_turn = implied_unit(step, values)
        if unit == "deg":
            seen = f"column {_col(names, joint)} moves in steps of {step:.6g} = 360/{per_turn}: degrees"
            out.append((seen, f"{joint}=deg", f"{joint!r}: 'deg'"))
        elif unit == "counts":
            seen = f"column {_col(names, joint)} holds whole numbers moving in steps of {step:g}: raw encoder counts"
            out.append((seen, f"{joint}=counts:2048", f"{joint!r}: 'counts:2048'"))
    return out


def _rate_notes(source: str, spec: SystemSpec, names, groups: Sequence[Columns], given, dt: float) -> list[str]:
    """A note per angle whose steps imply no unit that moves faster than radians would: degrees
    read as radians, or noise (a note, not a stop: nothing in such a column says which)."""
    out = []
    for j, joint in enumerate(spec.joint_names):
        column = np.concatenate([np.append(g.q[:, j], np.nan) for g in groups])
        if not spec.angular[j] or joint in given or implied_unit(quantum(column), column)[0] is not None:
            continue
        rates = np.abs(np.diff(column)) / dt
        rates = rates[np.isfinite(rates) & (rates * dt <= math.pi)]
        fast = float(np.percentile(rates, 99)) if rates.size else 0.0
        if fast > MAX_ANGLE_RATE:
            out.append(
                f"{source}: column {_col(names, joint)} moves at {fast:.4g} rad/s (99th percentile), faster "
                f"than {MAX_ANGLE_RATE:g}, and has no encoder quantum to tell its unit: if it is in degrees, "
                f"pass --units {joint}=deg"
            )
    return out


def _one_error(source: str, problems) -> DataError:
    flags, keywords = [], []
    unit_items = [p for p in problems if "=" in p[1] and not p[1].startswith("--")]
    if unit_items:
        flags.append("--units " + ",".join(p[1] for p in unit_items))
        keywords.append("units={" + ", ".join(p[2] for p in unit_items) + "}")
    for p in problems:
        if p[1].startswith("--"):
            flags.append(p[1])
            keywords.append(p[2])
    counts = "2048: your encoder's counts per turn; " if "counts:" in " ".join(flags) else ""
    return DataError(
        f"{source}: {'; '.join(p[0] for p in problems)}; pass {' '.join(flags)} "
        f"({counts}{', '.join(keywords)} in Python)"
    )


def _finite_rows(g: Columns) -> np.ndarray:
    ok = np.isfinite(g.t) & np.all(np.isfinite(g.q), axis=1) & np.all(np.isfinite(g.u), axis=1)
    if g.qd is not None:
        ok &= np.all(np.isfinite(g.qd), axis=1)
    return ok


def _check_steps(source: str, names, g: Columns, idx: np.ndarray, dt: float, tol: float) -> np.ndarray:
    """The time steps between ``g``'s kept rows ``idx``, checked: increasing, and uniform up to
    ``tol`` except at gaps (steps over :data:`GAP_PERIODS` periods)."""
    steps = np.diff(g.t[idx])
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise DataError(
            f"{source}: column {_col(names, 't')} is not strictly increasing in trajectory {g.name!r} "
            f"(data row {g.rows[idx[k + 1]]}: t = {g.t[idx[k + 1]]:.6g} after {g.t[idx[k]]:.6g}, the "
            "rows differing); expected increasing time (rows repeated exactly are dropped)"
        )
    adjacent = np.diff(idx) == 1
    irregular = adjacent & (steps <= GAP_PERIODS * dt) & (np.abs(steps - dt) > tol * dt + 1e-12)
    if irregular.any():
        k = int(np.flatnonzero(irregular)[np.argmax(np.abs(steps[irregular] - dt))])
        raise DataError(
            f"{source}: column {_col(names, 't')} is not uniformly sampled in trajectory {g.name!r} "
            f"(step {steps[k]:.6g} s vs median {dt:.6g} s near data row {g.rows[idx[k + 1]]}); expected "
            f"a constant sample period — resample first (steps over {GAP_PERIODS:g} periods are gaps: "
            "the log is split there)"
        )
    return steps


def _split(source: str, spec: SystemSpec, names, g: Columns, dt: float, tol: float, notes) -> list[Columns]:
    """``g`` cut at runs of missing values and at gaps in time, every finite row kept."""
    ok = _finite_rows(g)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        raise DataError(f"{source}: trajectory {g.name!r} has no row without a missing value; expected numbers")
    steps = _check_steps(source, names, g, idx, dt, tol)
    adjacent = np.diff(idx) == 1
    gaps = adjacent & (steps > GAP_PERIODS * dt)
    parts = np.split(idx, np.flatnonzero(gaps | ~adjacent) + 1)
    if len(parts) == 1 and idx.size == len(g.t):
        return [g]
    why = []
    if idx.size < len(g.t):
        columns = ["t", *spec.joint_names, *spec.input_names] + (
            [f"{j}_dot" for j in spec.joint_names] * (g.qd is not None)
        )
        arrays = [g.t[:, None], g.q, g.u] + ([g.qd] if g.qd is not None else [])
        bad = ~np.isfinite(np.concatenate(arrays, axis=1))
        named = ", ".join(f"{_col(names, c)} {int(n)}" for c, n in zip(columns, bad.sum(axis=0), strict=True) if n)
        runs = int(np.sum(np.diff(np.concatenate([[0], (~ok).astype(int), [0]])) == 1))
        first = g.rows[np.flatnonzero(~ok)[0]]
        why.append(
            f"{len(g.t) - idx.size} row(s) with missing values (NaN/inf: {named}) in {runs} run(s) from data row {first}"
        )
    if gaps.any():
        missing = int(np.sum(np.round(steps[gaps] / dt) - 1))
        first = g.t[idx[np.flatnonzero(gaps)[0]]]
        why.append(
            f"{int(gaps.sum())} gap(s) in column {_col(names, 't')} (about {missing} samples missing, first after t = {first:.6g})"
        )
    notes.append(
        f"{source}: trajectory {g.name!r} split into {len(parts)} pieces at {' and '.join(why)}; every other sample kept"
    )
    return [g.take(p, f"{g.name}/{k + 1}") for k, p in enumerate(parts)]


def _unwrap(source: str, spec: SystemSpec, names, pieces: list[Columns], notes) -> list[Columns]:
    """Smooth angles that jump by more than π between samples while staying within one turn,
    unwrapped (each piece on its own); one that jumps so and spans more is an error. An angle
    whose ordinary steps are not small (noise, test data) says nothing either way."""
    for j, joint in enumerate(spec.joint_names):
        if not spec.angular[j]:
            continue
        steps = np.abs(np.concatenate([np.diff(p.q[:, j]) for p in pieces]))
        jumps = int(np.sum(steps > math.pi))
        if not jumps or np.percentile(steps[steps <= math.pi], 99) >= math.pi / 4:
            continue
        values = np.concatenate([p.q[:, j] for p in pieces])
        low, high = float(values.min()), float(values.max())
        if high - low > 2.0 * math.pi * (1 + 1e-6):
            raise DataError(
                f"{source}: column {_col(names, joint)} jumps by more than π between samples {jumps} time(s) "
                f"and spans {high - low:.4g} rad, more than one turn: not an angle wrapped to one turn; "
                "expected radians (check --column-map and --units)"
            )
        for p in pieces:
            p.q = p.q.copy()  # the caller's arrays stay as they were
            p.q[:, j] = np.unwrap(p.q[:, j])
        notes.append(
            f"{source}: column {_col(names, joint)} was wrapped to one turn ([{low:.3g}, {high:.3g}] rad, "
            f"{jumps} jumps of 2π): unwrapped"
        )
    return pieces


def read_columns(
    source: str,
    spec: SystemSpec,
    groups: Sequence[Columns],
    *,
    names: Mapping[str, str] | None = None,
    given_units: Sequence[str] = (),
    time_given: bool = False,
    min_samples: int = 3,
    dt_tolerance: float = 1e-3,
    strict: bool = True,
) -> tuple[list[Columns], list[str], list[str]]:
    """Read a log's trajectories ``groups`` (canonical columns, given units applied): returns
    the pieces to use, notes on what was done, and (``strict=False``) the findings that would
    have stopped it, which ``strict`` raises as one :class:`DataError`. ``names``: {canonical:
    the file's column}, for messages; ``given_units``: joints whose unit the user gave."""
    names = dict(names or {})
    notes: list[str] = []
    groups = [_drop_repeats(source, g, notes) for g in groups]
    dt = _sample_period(groups)
    found = [] if time_given else [p for p in [_time_problem(names, dt)] if p is not None]
    found += _unit_problems(spec, names, groups, set(given_units))
    if found and strict:
        raise _one_error(source, found)
    notes += _rate_notes(source, spec, names, groups, set(given_units), dt)
    pieces = [p for g in groups for p in _split(source, spec, names, g, dt, dt_tolerance, notes)]
    short = [p for p in pieces if len(p.t) < min_samples]
    if len(short) == len(pieces):
        p = max(pieces, key=lambda p: len(p.t))
        done = "".join(f"; {n[len(source) + 2 :]}" for n in notes)  # why it is this short
        raise DataError(
            f"{source}: trajectory {p.name!r} has {len(p.t)} sample(s); expected at least {min_samples}{done}"
        )
    if short:
        notes.append(
            f"{source}: {len(short)} piece(s) shorter than {min_samples} samples dropped "
            f"({sum(len(p.t) for p in short)} samples)"
        )
    pieces = _unwrap(source, spec, names, [p for p in pieces if len(p.t) >= min_samples], notes)
    return pieces, notes, [str(_one_error(source, found))] if found else []
