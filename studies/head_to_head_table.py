"""The head-to-head table of ``studies/diagnose_head_to_head.py``, generated from its result
files (never typed): rewrites the block ``<!-- generated:diagnose-head-to-head -->`` in
docs/diagnose.md. ``--check`` only compares (exit 1 when the docs disagree with the results).

    python studies/head_to_head_table.py [--check]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "head_to_head"
DOC = ROOT / "docs" / "diagnose.md"
NAME = "diagnose-head-to-head"
ORDER = (
    "nominal",
    "gym_brt",
    "quanser_robots",
    "armandpl",
    "fitted",
    "diagnosed",
    "diagnosed_inconsistent",
    "diagnosed_prediction",
    "sysid_rigid",
    "sysid",
)
COMMAND = "python studies/diagnose_head_to_head.py && python studies/head_to_head_table.py"
SYSID_UNITS = {
    "rotor_inertia": "kg m²",
    "pendulum_com": "m",
    "pendulum_com_lateral": "m",
    "pendulum_armature": "kg m²",
    "arm_length": "m",
    "alpha_damping": "N m s/rad",
    "beta_damping": "N m s/rad",
    "alpha_frictionloss": "N m",
    "beta_frictionloss": "N m",
    "alpha_stiffness": "N m/rad",
    "alpha_springref": "rad",
    "motor_gain": "N m/V",
    "input_delay": "s",
}


def load(folder: Path = RESULTS) -> tuple[dict, list[dict]]:
    summary = json.loads((folder / "summary.json").read_text())
    return summary, [json.loads((folder / f"{n}.json").read_text()) for n in ORDER if (folder / f"{n}.json").is_file()]


def _runs(runs: list[int]) -> str:
    return f"runs {runs[0]}–{runs[-1]}" if runs else "nothing (published values)"


def _mrad(v: float, bold: bool = False) -> str:
    return f"**{1e3 * v:.2f}**" if bold else f"{1e3 * v:.2f}"


def _every_phase(d: dict, best: float | None) -> str:
    e = d.get("every_phase")
    return " – |" if e is None else f" {_mrad(e['position_rmse'], e['position_rmse'] == best)} |"


def score_table(docs: list[dict]) -> str:
    nominal = next(d for d in docs if d["name"] == "nominal")["position_rmse"]
    best = min(d["position_rmse"] for d in docs)
    phased = [d["every_phase"]["position_rmse"] for d in docs if "every_phase" in d]
    best_phased = min(phased) if phased else None
    extra = (" windows every 10 ms, both angles (mrad) |", "---|") if phased else ("", "")
    rows = [
        "| model | fitted on | α (mrad) | β (mrad) | both angles (mrad) | vs nominal | α̇, β̇ (rad/s) | fit wall time (s) |"
        + extra[0],
        "|---|---|---|---|---|---|---|---|" + extra[1],
    ]
    for d in docs:
        r = d["rmse"]
        wall = "–" if d["wall_seconds"] is None else f"{d['wall_seconds']:.0f}"
        diverged = f" ({d['n_diverged']} windows diverged)" if d["n_diverged"] else ""
        rows.append(
            f"| {d['label']}{diverged} | {_runs(d['fit_runs'])} | {_mrad(r['alpha'])} | {_mrad(r['beta'])} "
            f"| {_mrad(d['position_rmse'], d['position_rmse'] == best)} | {nominal / d['position_rmse']:.2f}× "
            f"| {r['alpha_dot']:.3f}, {r['beta_dot']:.3f} | {wall} |" + (_every_phase(d, best_phased) if phased else "")
        )
    return "\n".join(rows)


def every_phase_sentence(docs: list[dict]) -> str:
    """The ranking on windows starting every 10 ms, when the rows were scored so."""
    phased = sorted((d for d in docs if "every_phase" in d), key=lambda d: d["every_phase"]["position_rmse"])
    if len(phased) < 2:
        return ""
    first, second = phased[0], phased[1]
    return (
        f" The last column scores the same fits, not refitted, on {first['every_phase']['n_windows']} windows of "
        f"the same runs starting every {1e3 * first['every_phase']['stride_seconds']:g} ms (every point of the runs' "
        f"0.1 s input cycle alike; `diagnose_head_to_head.py --every-phase`): lowest **{first['label']}** "
        f"({_mrad(first['every_phase']['position_rmse'])} mrad), then {second['label']} "
        f"({_mrad(second['every_phase']['position_rmse'])} mrad)."
    )


def sysid_table(doc: dict) -> str:
    rows = ["| MJCF term (mujoco.sysid) | fitted | ± 95 % (sysid's iid interval) |", "|---|---|---|"]
    for name, value in doc["parameters"].items():
        half = doc["half_widths_95"][name]
        rows.append(f"| {name} ({SYSID_UNITS[name]}) | {value:.3g} | {half:.2g} |")
    return "\n".join(rows)


def _frame(f: dict) -> str:
    rotor = "θ = α" if f["rotor"] > 0 else "θ = −α"
    pend = ("β" if f["pendulum"] > 0 else "−β") + (" + π" if f["offset"] else "")
    if pend.startswith("−β + π"):
        pend = "π − β"
    return f"{rotor}, α_theirs = {pend}, V = {'u' if f['voltage'] > 0 else '−u'}"


def baseline_table(docs: list[dict]) -> str:
    keys = ("Mr", "Lr", "Mp", "Lp", "Rm", "km", "Dr", "Dp")
    rows = ["| simulator | source | " + " | ".join(keys) + " | their frame from ours |", "|---" * (len(keys) + 3) + "|"]
    for d in docs:
        if "frame" in d:
            p = d["parameters"]
            rows.append(
                f"| {d['label']} | {d['source']} | "
                + " | ".join(f"{p[k]:g}" for k in keys)
                + f" | {_frame(d['frame'])} |"
            )
    return "\n".join(rows)


COMMITTED_DIAGNOSIS = ROOT / "results" / "diagnose_real" / "growing_runs01-10.json"


def reproduces_committed(diagnosis: dict) -> str:
    """Whether the diagnosed row's fit is the committed diagnosis of the same runs and settings."""
    if not COMMITTED_DIAGNOSIS.is_file():
        return ""
    old = json.loads(COMMITTED_DIAGNOSIS.read_text())
    same = (
        old["settings"] == diagnosis["settings"]
        and old["plant"]["effects"] == diagnosis["plant"]["effects"]
        and all(abs(old["plant"]["lumped"][k] - v) <= 1e-9 * abs(v) for k, v in diagnosis["plant"]["lumped"].items())
    )
    verdict = "the same plant as" if same else "a different plant from"
    return f" It is {verdict} the committed `results/diagnose_real/growing_runs01-10.json`."


