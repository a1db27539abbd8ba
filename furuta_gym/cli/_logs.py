"""Reading measured logs on the command line, one way for ``diagnose``, ``train`` and ``evaluate``.

A DATA token is a file (CSV, ``.csv.gz``, NPZ, MAT; long form) read with a column map, signs and
offsets, or ``qube[:RUNS]`` for the real QUBE-Servo runs shipped with the package
(:mod:`furuta_gym.datasets`). ``train`` and ``evaluate`` then estimate absent velocities, drop the
start and cut elementary trajectories (:func:`furuta_gym.measured.prepare_log`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable, NamedTuple

__all__ = [
    "pairs",
    "qube_runs",
    "read_logs",
    "load_logs",
    "skip_start",
    "add_reading_arguments",
    "add_log_arguments",
    "prepared_logs",
    "PreparedLogs",
    "QUBE_SKIP",
]

#: Seconds dropped at the start of a vendored QUBE run unless --skip says otherwise: the balancing
#: controller's start transient (furuta_gym.datasets.load_qube_closed_loop drops the same).
QUBE_SKIP = 0.5


def pairs(text: str | None, what: str, convert: Callable[[str], Any] = str) -> dict:
    out = {}
    if not text:
        return out
    for item in text.split(","):
        if "=" not in item:
            raise ValueError(f"{what}: expected NAME=VALUE[,NAME=VALUE...], got {item!r}")
        k, v = item.split("=", 1)
        try:
            out[k.strip()] = convert(v.strip())
        except ValueError:
            raise ValueError(f"{what}: {k.strip()}={v.strip()!r} is not a number") from None
    return out


def qube_runs(token: str) -> list[int] | None:
    """Run numbers of a ``qube[:RUNS]`` token: ``qube`` (all), ``qube:1-5``, ``qube:2,7,9-11``."""
    spec = token.partition(":")[2]
    if not spec:
        return None
    runs = []
    for part in spec.split(","):
        lo, _, hi = part.partition("-")
        if not lo.isdigit() or (hi and not hi.isdigit()):
            raise ValueError(f"{token!r}: expected qube, qube:N, qube:N-M or qube:N,M,... (run numbers 1..15)")
        runs += list(range(int(lo), int(hi or lo) + 1))
    return runs


def read_logs(
    paths, system: str, column_map=None, sign=None, offset=None, units=None, time_unit=None, strict: bool = True
) -> list[tuple[str, Any]]:
    """``(source, reading)`` per log of ``paths``, nothing skipped, each read as
    :func:`furuta_gym.data.read_log` reads it (a :class:`~furuta_gym.data.LogReading`: its
    trajectories, notes on what the reading did, and with ``strict=False`` what would have
    stopped it). ``source`` names the log for error messages (a vendored run: its token and
    file). With several DATA tokens the trajectories are named ``<file stem>:<name>``."""
    from ..data import LogReading, read_log
    from ..datasets import QUBE_CLOSED_LOOP_SYSTEM, load_qube_closed_loop, qube_closed_loop_files

    out = []
    for path in paths:
        if path == "qube" or path.startswith("qube:"):
            if system != QUBE_CLOSED_LOOP_SYSTEM.name:
                raise ValueError(
                    f"{path!r}: the shipped QUBE-Servo runs are {QUBE_CLOSED_LOOP_SYSTEM.name} data; "
                    f"got --system {system}"
                )
            if units or time_unit:
                raise ValueError(
                    f"{path!r}: the shipped runs are read in rad and s; --units and --time-unit are for files"
                )
            runs = qube_runs(path)
            files = qube_closed_loop_files(runs)  # checks the run numbers
            for run, file in zip(runs or range(1, len(files) + 1), files, strict=True):
                out.append(
                    (f"{path} (run {run}: {file})", LogReading(load_qube_closed_loop([run], skip_seconds=0.0), []))
                )
            continue
        read = read_log(
            path,
            system,
            column_map=pairs(column_map, "--column-map"),
            signs=pairs(sign, "--sign", float),
            offsets=pairs(offset, "--offset", float),
            units=units,
            time_unit=time_unit,
            strict=strict,
        )
        if len(paths) > 1:
            for tr in read.trajectories:
                tr.name = f"{Path(path).stem}:{tr.name}"
        out.append((str(path), read))
    return out


def _read(paths, args) -> list[tuple[str, Any]]:
    return read_logs(
        paths,
        args.system,
        args.column_map,
        args.sign,
        args.offset,
        getattr(args, "units", None),
        getattr(args, "time_unit", None),
    )


def skip_start(trajs: list, seconds: float) -> list:
    """``trajs`` without the first ``seconds`` of each trajectory of the log; a piece of a log
    split by its reading (named ``<name>/<k>``) counts from its trajectory's start."""
    from ..data import Trajectory

    if not seconds > 0:
        return trajs
    out, starts = [], _starts(trajs)
    for tr in trajs:
        m = tr.t >= starts[_trajectory_of(tr)] + seconds - 1e-9
        if m.any():
            out.append(
                Trajectory(t=tr.t[m], q=tr.q[m], u=tr.u[m], qd=None if tr.qd is None else tr.qd[m], name=tr.name)
            )
    return out


