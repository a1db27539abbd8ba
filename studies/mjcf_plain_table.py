"""The table of ``studies/mjcf_plain_mujoco.py`` (the written MJCF in plain MuJoCo on the
head-to-head's test runs), generated from its result file (never typed): rewrites the block
``<!-- generated:mjcf-plain-mujoco -->`` in docs/diagnose.md. ``--check`` only compares (exit 1
when the docs disagree with the results).

    python studies/mjcf_plain_table.py [--check]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "head_to_head" / "mjcf_plain.json"
DOC = ROOT / "docs" / "diagnose.md"
NAME = "mjcf-plain-mujoco"
#: the issue's mark: plain MuJoCo on the written file within this share of the plant's own score
WITHIN = 0.05


def _mrad(v: float) -> str:
    return f"{1e3 * v:.2f}"


def _not_expressed(row: dict) -> str:
    """What the file could not carry: effects it lists, and one the written refit was fitted without."""
    refitted = [f"{k} (the file holds the refit without it)" for k in row.get("written_refitted_without", [])]
    return ", ".join(row["not_expressed"] + refitted) or "none"


def body(doc: dict | None = None) -> str:
    doc = doc or json.loads(RESULTS.read_text())
    nominal = doc["nominal_mjcf"]["position_rmse"]
    rows = [
        "| plant (fit on runs 1–10) | furuta-gym's prediction (mrad) | its MJCF in plain MuJoCo (mrad) "
        "| plain / plant | the MJCF's native terms only (mrad) | vs nominal MJCF | approximated | not expressed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["rows"]:
        plant, plain = r["plant"]["position_rmse"], r["plain_mujoco"]["position_rmse"]
        rows.append(
            f"| {r['label']} ({', '.join(r['effects'])}) | {_mrad(plant)} | **{_mrad(plain)}** "
            f"| {plain / plant:.3f} | {_mrad(r['native_terms_only']['position_rmse'])} | {nominal / plain:.1f}× "
            f"| {', '.join(r['approximated']) or '–'} | {_not_expressed(r)} |"
        )
    worst = max(r["plain_mujoco"]["position_rmse"] / r["plant"]["position_rmse"] for r in doc["rows"])
    verdict = "within" if worst <= 1 + WITHIN else "NOT within"
    return "\n".join(
        rows
        + [
            "",
            f"Both angles' position RMSE over the {doc['rows'][0]['plain_mujoco']['n_windows']} windows of "
            f"runs {doc['test_runs'][0]}–{doc['test_runs'][-1]} (0.1 s, the head-to-head's scoring), MuJoCo "
            f"{doc['mujoco']}, {doc['date']}. Plain MuJoCo on the written file is {verdict} "
            f"{100 * WITHIN:.0f} % of the plant's own score (at worst {100 * (worst - 1):+.1f} %); the shipped "
            f'nominal MJCF in plain MuJoCo scores {_mrad(nominal)} mrad. "Native terms only" is the same '
            "plant's file without MuJoCo's forms of its dry friction, constant torque, centre-of-mass offset "
            "and input delay (what `--mjcf` wrote before). From `python studies/mjcf_plain_mujoco.py && "
            "python studies/mjcf_plain_table.py`.",
        ]
    )


if __name__ == "__main__":
    sys.exit(block_main(__file__, DOC, NAME, body))