def findings(docs: list[dict]) -> str:
    by = {d["name"]: d for d in docs}
    parts = []
    if "diagnosed" in by:
        eff = ", ".join(f"{e['name']}:{e['joint']} ({e['coefficient']:.2g})" for e in by["diagnosed"]["effects"])
        parts.append(
            f"The diagnosis of runs {by['diagnosed']['fit_runs'][0]}–{by['diagnosed']['fit_runs'][-1]} "
            f"found {eff or 'nothing'}.{reproduces_committed(by['diagnosed']['diagnosis'])}"
        )
    for name in ("sysid", "sysid_rigid"):
        if name in by:
            f = by[name]["fit"]
            obj = f["objective"]
            settled = next(i for i, v in enumerate(obj) if v <= 1.001 * obj[-1])
            parts.append(
                f"{by[name]['label']}: {f['windows']} windows, {len(obj) - 1} Gauss-Newton iterations "
                f"(cap {f['iterations_cap']}; within 0.1 % of its final objective after {settled}), RMS "
                f"angle residual on its fit windows {1e3 * f['rms_angle_residual']:.2f} mrad."
            )
    extra = by.get("diagnosed_inconsistent")
    if extra:
        parts.append(
            f"{extra['label']}: the diagnosed plant with the effects its diagnosis reported "
            f"`inconsistent` added at their tested coefficients ({', '.join(extra['added'])}; no refit), "
            "`res.plant(include_inconsistent=True)` or `diagnose --mjcf OUT.xml --with-inconsistent`; "
            "its fit is the diagnosed row's."
        )
    if "diagnosed_prediction" in by:
        parts.append(prediction_first(by["diagnosed_prediction"]))
    return " ".join(parts)


def _rerun(doc: dict) -> str:
    """How the prediction-first row's diagnosis, run again, compares with the diagnosed row's."""
    versus, own = doc.get("diagnosis_vs_committed"), doc["same_run_position_rmse"]
    scores = (
        f"on these unseen runs its own plant scores {_mrad(own['diagnosed'])} mrad, "
        f"{_mrad(own['with_inconsistent'])} with its inconsistent effects"
    )
    if versus is None:
        return f"its diagnosis: {scores}."
    same = "the same effects as" if versus["same_effects"] else "other effects than"
    return (
        f"its diagnosis, run again (the finish needs its fitting context), finds {same} the diagnosed row's, "
        f"coefficients and parameters within {versus['largest_relative_difference']:.1%}; {scores}."
    )


def prediction_first(doc: dict) -> str:
    """What the prediction-first finish did on the fit runs and what its plant is."""
    f = doc["prediction_finish"]
    held = f["heldout_trajectory_rmse"]
    refit = {(e["name"], e["joint"]): e["coefficient"] for e in f["refit_plant"]["effects"]} if f["refit_plant"] else {}
    coefs = ", ".join(f"{k[0]}:{k[1]} {v:.2g}" for k, v in refit.items() if k[1] != "u")
    not_kept = (
        "" if doc["kept"] else f"; the refit, not kept, scores {_mrad(doc['refit_score']['position_rmse'])} mrad here"
    )
    return (
        f'{doc["label"]} (`diagnose(..., finish="prediction")`, `--prediction-first`): {_rerun(doc)} '
        f"Refitted by output error on {f['fit_windows']} fit-set windows with {', '.join(f['added']) or 'nothing'} "
        f"added ({', '.join(f['left_out']) or 'nothing'} left out for its sign): {coefs}. On the "
        f"{f['heldout_windows']} held-out {f['window_seconds']:g} s windows of the fit runs it predicts "
        f"{_mrad(held['refit'])} mrad against {_mrad(held['diagnosed'])} (diagnosed) and "
        f"{_mrad(held['with_inconsistent'])} (with its inconsistent effects): "
        f"{'kept' if doc['kept'] else 'not kept'} ({f['reason']}){not_kept}.{_dead_band(f, doc.get('without_dead_band'))} Its wall time is the "
        "diagnosis' and the finish's."
    )