def load_logs(paths, args) -> tuple[list, list[str]]:
    """Trajectories of ``paths`` with the column map, signs, offsets and units, start skipped
    (``furuta-gym diagnose``'s reading: velocities stay as logged), and notes on what the
    reading did."""
    read = [r for _, r in _read(paths, args)]
    return skip_start([tr for r in read for tr in r.trajectories], args.skip), [n for r in read for n in r.notes]


def add_reading_arguments(parser: argparse.ArgumentParser) -> None:
    """How a log's columns are read: names, signs, offsets, units (every command reading logs)."""
    parser.add_argument(
        "--column-map",
        metavar="CANON=FILECOL,...",
        help="columns under other names, e.g. alpha=theta,beta=alpha,u=plant_input",
    )
    parser.add_argument("--sign", metavar="CANON=±1,...", help="per-column sign, e.g. beta=-1")
    parser.add_argument("--offset", metavar="CANON=VALUE,...", help="per-column offset, e.g. beta=3.14159")
    parser.add_argument(
        "--units",
        metavar="JOINT=UNIT,...",
        help="the angles' units in the file when not radians: deg, or counts:N (N counts per turn), "
        "e.g. alpha=deg,beta=deg or alpha=counts:2048; applied before --sign and --offset",
    )
    parser.add_argument("--time-unit", choices=["s", "ms", "us"], help="the time column's unit (default s, checked)")


def add_log_arguments(parser: argparse.ArgumentParser, split_default: float | None, split_help: str) -> None:
    """The options of measured logs shared by ``train`` and ``evaluate``."""
    add_reading_arguments(parser)
    parser.add_argument(
        "--skip",
        type=float,
        metavar="SECONDS",
        help="drop this many seconds at the start of every log (start transients; "
        f"default {QUBE_SKIP} s for qube:RUNS, the controller catching the pendulum, 0 for files)",
    )
    parser.add_argument(
        "--velocity",
        choices=["zero_phase", "derivative_filter"],
        default="zero_phase",
        help="velocity estimate when a log has none: zero-phase (offline, no lag; default) or the "
        "paper's causal derivative filter (ω0 = 100 rad/s, ξ = 0.8)",
    )
    parser.add_argument("--cutoff", type=float, help="zero-phase velocity cutoff in Hz (default min(25, 0.08·fs))")
    parser.add_argument("--split", type=float, default=split_default, metavar="SECONDS", help=split_help)


#: how :func:`prepared_logs`' notes begin when it estimated velocities (the logs were measured)
ESTIMATED_NOTE = "velocities estimated"


class PreparedLogs(NamedTuple):
    """What :func:`prepared_logs` gives: the trajectories, notes on what reading and preparing
    them did, and whether they are measured logs (some carried no velocities, which were
    estimated), not generated data."""

    trajectories: list
    notes: list[str]
    measured: bool


def prepared_logs(paths, args, *, split: float | str | None = "measured", min_seconds: float = 0.0) -> PreparedLogs:
    """Training / test trajectories of ``paths`` (:func:`furuta_gym.measured.prepare_log` per
    log; ``args`` carries the :func:`add_log_arguments` options and ``system``) and notes on what
    was estimated and what reading the logs did. ``split``: seconds per elementary trajectory,
    ``None`` whole logs, or ``"measured"``: ``--split`` if given, else the paper's length for
    logs without velocities (measured: :data:`furuta_gym.measured.SPLIT_SECONDS`) and whole
    trajectories for logs that carry them (generated data, already cut as the paper's appendix
    cuts them). A piece of a log its reading split that is too short to serve is left out and
    counted in the notes."""
    from ..measured import SPLIT_SECONDS, prepare_log

    out, estimated, notes, short = [], [], [], 0
    for source, read in _read(paths, args):
        trajs = read.trajectories
        notes += read.notes
        is_qube = source.startswith("qube")
        skip = args.skip if args.skip is not None else (QUBE_SKIP if is_qube else 0.0)
        starts = _starts(trajs)
        for tr in trajs:
            seconds: Any = split
            if split == "measured":
                seconds = (
                    args.split if args.split is not None else (SPLIT_SECONDS[args.system] if tr.qd is None else None)
                )
            # a later piece of a split log starts past the skipped start
            piece_skip = max(0.0, starts[_trajectory_of(tr)] + skip - float(tr.t[0]))
            if "/" in tr.name and len(tr) * tr.dt - piece_skip < max(min_seconds, seconds or 0.0) - 1e-9:
                short += 1
                continue
            if tr.qd is None:
                estimated.append(tr.name)
            out += prepare_log(
                tr,
                source,
                velocity=args.velocity,
                cutoff_hz=args.cutoff,
                skip=piece_skip,
                split=seconds or None,
                min_seconds=min_seconds,
            )
    if short:
        notes.append(f"{short} piece(s) of split logs shorter than one trajectory after the skipped start: left out")
    if estimated:
        notes.insert(0, f"{ESTIMATED_NOTE} ({args.velocity}) for {len(estimated)} log(s)")
    return PreparedLogs(out, notes, measured=bool(estimated))


def _starts(trajs: list) -> dict[str, float]:
    """{trajectory: its first time}, over the pieces a log's reading split it into."""
    out: dict[str, float] = {}
    for tr in trajs:
        out[_trajectory_of(tr)] = min(out.get(_trajectory_of(tr), float("inf")), float(tr.t[0]))
    return out


def _trajectory_of(tr) -> str:
    """The trajectory a piece was cut from (pieces of a split log are named ``<name>/<k>``)."""
    return tr.name.rpartition("/")[0] or tr.name
