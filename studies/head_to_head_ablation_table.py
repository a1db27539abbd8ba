"""The table of ``studies/head_to_head_ablation.py`` (what separates the prediction-first plant
from mujoco.sysid, on held-out windows of the fit runs only), generated from its result file:
rewrites the block ``<!-- generated:head-to-head-ablation -->`` in docs/diagnose.md. ``--check``
only compares (exit 1 when the docs disagree with the results).

    python studies/head_to_head_ablation_table.py [--check]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "head_to_head" / "ablation.json"
DOC = ROOT / "docs" / "diagnose.md"
NAME = "head-to-head-ablation"


def _change(versus: dict | None) -> str:
    return "–" if versus is None else f"{-100 * versus['improvement']:+.1f} % (t {-versus['z_score']:+.1f})"


def _placed(r: dict, placement: str) -> str:
    """The held-out error and change on the windows of another placement ("–" if not scored)."""
    entry = r.get("by_placement", {}).get(placement)
    if entry is None:
        return "– | –"
    return f"{1e3 * entry['heldout_rmse']:.3f} | {_change(entry if 'improvement' in entry else None)}"


def _row(r: dict) -> str:
    folds = r["per_fold"]
    delays = ", ".join(f"{v:g}" for v in sorted({round(1e3 * f["delay"], 3) for f in folds}))
    j1b = ", ".join(f"{1e6 * f['theta']['J1b']:.1f}" for f in folds)
    return (
        f"| {r['label']} | {folds[0]['train_windows'] or '– (not refitted)'} "
        f"| **{1e3 * r['heldout_rmse']:.3f}** | {1e3 * r['fold_rmse'][2]:.3f} | {_change(r.get('vs_current'))} "
        f"| {_placed(r, 'grid')} | {_placed(r, 'starts')} | {delays} | {j1b} |"
    )


def _windows_sentence(doc: dict) -> str:
    """How many held-out windows each placement has (the same for every variant)."""
    current = doc["variants"].get("current") or next(iter(doc["variants"].values()))
    counts = {"segments": sum(len(f["sums"]) for f in current["per_fold"])}
    counts |= {p: e["windows"] for p, e in current.get("by_placement", {}).items()}
    return (
        f"Held-out windows: {counts['segments']} cut back to back from each segment's first sample (the finish's "
        f"own, as the diagnosis cuts them), {counts.get('grid', '–')} on each run's back-to-back grid from its first "
        f"sample (the head-to-head's scoring and mujoco.sysid's fit: every window starts at the same point of the "
        f"runs' 0.1 s input cycle), {counts.get('starts', '–')} starting every 10 ms (every point of that cycle "
        "alike). "
    )


def error_shares(profile, dt: float, quantisation: float) -> dict[str, float]:
    """Shares of a window's mean squared error: the encoder's rounding (``quantisation``², held),
    and a part growing like t² (a start velocity's error, a·t) and one like t⁴ (a force's,
    b·t²), a² and b² fitted to the mean square at each step (least squares)."""
    ms = np.asarray(profile, dtype=float) ** 2
    t = dt * np.arange(1, ms.size + 1)
    basis = np.stack([t**2, t**4], axis=1)
    (a2, b2), *_ = np.linalg.lstsq(basis, ms - quantisation**2, rcond=None)
    parts = {"velocity": a2 * np.mean(t**2), "force": b2 * np.mean(t**4), "rounding": quantisation**2}
    total = sum(parts.values())
    return {k: float(v / total) for k, v in parts.items()}


def _shares_sentence(o: dict, dt: float) -> str:
    pct = lambda x: f"{100 * x:.0f} %"  # noqa: E731
    out = []
    for placement, words in (("grid", "back-to-back"), ("phases", "starting every 30 ms")):
        for plant, name in (("prediction_first", "the refit"), ("sysid", "sysid's values")):
            sh = error_shares(o["profile"][placement][plant], dt, o["quantisation_rmse"])
            out.append(
                f"{name} on the windows {words}: {pct(sh['velocity'])} like t, {pct(sh['force'])} like t², "
                f"{pct(sh['rounding'])} rounding"
            )
    return (
        "Each plant's mean squared error over a window's steps fitted as the encoder's rounding plus a part "
        "growing like t (a start velocity's error) and one like t² (a force's): " + "; ".join(out) + ". "
    )


def _rotor_angle_sentence(o: dict, runs: list[int]) -> str:
    r = o.get("rotor_angle_residual")
    if r is None or "rmse_without_run_out" not in r:
        return ""
    square = ", ".join(f"{c[2]:+.2f}" for c in r["coefficients"])
    corr = ", ".join(f"{c:+.2f}" for c in r["correlation_alpha_squared"])
    per_run = ", ".join(
        f"run {runs[int(k)]} {100 * (after / before - 1):+.1f} %" for k, (before, after) in r["per_run"].items()
    )
    return (
        f"The refit's windows starting every {1e3 * o['phase_stride']:g} ms, each window's error fitted as v·t + a·t²/2: "
        f"the acceleration errors a of α and β correlate with the square of the rotor's start angle ({corr}). 1, α "
        f"and α² of that angle fitted to them per joint (α² coefficients {square} rad/s² per rad²) and that part "
        f"taken away: {1e3 * r['rmse']:.3f} → {1e3 * r['rmse_without']:.3f} mrad fitted on every run, "
        f"{1e3 * r['rmse_without_run_out']:.3f} mrad fitted for each run on the other runs ({per_run}). "
    )


def _force_sentence(o: dict) -> str:
    f = o.get("force_error_bounds")
    if f is None:
        return ""
    best = min(f["ridge"], key=lambda k: f["ridge"][k])
    return (
        f"What a better force could take from the same windows' error ({1e3 * f['rmse']:.3f} mrad): each window's "
        f"own acceleration error taken away (an oracle no plant has) leaves {1e3 * f['oracle']:.3f} mrad; the "
        "acceleration errors predicted by a smooth function of each window's start state and input, fitted for each "
        "run on the other runs (600 random Fourier features, ridge, the best penalty of "
        f"{', '.join(f['ridge'])}: {best}), leave {1e3 * f['ridge'][best]:.3f} mrad. "
    )


def _input_residual_sentence(doc: dict) -> str:
    """The sentence of ``head_to_head_ablation.py --input-residual`` ("" before it was run)."""
    r = doc.get("input_residual")
    if r is None:
        return ""
    cell = lambda c: "–" if c is None else f"{c[0]:+.2f} ± {c[1]:.2f}"  # noqa: E731
    edges = lambda b: f"{b['bin'][0]:g} to {b['bin'][1]:g}"  # noqa: E731
    by_input = "; ".join(
        f"{edges(b)} V: {cell(b['all'])} (rotor turning forward {cell(b['pos'])}, backward {cell(b['neg'])})"
        for b in r["by_input"]
        if b["all"] is not None and b["all"][2] >= 100
    )
    by_speed = "; ".join(
        f"{edges(b)} rad/s: {cell(b['all'])}" for b in r["by_speed"] if b["all"] is not None and b["all"][2] >= 100
    )
    u, v = r["on_input"], r["on_speed"]
    return (
        f"The committed prediction-first refit's rotor acceleration error without its dead band on runs 1–10 (measured − predicted; "
        f"{r['windows']} windows starting every {1e3 * r['stride']:g} ms, each window's error fitted as v·t + a·t²/2; "
        f"RMS {r['rotor_accel_rms']:.2f} rad/s²; mean ± standard error in rad/s², bins of at least 100 windows), by "
        f"the window's mean input: {by_input}. By the rotor's start speed: {by_speed}. Regressed on 1, ū, sgn ū: "
        f"sgn ū {u['coefficients'][2]:+.2f} rad/s², ū {u['coefficients'][1]:+.2f} rad/s² per V, R² {u['r2']:.3f}; "
        f"on 1, α̇, sgn α̇: sgn α̇ {v['coefficients'][2]:+.3f} rad/s², R² {v['r2']:.4f}. " + _fold_plants_sentence(r)
    )


def _fold_plants_sentence(r: dict) -> str:
    """The refit before the dead band and the dead-band variant (refitted on folds 0 and 1) on the same windows."""
    plants = r.get("fold_plants", {})
    if "staggered" not in plants or "staggered_dead_band" not in plants:
        return ""
    now, banded = plants["staggered"], plants["staggered_dead_band"]
    sign = lambda p: f"sgn ū {p['on_input']['coefficients'][2]:+.2f} rad/s², R² {p['on_input']['r2']:.4f}"  # noqa: E731
    return (
        f"Refitted on folds 0 and 1, on the same windows: the refit before the dead band {1e3 * now['rmse']:.3f} mrad ({sign(now)}), "
        f"with the dead band ({1e3 * banded['dead_band']:g} mV) {1e3 * banded['rmse']:.3f} mrad ({sign(banded)}). "
    )


def _dead_band_sentence(doc: dict) -> str:
    """The dead-band variants (the shipped finish among them) against the refit before the dead band,
    on each placement ("" before they were run)."""
    words = {"segments": "the finish's own held-out windows", "grid": "the score's grid", "starts": "every 10 ms"}
    out = []
    for name in ("finish", "staggered_dead_band", "staggered_dead_band_delay_j1b"):
        r = doc["variants"].get(name)
        if r is None or "vs_finish" not in r:
            continue
        bands = ", ".join(f"{1e3 * f['dead_band']:g}" for f in r["per_fold"])
        places = {"segments": r["vs_finish"]} | {
            p: e["vs_finish"] for p, e in r.get("by_placement", {}).items() if "vs_finish" in e
        }
        out.append(
            f'The row "{r["label"]}": its dead band per fold {bands} mV; against the refit before it ("staggered"): '
            + ", ".join(f"{words[p]} {_change(c)}" for p, c in places.items())
            + " (each passing the rule for a gain: "
            + ", ".join("yes" if c["passes_rule"] else "no" for c in places.values())
            + "). "
        )
    return "".join(out)


def _cable_laws_sentence(doc: dict) -> str:
    """Issue 64's rotor laws on runs 1–10 (``--cable-laws``; "" before it was run)."""
    r = doc.get("cable_laws")
    if r is None:
        return ""

    def law(name: str, f: dict) -> str:
        coefficients = ", ".join(f"{k} {v:.2g}" for k, v in f["effects"].items())
        cable = (
            f" and a cable of {f['cable'][0]:.2g} N m/rad with a play of {f['cable'][1]:.2g} rad"
            if f["cable"][0]
            else ""
        )
        return (
            f"the {name} ({coefficients}{cable}): validation gain {100 * f['validation_gain']:.1f} % (t "
            f"{f['validation_t']:.1f}), fold 2 {1e3 * f['heldout_rmse']:.3f} mrad"
        )

    return (
        'Issue 64\'s two rotor laws, asked on the rotor whatever the data say (`cable_laws="always"`, Method step '
        "11), each fitted by the diagnosis of runs 1–10 onto its model as diagnosed: "
        + "; ".join(law(name, f) for name, f in r["laws"].items())
        + f"; the model as diagnosed {1e3 * r['diagnosed_heldout_rmse']:.3f} mrad on fold 2 (the same windows, from "
        f"measured start states, as the diagnosis scores its own errors). Step 11's verdict: {r['verdict']} "
        f"({r['machine']}, {r['date']}). "
    )


