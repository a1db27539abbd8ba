"""`furuta-gym reproduce --quick` from a truly cold start, two installations side by side.

"Cold" means every cache a run could find empty: JAX's persistent compilation cache (with the
traced training steps stored beside it) and the C-kernel cache, both pointed at fresh temporary
folders (``JAX_COMPILATION_CACHE_DIR``, ``XDG_CACHE_HOME``). Pointing only ``XDG_CACHE_HOME``
elsewhere is not enough for code before 2026-11-25 (its JAX cache ignored it), which is how a warm
run was once recorded as cold.

Each installation is a Python interpreter with furuta-gym installed (e.g. this checkout's venv and
one with an older commit installed: ``git worktree add /tmp/old REV && python -m venv /tmp/oldvenv
&& /tmp/oldvenv/bin/pip install -e /tmp/old``). The runs go one after the other, baseline first,
on whatever else the machine is doing: run it on a quiet machine. The section compares the two
runs' tables cell by cell: a speed change that keeps the arithmetic leaves them identical; one
that changes rounding (``fast_compile``) moves the barely-trained quick models a little, and
the section says how many cells moved and by how much.

    python bench/quick_cold.py --python /root/venv/bin/python --baseline-python /tmp/oldvenv/bin/python

≈ 11 min. Rewrites its section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _generated import machine, write_section

SECTION = "quick_cold"


def describe(python: str) -> str:
    """Where that interpreter's furuta_gym lives and, if in a git checkout, its commit."""
    code = "import furuta_gym, pathlib; print(pathlib.Path(furuta_gym.__file__).resolve().parents[1])"
    root = subprocess.run(
        [python, "-c", code], capture_output=True, text=True, cwd=tempfile.gettempdir(), check=True
    ).stdout.strip()
    rev = subprocess.run(["git", "-C", root, "describe", "--always", "--dirty"], capture_output=True, text=True)
    return f"{root} @ {rev.stdout.strip() or '?'}"


def cold_quick(python: str, work: Path) -> tuple[float, float, dict]:
    """(wall seconds of the whole command, the run's own total, its cells) of one cold run."""
    for sub in ("xdg", "jax"):
        (work / sub).mkdir(parents=True)
    env = dict(
        os.environ,
        XDG_CACHE_HOME=str(work / "xdg"),
        JAX_COMPILATION_CACHE_DIR=str(work / "jax"),
        MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
    )
    env.pop("FURUTA_GYM_CACHE", None)  # it would win over XDG_CACHE_HOME
    out = work / "out"
    t0 = time.perf_counter()
    subprocess.run(
        [python, "-m", "furuta_gym", "reproduce", "--quick", "--out", str(out), "--no-progress"],
        env=env,
        cwd=tempfile.gettempdir(),
        check=True,
        stdout=subprocess.DEVNULL,
    )
    wall = time.perf_counter() - t0
    record = json.loads((out / "run.json").read_text())
    return wall, float(record["seconds"]["total"]), our_cells(out / "tables.csv")


def our_cells(path: Path) -> dict[tuple[str, ...], str]:
    """Our value of every cell of a reproduction's tables.csv, keyed by system, test set, model,
    loss and metric (a number as text, or N/A / X / fail)."""
    with open(path, newline="") as f:
        return {
            (r["system"], r["test_set"], r["model"], r["loss"], r["metric"]): r["ours_mean"] or r["ours"]
            for r in csv.DictReader(f)
        }


def compare_tables(baseline: dict, measured: dict) -> str:
    """ "identical", or how many cells differ and by how much (a change that only reorders
    floating-point rounding moves barely-trained quick models by a little, not a lot)."""
    if baseline == measured:
        return "identical"
    if baseline.keys() != measured.keys():
        return "**different cells** (the tables do not list the same cells)"
    differ = [k for k in baseline if baseline[k] != measured[k]]
    deltas = []
    for k in differ:
        try:
            deltas.append((abs(float(baseline[k]) - float(measured[k])), k))
        except ValueError:  # N/A, X or fail on one side
            return f"**different**: {'/'.join(k)} is {baseline[k]} in the baseline, {measured[k]} measured"
    largest, where = max(deltas)
    typical = sorted(d for d, _ in deltas)[len(deltas) // 2]
    return (
        f"**different** in {len(differ)} of {len(baseline)} cells (log10 RMSE): median |Δ| {typical:.2g}, "
        f"largest {largest:.2g} ({'/'.join(where)})"
    )


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable, help="interpreter of the code measured")
    parser.add_argument("--baseline-python", required=True, help="interpreter of the code compared against")
    parser.add_argument("--no-write", action="store_true", help="print the section, leave BENCHMARKS.md alone")
    parser.add_argument(
        "--keep",
        type=Path,
        default=None,
        metavar="DIR",
        help="copy the measured run's output (tables, figures, run.json, models) to DIR, "
        "which must not exist (e.g. to commit it as results/reproduce_quick)",
    )
    args = parser.parse_args(argv)
    if args.keep is not None and args.keep.exists():
        parser.error(f"--keep {args.keep}: exists; give a new folder (nothing is overwritten)")

    header = f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {machine()}"
    results = {}
    with tempfile.TemporaryDirectory(prefix="quick_cold_") as tmp:
        for name, python in (("baseline", args.baseline_python), ("measured", args.python)):
            results[name] = (describe(python), *cold_quick(python, Path(tmp) / name))
            print(f"{name}: {results[name][0]}: {results[name][1]:.1f} s", flush=True)
        if args.keep is not None:  # the datasets are regenerated from the manifest on reuse
            shutil.copytree(
                Path(tmp) / "measured" / "out",
                args.keep,
                ignore=shutil.ignore_patterns("*.csv", "train_state.eqx", "history.json"),
            )
            shutil.copy2(Path(tmp) / "measured" / "out" / "tables.csv", args.keep / "tables.csv")
    (b_code, b_wall, b_total, b_rows), (m_code, m_wall, m_total, m_rows) = results["baseline"], results["measured"]
    same = compare_tables(b_rows, m_rows)
    text = "\n".join(
        [
            f"<!-- {SECTION}:start -->",
            "## `furuta-gym reproduce --quick`, truly cold (`python bench/quick_cold.py`)",
            "",
            f"{header}. Both caches empty (JAX compilation + traced steps, C kernels); baseline first, then",
            "the measured code, one after the other. Target: ≤ 300 s.",
            "",
            "| code | whole command s | run's own total s |",
            "|---|---:|---:|",
            f"| baseline: {b_code} | {b_wall:.1f} | {b_total:.1f} |",
            f"| measured: {m_code} | {m_wall:.1f} | {m_total:.1f} |",
            f"| ratio measured / baseline | {m_wall / b_wall:.3f} | {m_total / b_total:.3f} |",
            "",
            f"Tables of the two runs: {same}.",
            f"<!-- {SECTION}:end -->",
        ]
    )
    print(text)
    if not args.no_write:
        write_section(text, f"<!-- {SECTION}:start -->", f"<!-- {SECTION}:end -->")


if __name__ == "__main__":
    main()
