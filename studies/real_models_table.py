"""The docs table of ``studies/real_models.py``, generated from its result files (never typed).

Reads ``results/real_models/*.json`` and rewrites the block between
``<!-- generated:real-models -->`` and ``<!-- /generated:real-models -->`` in docs/learning.md:
per-state log10 RMSE and RMSE on the test runs, the winner (lowest mean log10 RMSE over the four
states), what each learned model was trained with, and the command that makes it all. ``--check``
only compares (exit 1 when the docs disagree with the results).

    python studies/real_models_table.py [--check]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import fill_block, update  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "real_models"
DOC = ROOT / "docs" / "learning.md"
NAME = "real-models"
ORDER = (
    "nominal",
    "fitted",
    "diagnosed",
    "dln_prop",
    "dln_prop_span",
    "dln_prop_span_traj",
    "dln_traj",
    "adln_prop",
    "adln_prop_span",
    "adln_aph",
)
STATES = (("alpha", "α"), ("beta", "β"), ("alpha_dot", "α̇"), ("beta_dot", "β̇"))
STUDY = "python studies/real_models.py"  # the command a summary without its own record ran


def load(folder: Path = RESULTS) -> tuple[dict, list[dict]]:
    summary = json.loads((folder / "summary.json").read_text())
    docs = [json.loads((folder / f"{n}.json").read_text()) for n in ORDER if (folder / f"{n}.json").is_file()]
    return summary, docs


def mean_log10(doc) -> float:
    """Mean of the four log10 RMSEs; a diverged model ("X") ranks last."""
    cells = doc["test"]["log10_rmse"].values()
    return float("inf") if any(isinstance(v, str) for v in cells) else sum(cells) / len(cells)


def _cell(v, best) -> str:
    if isinstance(v, str):
        return v
    return f"**{v:.3f}**" if v == best else f"{v:.3f}"


def score_table(docs: list[dict]) -> str:
    units = ("rad", "rad", "rad/s", "rad/s")
    head = (
        "| model | "
        + " | ".join(f"{s} log10" for _, s in STATES)
        + " | mean log10 | "
        + " | ".join(f"{s} RMSE ({u})" for (_, s), u in zip(STATES, units, strict=True))
        + " |"
    )
    rows = [head, "|---" * (2 + 2 * len(STATES)) + "|"]
    finite = [d for d in docs if mean_log10(d) < float("inf")]
    best = {k: min(d["test"]["log10_rmse"][k] for d in finite) for k, _ in STATES} if finite else {}
    best_mean = min((mean_log10(d) for d in finite), default=None)
    for d in docs:
        lg, rm = d["test"]["log10_rmse"], d["test"]["rmse"]
        m = mean_log10(d)
        rows.append(
            f"| {d['label']} | "
            + " | ".join(_cell(lg[k], best.get(k)) for k, _ in STATES)
            + f" | {_cell(m, best_mean) if m < float('inf') else 'X'} | "
            + " | ".join("–" if rm[k] is None else f"{rm[k]:.4f}" for k, _ in STATES)
            + " |"
        )
    return "\n".join(rows)


def shape_table(docs: list[dict]) -> str:
    """The potential each model believes in, where the physics says what it must be."""
    rows = ["| model | V(β = π) − V(0) (mJ) | ∂²V/∂β² at β = π (mN·m/rad) |", "|---|---|---|"]
    for d in docs:
        p = d["potential"]
        rows.append(f"| {d['label']} | {1e3 * p['rise_to_top_J']:.1f} | {1e3 * p['curvature_at_top_Nm_per_rad']:.2f} |")
    return "\n".join(rows)


def training_table(docs: list[dict]) -> str:
    labels = {d["name"]: d["label"] for d in docs}
    rows = [
        "| model | epochs per stage | horizons | L_Iτ quadrature | learning rate | training s "
        "| snapshot kept | its / the last one's validation mean log10 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for d in docs:
        tr = d.get("training")
        if not tr:
            continue
        c = tr["config"]
        hz = ", ".join(
            "L_Iτ alone" if h is None else (f"{h} samples" if isinstance(h, int) else f"{h} s") for h in c["horizons"]
        )
        lr = c["learning_rate"]
        lr = ", ".join(f"{v:g}" for v in lr) if isinstance(lr, list) else f"{lr:g}"
        quad = "–"  # L_Iτ's rule (and its intervals per residual): L_prop only
        if "_prop" in d["name"]:
            span = c.get("integral_span", 1)
            quad = c["quadrature"] + (f", {span} intervals per residual" if span > 1 else "")
        epochs = ", ".join(map(str, c["epochs"]))
        if "continues" in tr:  # trajectory stages continued from another row's selected model
            after = labels.get(tr["continues"], tr["continues"])
            epochs += f" (from {after}, its kept snapshot; λ {c['lambda_traj']:g} of {tr['lambda_candidates']})"
        rows.append(
            f"| {d['label']} | {epochs} | {hz} | {quad} | {lr} "
            f"| {tr['training_seconds']:.0f} | {tr['selected']} "
            f"| {tr['validation'][tr['selected']]:.3f} / {tr['validation'][tr.get('last', 'model.eqx')]:.3f} |"
        )
    return "\n".join(rows)


#: each L_prop variant, the row it improves on (and how it differs from it), and its baseline loss
SPAN_PAIRS = (
    ("dln_prop_span", "dln_prop", "than with the paper's L_Iτ", "dln_traj"),
    ("adln_prop_span", "adln_prop", "than with the paper's L_Iτ", "adln_aph"),
)
TRAJECTORY_PAIRS = (("dln_prop_span_traj", "dln_prop_span", "than without the trajectory stages", "dln_traj"),)


def span_sentence(docs: list[dict], pairs=SPAN_PAIRS, title: str = "L_Iτ over 0.1 s") -> str:
    """L_prop variants against the row they improve on and against their baselines, and their
    potential against the physics' (the nominal model's), in one generated sentence."""
    by = {d["name"]: d for d in docs}
    physics = by["nominal"]["potential"] if "nominal" in by else None
    parts = []
    for name, before, how, base in pairs:
        if not (physics and name in by and base in by):
            continue
        p = by[name]["potential"]
        curv = p["curvature_at_top_Nm_per_rad"] / physics["curvature_at_top_Nm_per_rad"]
        rise = p["rise_to_top_J"] / physics["rise_to_top_J"]
        gap = mean_log10(by[name]) - mean_log10(by[base])
        than = ""  # against the row it improves on, where this run has that row
        if before in by:
            gain = mean_log10(by[before]) - mean_log10(by[name])
            than = f"{abs(gain):.2f} {'better' if gain >= 0 else 'worse'} {how} and "
        parts.append(
            f"{by[name]['label']}: curvature at β = π {curv:.0%} and rise to the top {rise:.0%} of the "
            f"physics'; mean log10 {than}"
            + (f"{gap:.3f} behind" if gap > 0 else f"{-gap:.3f} ahead of")
            + f" {by[base]['label']}"
        )
    return (f"{title} — " + "; ".join(parts) + ".") if parts else ""


def block(summary: dict, docs: list[dict], folder: Path = RESULTS, name: str = NAME) -> str:
    ranked = sorted(docs, key=mean_log10)
    winner, second = ranked[0], ranked[1]
    test = docs[0]["test"]
    fit, tst = summary["fit_runs"], summary["test_runs"]
    diag = next((d["diagnose"] for d in docs if d.get("diagnose")), None)
    train_min = sum(d["training"]["training_seconds"] for d in docs if d.get("training")) / 60
    lines = [
        f"Fitted / trained on runs {fit[0]}–{fit[-1]}, scored on runs {tst[0]}–{tst[-1]}: {test['n_windows']} "
        f"open-loop windows of {summary['window_seconds']} s started from the measured state, input held; "
        "log10 RMSE (lower is better; **bold**: best in its column) and RMSE in rad, rad/s.",
        "",
        score_table(docs),
        "",
        f"**Winner: {winner['label']}** (lowest mean log10 RMSE over the four states, {mean_log10(winner):.3f}; "
        f"next {second['label']}, {mean_log10(second):.3f}: {mean_log10(second) - mean_log10(winner):.3f} "
        "apart, one seed of each learned model).",
    ]
    if diag:
        lines += ["", f"Diagnosis on runs {fit[0]}–{fit[-1]}: {diag['note']}."]
    lines += [
        "",
        "Energy shape at α = 0 (the physical potential rises from hanging to upright and "
        "has its maximum there; the logs only visit the neighbourhood of the top):",
        "",
        shape_table(docs),
        "",
        span_sentence(docs),
        "",
        *[
            line
            for sentence in [span_sentence(docs, TRAJECTORY_PAIRS, "With trajectory stages at the baselines' budget")]
            if sentence
            for line in (sentence, "")
        ],
        f"Learned models: {summary['n_train']} training and {summary['n_validation']} validation "
        f"elementary trajectories of {summary['split_seconds']} s (every {summary['validation_every']}th "
        f"held out), the script's schedules × {summary['budget']}:",
        "",
        training_table(docs),
        "",
        f"Made by `{summary.get('command', STUDY)} && python studies/real_models_table.py"
        + ("" if folder == RESULTS else f" --results {folder.relative_to(ROOT)} --block {name}")
        + f"` ({train_min:.0f} min of training in all, {summary['date']})"
        + (
            f"; the nominal, fitted and diagnosed rows again by `{rerun['command']}` ({rerun['date']})"
            if (rerun := summary.get("declared_rerun"))
            else ""
        )
        + f"; figure: [{folder.relative_to(ROOT)}/energy.png](../{folder.relative_to(ROOT)}/energy.png).",
    ]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    ap.add_argument("--results", type=Path, default=RESULTS, help="result folder (default results/real_models)")
    ap.add_argument("--block", default=NAME, help=f"the docs block to fill (default {NAME})")
    args = ap.parse_args()
    folder = args.results.resolve()
    summary, docs = load(folder)
    text = fill_block(DOC.read_text(), args.block, block(summary, docs, folder, args.block), where=DOC)
    return update(DOC, text, args.check, "run python studies/real_models_table.py")


if __name__ == "__main__":
    sys.exit(main())