def _oe_in_sample(doc: dict) -> str:
    """The sentences of ``head_to_head_ablation.py --oe-in-sample`` ("" before it was run)."""
    o = doc.get("oe_in_sample")
    if o is None:
        return ""
    m = lambda x: f"{1e3 * x:.3f}"  # noqa: E731
    pf, sy = "prediction_first", "sysid"
    w, refined = o["windows"], o["refined_start"]
    return (
        f"The finish's output-error fit on runs 1–10 (free: {', '.join(o['free'])}; fitted with the diagnosis' "
        f"substeps, scored with the head-to-head's 4): on its own objective ({w['finish_objective']} staggered "
        f"windows of folds 0 and 1) its refit scores {m(o['finish_objective'][pf])} mrad and sysid's values "
        f"{m(o['finish_objective'][sy])}; started from sysid's values it ends at {m(o['from_sysid']['finish_objective'])} "
        f"there and moves from {m(o['grid'][sy])} to {m(o['from_sysid']['grid'])} on the head-to-head's "
        f"{w['grid']} back-to-back windows (the refit from its own start: {m(o['grid'][pf])}). The same refit on "
        f"sysid's objective (those {w['grid']} windows) reaches {m(o['grid_fit']['from_sysid'])} from sysid's values "
        f"and {m(o['grid_fit']['from_finish_start'])} from its own start. Each window's start velocity refined by "
        f"{o['refine_steps']} Gauss-Newton steps on its own positions (an oracle that also takes up much of an error growing like t²), back-to-back windows: "
        f"the refit "
        f"{m(refined['grid'][pf])}, sysid's values {m(refined['grid'][sy])} (unrefined {m(o['grid'][pf])}, "
        f"{m(o['grid'][sy])}); {w['phases']} windows starting every {1e3 * o['phase_stride']:g} ms (every 10 ms point of the cycle alike): "
        f"{m(refined['phases'][pf])} and {m(refined['phases'][sy])} (unrefined {m(o['phases'][pf])}, "
        f"{m(o['phases'][sy])}); the encoder's count alone, as uniform rounding: {m(o['quantisation_rmse'])} mrad. "
        + (
            _shares_sentence(o, doc["window_seconds"] / len(next(iter(o["profile"]["grid"].values()))))
            if "profile" in o
            else ""
        )
        + _rotor_angle_sentence(o, doc["fit_runs"])
        + _force_sentence(o)
    )


