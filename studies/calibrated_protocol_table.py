"""The calibrated-rig block of docs/learning.md, from ``results/calibrated_protocol``: the six
models' prediction columns beside the paper's experimental ones (``reproduce --plant ... --sensor
experiment``'s tables.csv), each model's energy shape and its swing-up on the rig
(``studies/calibrated_protocol.py``'s control.json).

    python studies/calibrated_protocol_table.py [--check]
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
LABELS = {
    "dln_traj": "DeLaN L_traj",
    "dln_prop": "DeLaN L_prop",
    "aph_aph": "APHYNITY L_aph",
    "aph_prop": "APHYNITY L_prop",
    "adln_aph": "augmented DeLaN L_aph",
    "adln_prop": "augmented DeLaN L_prop",
    "dln_prop_span": "DeLaN L_prop, span 0.2 s",
    "adln_prop_span": "augmented DeLaN L_prop, span 0.1 s",
    "dln_prop_offline": "DeLaN L_prop, span 0.2 s, offline velocities",
    "adln_prop_offline": "augmented DeLaN L_prop, span 0.1 s, offline velocities",
    "dln_prop_joint": "DeLaN L_prop, span 0.2 s, offline velocities, L_Iτ per joint",
    "dln_prop_spring": "DeLaN L_prop, span 0.2 s, offline velocities, learned rotor spring",
    "adln_prop_spring": "augmented DeLaN L_prop, span 0.1 s, offline velocities, learned rotor spring",
    "dln_traj_spring": "DeLaN L_traj, offline velocities, learned rotor spring",
    "adln_aph_spring": "augmented DeLaN L_aph, offline velocities, learned rotor spring",
    "plant model": "the plant's own model (reference)",
    "nominal analytic": "nominal analytic (reference)",
}
MODEL_KEYS = {"DLN": "dln", "APH": "aph", "ADLN": "adln"}
#: the L_prop runs again (name suffix: reproduction folder under results/calibrated_protocol); the
#: commands that made them are in studies/calibrated_protocol.py
VARIANTS = {
    "_span": "reproduce_span",
    "_offline": "reproduce_offline",
    "_joint": "reproduce_joint",
    "_spring": "reproduce_spring",
}


def _table_rows(folder: str, suffix: str) -> list[dict]:
    """The state rows of one reproduction's tables.csv, each with its docs label."""
    path = OUT / folder / "tables.csv"
    if not path.exists():
        return []
    with open(path) as fh:
        rows = [r for r in csv.DictReader(fh) if r["metric"] in STATES]
    return [{**r, "label": LABELS[f"{MODEL_KEYS[r['model']]}_{r['loss']}{suffix}"]} for r in rows]


def prediction_table() -> list[str]:
    """Per test set and model: each state's log10 RMSE, ours (the paper's experimental value)."""
    rows = _table_rows("reproduce", "")
    for suffix, folder in VARIANTS.items():
        rows += _table_rows(folder, suffix)
    lines = ["| test set | model | α | β | α̇ | β̇ |", "|---|---|---:|---:|---:|---:|"]
    for test_set in dict.fromkeys(r["test_set"] for r in rows):
        for label in dict.fromkeys(r["label"] for r in rows if r["test_set"] == test_set):
            cells = {r["metric"]: r for r in rows if (r["test_set"], r["label"]) == (test_set, label)}
            text = [f"{cells[s]['ours']} ({cells[s]['paper'] or '—'})" for s in STATES]
            lines.append(f"| {test_set} | {label} | " + " | ".join(text) + " |")
    return lines


def _run_cells(row: dict | None) -> list[str]:
    """A swing-up's two cells: from x0 = 0, and the seeded starts."""
    if row is None:
        return ["not run", "—"]
    if "design_error" in row:
        return ["design failed", "—"]
    return ["yes" if row["from_rest"] else "NO", f"{row['seeded_successes']}/{row['seeded']}"]


def control_table(doc: dict) -> list[str]:
    """Per design model: the potential's curvature at both ends and the swing-up on the rig, with
    the default pump gain and with the gain picked on the design model."""
    lines = [
        "| designed on | V'' hanging (mN·m/rad) | V'' upright (mN·m/rad) | shape | swing-up from x0 = 0 | "
        f"seeded starts (of {doc['episodes']}) | k_e picked on the model: from x0 = 0 | seeded |",
        "|---|---:|---:|---|---|---:|---|---:|",
    ]
    for name, row in doc["models"].items():
        shape = row.get("shape")
        if shape is None:
            curv, kind = ["—", "—"], "no potential"
        else:
            low, top = shape["curvature_at_hanging_Nm_per_rad"], shape["curvature_at_top_Nm_per_rad"]
            curv = [f"{1e3 * low:+.2f}", f"{1e3 * top:+.2f}"]
            kind = "physical" if low > 0 > top else ("upright a minimum" if top > 0 else "hanging a maximum")
        cells = [*curv, kind, *_run_cells(row), *_run_cells(row.get("gain_picked_on_model"))]
        lines.append(f"| {LABELS[name]} | " + " | ".join(cells) + " |")
    return lines