def _dead_band(finish: dict, without: dict | None) -> str:
    """The finish's input dead band trial, in a sentence (empty for results made before it had one)."""
    band = finish.get("dead_band")
    if band is None:
        return ""
    if not band["kept"]:
        return f" Its input dead band is not kept ({band['reason']})."
    held = band["heldout_trajectory_rmse"]
    text = (
        f" With it, an input dead band of {1e3 * band['width']:.0f} mV (fitted with the rest) is kept: held-out "
        f"{_mrad(held['without'])} → {_mrad(held['with'])} mrad ({band['heldout_improvement']:.1%} of the sum of "
        f"squares, t {band['z_score']:.1f}); `--mjcf` writes the refit without it, which plain MuJoCo can run"
    )
    if without is None:
        return text + "."
    return text + (
        f", and which scores {_mrad(without['position_rmse'])} mrad on these unseen runs "
        f"({_mrad(without['every_phase_position_rmse'])} on the windows starting every 10 ms)."
    )


#: each extra MJCF term of the sysid fit and the library effect that is the same physics
COUNTERPART = {
    "alpha_stiffness": ("spring", "alpha"),
    "alpha_frictionloss": ("coulomb_friction", "alpha"),
    "beta_frictionloss": ("coulomb_friction", "beta"),
    "pendulum_com_lateral": ("com_offset", "beta"),
    "input_delay": ("input_delay", "u"),
}


def _counterpart(diagnosis: dict, term: str) -> str:
    name, joint = COUNTERPART[term]
    e = next((e for e in diagnosis["effects"] if (e["name"], e["joint"]) == (name, joint)), None)
    if e is None:
        return f"{name}:{joint}: not tested"
    ev = e.get("evidence") or {}
    gain = ev.get("heldout_residual_reduction")
    detail = "" if gain is None else f", held-out residual −{gain:.0%}, t {ev['z_score']:.1f}"
    coef = "" if e["coefficient"] is None else f" {e['coefficient']:.2g} {e['unit']}"
    return f"{name}:{joint} {e['status']}{coef}{detail}"


def ablation_table(doc: dict, diagnosis: dict | None) -> str:
    """Each extra MJCF term of the sysid fit zeroed at its fitted values (no refit): the error on
    the unseen runs without it, beside what the diagnosis said of the same physics."""
    without = doc.get("position_rmse_without")
    if not without:
        return ""
    rows = [
        f"| sysid term set to zero (all kept: {_mrad(without['none'])} mrad) | both angles (mrad) | the diagnosis of "
        "the same runs on the same physics |",
        "|---|---|---|",
    ]
    for term, v in sorted(((t, v) for t, v in without.items() if t != "none"), key=lambda kv: -kv[1]):
        rows.append(f"| {term} | {_mrad(v)} | {_counterpart(diagnosis, term) if diagnosis else '–'} |")
    return "\n".join(rows)


def block() -> str:
    summary, docs = load()
    ranked = sorted(docs, key=lambda d: d["position_rmse"])
    first, second = ranked[0], ranked[1]
    windows = docs[0]["n_windows"]
    lines = [
        f"Fitted on runs {summary['fit_runs'][0]}–{summary['fit_runs'][-1]}, scored on runs "
        f"{summary['test_runs'][0]}–{summary['test_runs'][-1]} (never fitted): {windows} back-to-back "
        f"{summary['window_seconds']} s open-loop windows from the measured state, the logged input held; RMSE "
        "over every predicted sample (**bold**: lowest).",
        "",
        score_table(docs),
        "",
        f"Lowest error on the unseen runs: **{first['label']}** ({_mrad(first['position_rmse'])} mrad), then "
        f"{second['label']} ({_mrad(second['position_rmse'])} mrad).{every_phase_sentence(docs)} {findings(docs)}",
    ]
    lines += [
        "",
        "The public simulators as implemented here (`studies/qube_baselines.py`; SI units):",
        "",
        baseline_table(docs),
    ]
    if any(d["name"] == "sysid" for d in docs):
        sysid_doc = next(d for d in docs if d["name"] == "sysid")
        diagnosis = next((d["diagnosis"] for d in docs if d["name"] == "diagnosed"), None)
        lines += ["", ablation_table(sysid_doc, diagnosis), "", sysid_table(sysid_doc)]
    dates = sorted({d["date"] for d in docs})
    when = dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}"
    lines += [
        "",
        f"Made by `{COMMAND}` ({when}, {summary['machine']}, {summary['cpu']}); results in "
        "[results/head_to_head/](../results/head_to_head/).",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(block_main(__file__, DOC, NAME, block))