def body(given: dict | None = None) -> str:
    doc: dict = json.loads(RESULTS.read_text()) if given is None else given
    rows = [
        "| variant | windows per refit | held-out error, both angles (mrad) | fold 2 only (mrad) "
        "| change of the sum of squares vs current | on the score's grid (mrad) | change there "
        "| starting every 10 ms (mrad) | change there | input delay (ms) | J1b per fold (1e-6 kg m²) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    rows += [_row(r) for r in doc["variants"].values()]
    finish = doc["finish_heldout_rmse"]
    ins = doc["in_sample"]
    runs = ins["per_run"].values()
    better = sum(r["sysid_in_furuta_gym"] < r["prediction_first"] for r in runs)
    phases = ins.get("every_phase")
    in_sample = (
        f"On runs 1–10 themselves with the head-to-head's scoring ({ins['n_windows']} back-to-back windows; both "
        f"fits saw them): mujoco.sysid (MJCF terms) rolled out by MuJoCo {1e3 * ins['sysid']:.3f} mrad, the same "
        f"values in furuta-gym's simulator {1e3 * ins['sysid_in_furuta_gym']:.3f}, the committed prediction-first "
        f"plant {1e3 * ins['prediction_first']:.3f}; sysid's values in furuta-gym's simulator predict better than "
        f"that plant on {better} of the {len(runs)} runs. "
    )
    if phases is not None:
        in_sample += (
            f"With windows starting every 10 ms instead ({phases['n_windows']} windows): sysid by MuJoCo "
            f"{1e3 * phases['sysid']:.3f} mrad, in furuta-gym's simulator {1e3 * phases['sysid_in_furuta_gym']:.3f}, "
            f"the prediction-first plant {1e3 * phases['prediction_first']:.3f}. "
        )
    return "\n".join(
        rows
        + [
            "",
            f"Runs {doc['fit_runs'][0]}–{doc['fit_runs'][-1]} only (runs 11–15 are not read): their 2 s segments in "
            f"{doc['folds']} folds (every third segment; fold 2 is the diagnosis' held-out set), each variant "
            f"refitted on the other folds and scored on each fold in turn, {doc['window_seconds']:g} s open-loop "
            "windows from the measured state; position RMSE of both angles over every held-out window. "
            + _windows_sentence(doc)
            + "The "
            "diagnosis refitted (found "
            f"{', '.join(doc['found'])}) is fitted on folds 0 and 1, so fold 2 is held out from it and from the "
            "refit, folds 0 and 1 from the refit only. Change: the variant's pooled sum of squares against the "
            "current finish's, with t of the per-window log ratios (negative: better; the diagnosis' rule for a "
            "gain asks ≥ 3 % and t ≥ 3). The finish itself reported "
            f"{1e3 * finish['refit']:.3f} mrad on fold 2 (diagnosed plant {1e3 * finish['diagnosed']:.3f}). "
            "The sysid rows start from, or are, mujoco.sysid's fit of every window of runs 1–10 (mapped onto the "
            "lumped parameters: its pendulum a point mass with armature, friction loss as Coulomb friction, the "
            "MJCF's back-EMF in the rotor damping): every fold was in its fit. "
            + in_sample
            + _oe_in_sample(doc)
            + _input_residual_sentence(doc)
            + _dead_band_sentence(doc)
            + _cable_laws_sentence(doc)
            + f"{doc['machine']}, {doc['date']}. From `python studies/head_to_head_ablation.py && python "
            "studies/head_to_head_ablation.py --in-sample && python studies/head_to_head_ablation.py --oe-in-sample && "
            "python studies/head_to_head_ablation.py --input-residual && python studies/head_to_head_ablation.py --cable-laws && "
            "python studies/head_to_head_ablation_table.py`.",
        ]
    )


if __name__ == "__main__":
    sys.exit(block_main(__file__, DOC, NAME, body))