def _meets_bar(run: dict | None) -> bool:
    """Swing-up from x0 = 0 and from at least 90 % of the seeded starts."""
    if run is None or "design_error" in run:
        return False
    return bool(run["from_rest"]) and run["seeded_successes"] >= 0.9 * run["seeded"]


def verdict(doc: dict) -> str:
    """Whether each L_prop model meets the protocol's bar: upright a maximum, swing-up from rest
    and from at least 90 % of the seeded starts (with either pump gain)."""
    parts = []
    for name in (f"{kind}_prop{suffix}" for suffix in ("", *VARIANTS) for kind in ("dln", "adln")):
        row = doc["models"].get(name)
        if row is None and name.endswith(tuple(VARIANTS)):
            continue  # a variant not run
        if row is None:
            parts.append(f"{LABELS[name]}: not trained")
            continue
        shape_ok = row.get("shape") is not None and row["shape"]["curvature_at_top_Nm_per_rad"] < 0
        gains = [("the default k_e", row), ("k_e picked on the model", row.get("gain_picked_on_model"))]
        met = [f"{'meets' if _meets_bar(run) else 'does NOT meet'} the bar with {g}" for g, run in gains if run]
        parts.append(
            f"{LABELS[name]}: upright {'a maximum' if shape_ok else 'NOT a maximum'}, swing-up " + ", ".join(met)
        )
    return "; ".join(parts) + " (the bar: x0 = 0 and ≥ 90 % of the starts)."


def terms_table(doc: dict) -> list[str]:
    """Per design model: the inertias, the rotor's damping (back-EMF included) and how strongly a
    volt moves the rotor, input / M₁₁, relative to the plant's (``calibrated_protocol.py --terms-only``)."""
    terms = doc.get("terms")
    if not terms:
        return []

    def gain_over_inertia(t):
        return t["input_force_per_volt"][0] / t["mass_matrix_at_rest"][0][0]

    plant = gain_over_inertia(terms["plant model"])
    lines = [
        "The rest of what a design takes, at rest (M in 1e-4 kg·m², rotor damping in 1e-4 N·m·s/rad with "
        "the back-EMF, the potential's stiffness in α, ∂²V/∂α², in 1e-4 N·m/rad: the plant's is its cable "
        "spring; the learned models' input force is fixed at the nominal 5e-3 N·m/V):",
        "",
        "| designed on | M₁₁ | M₂₂ | rotor damping | ∂²V/∂α² | (input / M₁₁) ÷ the plant's |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for name, t in terms.items():
        m, d = t["mass_matrix_at_rest"], t["force_per_unit_velocity"]
        stiffness = f"{1e4 * t['alpha_stiffness_at_rest']:.3g}" if "alpha_stiffness_at_rest" in t else "—"
        lines.append(
            f"| {LABELS[name]} | {1e4 * m[0][0]:.3g} | {1e4 * m[1][1]:.3g} | {-1e4 * d[0][0]:.3g} | {stiffness} | "
            f"{gain_over_inertia(t) / plant:.3g} |"
        )
    return lines


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
            + (
                f" The next stage (2-step L_traj + L_Iτ) then ran {st['later_epochs']} epoch(s) in "
                f"{st['later_seconds']:.0f} s; {st['later_steps_skipped']} of its {st['later_steps']} steps were skipped "
                "(a non-finite loss or gradient: the ODE solve failed)."
                if st["later_epochs"]
                else ""
            )
        )
    return lines


def _hanging_hz(mass: list, curvature: float) -> str:
    """The pendulum's small-oscillation frequency about hanging, √(V''·(M⁻¹)₂₂)/2π: free of the
    overall scale that free releases leave open. "—" where V'' ≤ 0 (no oscillation)."""
    inverse_22 = mass[0][0] / (mass[0][0] * mass[1][1] - mass[0][1] * mass[1][0])
    value = curvature * inverse_22
    return f"{value**0.5 / (2 * 3.141592653589793):.2f}" if value > 0 else "—"


