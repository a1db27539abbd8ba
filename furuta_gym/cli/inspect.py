"""``furuta-gym inspect LOG... --system {furuta,nmsd}``: what a log holds, before diagnosing or training.

Each log is read as ``diagnose``, ``train`` and ``evaluate`` read it (same options), leniently:
what would stop them is listed, not raised. Per log and trajectory: duration, sample rate, gaps,
per joint the quantum and the unit it implies, range, share of repeated counts, velocity range
and reversals, the input's range and share at its limits; then what can and cannot be
identified from it (``furuta_gym.inspection``).
"""

from __future__ import annotations

import argparse

from ..systems import SYSTEMS
from ._logs import add_reading_arguments

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "data",
        metavar="LOG",
        nargs="+",
        help="logs as diagnose reads them: CSV (.csv.gz too), NPZ, MAT, or qube[:RUNS] for the shipped runs",
    )
    parser.add_argument("--system", required=True, choices=sorted(SYSTEMS))
    add_reading_arguments(parser)
    parser.add_argument("--json", metavar="OUT", help="write the inspection as JSON here")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --json file")


def run(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from ..inspection import describe_log, format_inspection, identifiability
    from ..systems import get_spec
    from ._logs import read_logs

    out = Path(args.json) if args.json else None
    if out is not None and out.exists() and not args.overwrite:
        raise FileExistsError(f"{out}: exists; refusing to overwrite (pass --overwrite)")
    spec = get_spec(args.system)
    read = read_logs(
        args.data, args.system, args.column_map, args.sign, args.offset, args.units, args.time_unit, strict=False
    )
    logs = [describe_log(source, reading, spec) for source, reading in read]
    everything = [tr for _, reading in read for tr in reading.trajectories]
    pooled = identifiability(everything, spec) if len(logs) > 1 else None
    print(format_inspection(logs, spec, pooled))
    if out is not None:
        doc = {"system": spec.name, "logs": logs}
        if pooled is not None:
            doc["pooled"] = {"identifiable": pooled[0], "not_identifiable": pooled[1]}
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(doc, indent=2) + "\n")
        print(f"wrote {out}")
    return 0
