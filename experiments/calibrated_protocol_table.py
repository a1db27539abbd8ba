"""The calibrated-rig block of docs/learning.md, from ``results/calibrated_protocol``: the six
models' prediction columns beside the paper's experimental ones (``reproduce --plant ... --sensor
experiment``'s tables.csv), each model's energy shape and its swing-up on the rig
(``experiments/calibrated_protocol.py``'s control.json).

    python experiments/calibrated_protocol_table.py [--check]
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "calibrated_protocol"
STATES = ("alpha", "beta", "alpha_dot", "beta_dot")
LABELS = {"dln_traj": "DeLaN L_traj", "dln_prop": "DeLaN L_prop", "aph_aph": "APHYNITY L_aph",
          "aph_prop": "APHYNITY L_prop", "adln_aph": "augmented DeLaN L_aph", "adln_prop": "augmented DeLaN L_prop",
          "plant model": "the plant's own model (reference)", "nominal analytic": "nominal analytic (reference)"}
MODEL_KEYS = {"DLN": "dln", "APH": "aph", "ADLN": "adln"}


def prediction_table() -> list[str]:
    """Per test set and model: each state's log10 RMSE, ours (the paper's experimental value)."""
    with open(OUT / "reproduce" / "tables.csv") as fh:
        rows = [r for r in csv.DictReader(fh) if r["metric"] in STATES]
    lines = ["| test set | model | α | β | α̇ | β̇ |", "|---|---|---:|---:|---:|---:|"]
    keys = dict.fromkeys((r["test_set"], r["model"], r["loss"]) for r in rows)
    for test_set, model, loss in keys:
        cells = {r["metric"]: r for r in rows if (r["test_set"], r["model"], r["loss"]) == (test_set, model, loss)}
        text = [f"{cells[s]['ours']} ({cells[s]['paper'] or '—'})" for s in STATES]
        label = LABELS[f"{MODEL_KEYS[model]}_{loss}"]
        lines.append(f"| {test_set} | {label} | " + " | ".join(text) + " |")
    return lines


def control_table(doc: dict) -> list[str]:
    """Per design model: the potential's curvature at both ends and the swing-up on the rig."""
    lines = ["| designed on | V'' hanging (mN·m/rad) | V'' upright (mN·m/rad) | shape | swing-up from x0 = 0 | "
             f"seeded starts (of {doc['episodes']}) |", "|---|---:|---:|---|---|---:|"]
    for name, row in doc["models"].items():
        shape = row.get("shape")
        if shape is None:
            curv, kind = ["—", "—"], "no potential"
        else:
            low, top = shape["curvature_at_hanging_Nm_per_rad"], shape["curvature_at_top_Nm_per_rad"]
            curv = [f"{1e3 * low:+.2f}", f"{1e3 * top:+.2f}"]
            kind = "physical" if low > 0 > top else ("upright a minimum" if top > 0 else "hanging a maximum")
        if "design_error" in row:
            run = ["design failed", "—"]
        else:
            run = ["yes" if row["from_rest"] else "NO", f"{row['seeded_successes']}/{row['seeded']}"]
        lines.append(f"| {LABELS[name]} | {curv[0]} | {curv[1]} | {kind} | {run[0]} | {run[1]} |")
    return lines


def verdict(doc: dict) -> str:
    """Whether both L_prop models meet the protocol's bar: upright a maximum, swing-up from rest
    and from at least 90 % of the seeded starts."""
    parts = []
    for name in ("dln_prop", "adln_prop"):
        row = doc["models"].get(name)
        if row is None:
            parts.append(f"{LABELS[name]}: not trained")
            continue
        shape_ok = row.get("shape") is not None and row["shape"]["curvature_at_top_Nm_per_rad"] < 0
        ok = "design_error" not in row and row["from_rest"] and row["seeded_successes"] >= 0.9 * row["seeded"]
        parts.append(f"{LABELS[name]}: upright {'a maximum' if shape_ok else 'NOT a maximum'}, swing-up "
                     + ("meets" if ok else "does NOT meet") + " the bar (x0 = 0 and ≥ 90 % of the starts)")
    return "; ".join(parts) + "."


def itau_stage_lines(doc: dict) -> list[str]:
    """What each L_prop run's L_Iτ stage left: epochs, mass matrix, stiffness, potential shape."""
    lines = []
    for name, st in doc.get("itau_stage", {}).items():
        m, mp = st["mass_matrix_at_rest"], st["plant_mass_matrix_at_rest"]
        low, top = st["shape"]["curvature_at_hanging_Nm_per_rad"], st["shape"]["curvature_at_top_Nm_per_rad"]
        kind = "physical" if low > 0 > top else ("upright a minimum" if top > 0 else "hanging a maximum")
        lines.append(
            f"- {LABELS[name]}, after {min(st['epoch'] - 1, st['itau_epochs'])} of its {st['itau_epochs']} L_Iτ epochs: M(0) = "
            f"[[{m[0][0]:.2g}, {m[0][1]:.2g}], [·, {m[1][1]:.2g}]] kg·m² against the plant's "
            f"[[{mp[0][0]:.2g}, {mp[0][1]:.2g}], [·, {mp[1][1]:.2g}]]; the free dynamics' largest |eigenvalue| "
            f"{st['stiffness_median']:.2g} /s (median over 20 states; max {st['stiffness_max']:.2g}) against the "
            f"plant's {st['plant_stiffness_median']:.2g} /s; potential shape {kind} (the curvatures' signs do not "
            "depend on the overall scale)."
            + (f" The next stage (2-step L_traj + L_Iτ) then ran {st['later_epochs']} epoch(s) in "
               f"{st['later_seconds']:.0f} s; {st['later_steps_skipped']} of its {st['later_steps']} steps were skipped "
               "(a non-finite loss or gradient: the ODE solve failed)." if st["later_epochs"] else ""))
    return lines


def body() -> str:
    doc = json.loads((OUT / "control.json").read_text())
    return "\n".join(["Prediction, log10 RMSE on the rig's test runs: ours (the paper's experimental value; "
                      "its forced APHYNITY rows diverged, X).", "", *prediction_table(), "",
                      f"Energy shape and the swing-up designed on each model, run on the rig "
                      f"({doc['seconds_per_episode']:g} s episodes, 2048-count encoders, derivative-filter velocities; "
                      f"{doc['date']}).", "", *control_table(doc), "", verdict(doc), "",
                      "What the L_Iτ stage left in the L_prop runs that did not finish (see the text above the block):", "",
                      *itau_stage_lines(doc)])


if __name__ == "__main__":
    sys.exit(block_main(__file__, ROOT / "docs" / "learning.md", "calibrated-protocol", body))