def itau_causes_lines(plant_curvature: float) -> list[str]:
    """``studies/calibrated_itau.py``'s cells: the plant's own L_Iτ per velocity estimate, and
    what DeLaN's L_Iτ stage leaves per sensor, velocity estimate and span."""
    path = OUT / "itau_causes.json"
    if not path.exists():
        return []
    doc = json.loads(path.read_text())
    first = next(iter(doc["cells"].values()))
    lines = [
        "The plant's own L_Iτ on its 64 training releases (0 would be a perfect fit; the normaliser "
        "is the model's own momentum changes):",
        "",
        "| data | L_Iτ of the plant |",
        "|---|---:|",
    ]
    lines += [f"| {name} | {value:.2g} |" for name, value in doc["plant_itau"].items()]
    lines += [
        "",
        "DeLaN's L_Iτ stage alone (the recipe's, seed 0), per sensor, velocities and span:",
        "",
        "| sensor | velocities | span (20 ms intervals) | epochs | L_Iτ learned / plant | hanging frequency (Hz; plant {}) | "
        "stiffness (1/s; plant {:.1f}) | potential |".format(
            _hanging_hz(first["plant_mass_matrix_at_rest"], plant_curvature), first["plant_stiffness_median"]
        ),
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    velocity = {"recorded": "the sensor's", "zero_phase": "zero-phase, offline"}
    for cell in doc["cells"].values():
        low, top = cell["shape"]["curvature_at_hanging_Nm_per_rad"], cell["shape"]["curvature_at_top_Nm_per_rad"]
        kind = "physical" if low > 0 > top else ("upright a minimum" if top > 0 else "hanging a maximum")
        lines.append(
            f"| {cell['sensor']} | {velocity[cell['velocity']]} | {cell['span']} | {cell['epochs']} | "
            f"{cell['itau_learned_over_plant']:.2g} | {_hanging_hz(cell['mass_matrix_at_rest'], low)} | "
            f"{cell['stiffness_median']:.3g} | {kind} |"
        )
    return lines


def scale_fit_lines() -> list[str]:
    """``calibrated_itau.py --scale-fit-only``: where the scale fit's forced run takes the rotor,
    and the scale the plant's own model and the L_prop checkpoints get there."""
    path = OUT / "itau_causes.json"
    doc = json.loads(path.read_text()).get("scale_fit") if path.exists() else None
    if not doc:
        return []
    velocity = {"recorded": "the sensor's", "zero_phase": "zero-phase, offline"}
    lines = [
        f"The scale fit's forced run (the 2 V chirp, 20 s) takes the rotor {doc['rotor_travel_rad']:.1f} rad "
        f"end to end, to |α| = {doc['scale_fit_max_abs_alpha_rad']:.1f} rad; the training releases never pass "
        f"|α| = {doc['training_max_abs_alpha_rad']:.1f} rad. The scale it fits (1 is right for the plant's "
        "own model) and the share of the input's impulse left unexplained:",
        "",
        "| model | velocities, span | scale | unexplained |",
        "|---|---|---:|---:|",
    ]
    for key, fit in doc["plant_fits"].items():
        v, span = key.split(", ")
        lines.append(
            f"| the plant's own model | {velocity[v]}, {span} | {fit['factor']:.3g} | {fit['relative_residual']:.2f} |"
        )
    names = {"reproduce": "", **{folder: suffix for suffix, folder in VARIANTS.items()}}
    for key, fit in doc["recorded_fits"].items():
        folder, name = key.split("/")
        lines.append(
            f"| {LABELS[name + names[folder]]} | as trained | {fit['factor']:.3g} | "
            f"{fit['relative_residual_after']:.2f} |"
        )
    for key, fit in doc.get("in_range_fits", {}).items():
        folder, name = key.split("/")
        lines.append(
            f"| {LABELS[name + names[folder]]}, refitted on the run's first "
            f"{doc['seconds_inside_training_range']:.2f} s (inside the training range) | zero-phase, offline, "
            f"span 10 | × {fit['factor']:.3g} | {fit['relative_residual_after']:.2f} |"
        )
    return lines


def body() -> str:
    doc = json.loads((OUT / "control.json").read_text())
    return "\n".join(
        [
            "Prediction, log10 RMSE on the rig's test runs: ours (the paper's experimental value; "
            "its forced APHYNITY rows diverged, X).",
            "",
            *prediction_table(),
            "",
            f"Energy shape and the swing-up designed on each model, run on the rig "
            f"({doc['seconds_per_episode']:g} s episodes, 2048-count encoders, derivative-filter velocities; "
            f"{doc['date']}).",
            "",
            *control_table(doc),
            "",
            verdict(doc),
            "",
            *terms_table(doc),
            "",
            "What the L_Iτ stage left in the L_prop runs that did not finish (see the text above the block):",
            "",
            *itau_stage_lines(doc),
            "",
            *itau_causes_lines(doc["models"]["plant model"]["shape"]["curvature_at_hanging_Nm_per_rad"]),
            "",
            *scale_fit_lines(),
        ]
    )


if __name__ == "__main__":
    sys.exit(block_main(__file__, ROOT / "docs" / "learning.md", "calibrated-protocol", body))
