"""The README's headline results table, written from the committed reproduction tables.

    python studies/readme_results.py           # rewrite the README block
    python studies/readme_results.py --check   # exit 1 if the README block is stale

Reads the reproduction of the frozen recipe (``results/reproduce/tables.csv``). Per system and model, with L_prop
against the model's baseline loss (L_traj for DeLaN, L_aph for APHYNITY and augmented DeLaN):
how many cells of each are at or below the paper's, and the force decomposition — the mean over
both test sets of the inertial, Coriolis and potential-derived log10 RMSE (APHYNITY has none:
its M and V are the prior's).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TABLE = ROOT / "results" / "reproduce" / "tables.csv"
NAME = "readme-results"  # the README block this writes
BASELINE = {"DLN": "traj", "APH": "aph", "ADLN": "aph"}
LOSS = {"traj": "L_traj", "aph": "L_aph", "prop": "L_prop"}
FORCES = ("inertial", "coriolis", "potential")
SYSTEM = {"furuta": "Furuta", "nmsd": "N-MSD"}


def _rows(system: str) -> list[dict]:
    with TABLE.open() as f:
        return [r for r in csv.DictReader(f) if r["system"] == system]


def _cells(rows, model, loss) -> tuple[int, int]:
    """(at or below the paper, cells with a paper value) of one model × loss."""
    mine = [r for r in rows if r["model"] == model and r["loss"] == loss and r["better_or_equal"]]
    return sum(r["better_or_equal"] == "yes" for r in mine), len(mine)


def _forces(rows, model, loss) -> float | None:
    values = [
        float(r["ours_mean"])
        for r in rows
        if r["model"] == model and r["loss"] == loss and r["metric"] in FORCES and r["ours_mean"]
    ]
    return float(np.mean(values)) if values else None


def table() -> str:
    lines = [
        "| system | model | cells at or below the paper: L_prop | baseline | "
        "force decomposition, log10 RMSE: L_prop | baseline |",
        "|---|---|---|---|---|---|",
    ]
    seeds = set()
    for system in SYSTEM:
        rows = _rows(system)
        seeds |= {r["n_seeds"] for r in rows}
        for model, base in BASELINE.items():
            prop, ref = _cells(rows, model, "prop"), _cells(rows, model, base)
            fp, fb = _forces(rows, model, "prop"), _forces(rows, model, base)
            force = "N/A (prior) | N/A" if fp is None else f"**{fp:.2f}** | {fb:.2f} ({LOSS[base]})"
            lines.append(
                f"| {SYSTEM[system]} | {model} | {prop[0]} of {prop[1]} | "
                f"{ref[0]} of {ref[1]} ({LOSS[base]}) | {force} |"
            )
    note = (
        f"{' / '.join(sorted(seeds))} model seed(s) per row, the frozen recipe, one run from scratch; "
        "generated from [results/reproduce](results/reproduce/tables.md) by "
        "`studies/readme_results.py`."
    )
    return "\n".join(lines) + "\n\n" + note


def main(argv=None) -> int:
    return block_main(__file__, README, NAME, table, argv)


if __name__ == "__main__":
    raise SystemExit(main())
