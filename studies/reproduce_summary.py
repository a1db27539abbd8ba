"""docs/reproduce.md's summary of the frozen recipe's reproduction, written from its files.

    python studies/reproduce_summary.py           # rewrite the docs block
    python studies/reproduce_summary.py --check   # exit 1 if the docs block is stale

Reads ``results/reproduce/tables.csv`` (our cells beside the paper's) and ``run.json`` (command,
machine, seconds per model; a model the last invocation reused keeps the seconds of the run that
trained it). Per system, model and loss: the cells at or below the paper's, the force
decomposition (mean log10 RMSE of the inertial, Coriolis and potential-derived forces over the
test sets), training seconds; then every cell where the paper's number is lower than ours.
"""

from __future__ import annotations

import csv
import json
import re
import sys
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "results" / "reproduce"
DOCS = ROOT / "docs" / "reproduce.md"
NAME = "reproduce-summary"  # the docs/reproduce.md block this writes
FORCES = ("inertial", "coriolis", "potential")
LOSS = {"traj": "L_traj", "aph": "L_aph", "prop": "L_prop"}
SYSTEM = {"furuta": "Furuta", "nmsd": "N-MSD"}


def _seconds(record) -> float | None:
    """Training + evaluation seconds of one model's record in run.json."""
    if not isinstance(record, dict):
        return None
    original = record.get("original")
    if original:
        return float(original.get("train", 0.0)) + float(original.get("evaluate", 0.0))
    return float(record["seconds"])


def _model_rows(rows, run) -> list[str]:
    lines = [
        "| system | model | loss | cells at or below the paper | force decomposition, log10 RMSE "
        "| train + evaluate s |",
        "|---|---|---|---|---|---|",
    ]
    keys = dict.fromkeys((r["system"], r["model"], r["loss"]) for r in rows)
    for system, model, loss in keys:
        mine = [r for r in rows if (r["system"], r["model"], r["loss"]) == (system, model, loss)]
        judged = [r for r in mine if r["better_or_equal"]]
        forces = [float(r["ours_mean"]) for r in mine if r["metric"] in FORCES and r["ours_mean"]]
        force = f"{np.mean(forces):.2f}" if forces else "N/A (prior)"
        seconds = _seconds(run["seconds"].get(f"{system}/{model.lower()}_{loss}/seed0"))
        lines.append(
            f"| {SYSTEM[system]} | {model} | {LOSS[loss]} | "
            f"{sum(r['better_or_equal'] == 'yes' for r in judged)} of {len(judged)} | {force} | "
            f"{'' if seconds is None else f'{seconds:.0f}'} |"
        )
    return lines


def _behind(rows) -> list[str]:
    worse = [r for r in rows if r["better_or_equal"] == "no"]
    if not worse:
        return ["Every cell with a paper value is at or below the paper's."]
    cells = [
        f"{SYSTEM[r['system']]} {r['model']} {LOSS[r['loss']]}, {r['test_set']} {r['metric']} "
        f"({float(r['ours_mean']):.2f} vs {float(r['paper']):.2f})"
        for r in worse
    ]
    return [f"Cells where the paper is lower ({len(worse)}): " + "; ".join(cells) + "."]


def _provenance(run) -> str:
    """What the last invocation trained itself and what it took from earlier ones into its folder."""
    models = [r for k, r in run["seconds"].items() if isinstance(r, dict) and "/seed" in k]
    reused = sum(r.get("status") == "reused" for r in models)
    if reused == 0:
        return f"it trained all {len(models)} models"
    if reused == len(models):
        return (
            "it reused all the models, trained from scratch into the same folder by the invocations in `invocations/`"
        )
    return (
        f"it trained {len(models) - reused} models and reused {reused} trained by an earlier "
        "invocation into the same folder: `invocations/`"
    )


def summary() -> str:
    with (RUN / "tables.csv").open() as f:
        rows = list(csv.DictReader(f))
    run = json.loads((RUN / "run.json").read_text())
    seeds = sorted({r["n_seeds"] for r in rows})
    machine = run["machine"]
    total = sum(s for s in map(_seconds, run["seconds"].values()) if s is not None)
    command = re.sub(r"--out \S+", "--out <folder>", run["command"])
    head = (
        f"`{command}` (the last invocation, {run['date_utc'][:16].replace('T', ' ')} UTC, "
        f"{machine.get('cpu', 'cpu')}, {machine['cpu_count']} cores; {_provenance(run)}); "
        f"{' / '.join(seeds)} model seed(s); "
        f"{total:.0f} s of training and evaluation summed over the models. Full tables: "
        "[results/reproduce/tables.md](../results/reproduce/tables.md)."
    )
    return "\n".join([head, "", *_model_rows(rows, run), "", *_behind(rows)])


def main(argv=None) -> int:
    return block_main(__file__, DOCS, NAME, summary, argv)


if __name__ == "__main__":
    raise SystemExit(main())
