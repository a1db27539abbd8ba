"""Docs tables of the diagnosis, generated from the committed result files (never typed by hand).

Reads ``results/diagnose_sim/*.json``, ``results/diagnose_sim_exact_angles/*.json``,
``results/diagnose_sim_uniform_blocks/*.json``, ``results/diagnose_sim_stop_dwell/*.json`` and
``results/diagnose_sim_held_stop_off/*.json``
(``studies/diagnose_simulated.py``) and ``results/diagnose_real/`` (its JSON files and
``reference/``, ``runs/``; ``studies/diagnose_real_data.py``) and rewrites the blocks between
``<!-- generated:NAME -->`` and ``<!-- /generated:NAME -->`` in docs/diagnose.md and README.md.
``--check`` only compares (the test suite runs it: a quoted number that disagrees with its
results file fails).

    python studies/diagnose_tables.py [--check]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections import defaultdict
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import fill_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIM, REAL = ROOT / "results" / "diagnose_sim", ROOT / "results" / "diagnose_real"
EXACT = ROOT / "results" / "diagnose_sim_exact_angles"  # the closed-loop logs without quantisation
UNIFORM = ROOT / "results" / "diagnose_sim_uniform_blocks"  # the sticky sweeps, every block weighted alike
RESTS = ROOT / "results" / "diagnose_rest_bound" / "calibration.json"  # studies/rest_bound_calibration.py
DRIFT = ROOT / "results" / "cable_centre_drift" / "drift.json"  # studies/cable_centre_drift.py
MATCH = ROOT / "results" / "closed_loop_match" / "match.json"  # studies/closed_loop_match.py
# the same logs and runs with stops left out of the equation error (--stop-dwell 0.04)
STOP, REAL_STOP = ROOT / "results" / "diagnose_sim_stop_dwell", ROOT / "results" / "diagnose_real_stop_dwell"
# ... and with every stop kept (--held-stop off: the default before issue 43 left out the stops that dry
# friction held; these records were made then), and the held-stop rule's calibration
OFF, REAL_OFF = ROOT / "results" / "diagnose_sim_held_stop_off", ROOT / "results" / "diagnose_real_held_stop_off"
HELD_CALIBRATION = ROOT / "results" / "diagnose_held_stop" / "calibration.json"  # diagnose_held_stop_calibration.py


def _load(folder: Path) -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))}


def _found(doc) -> list[dict]:
    return [e for e in doc["effects"] if e["significant"]]


def _ratio(doc, key="error") -> float:
    b, a = doc[f"{key}_before"], doc[f"{key}_after"]
    return b["trajectory_rmse"] / a["trajectory_rmse"]


def _expected(planted) -> list[tuple[str, str, float]]:
    """What the diagnosis can report for the planted effects: a spring with a rest position is a
    spring plus a constant torque k·q_ref (the same force)."""
    out = []
    for p in planted:
        out.append((p["name"], p["joint"], p["coefficient"]))
        if p["name"] == "spring" and p.get("reference"):
            out.append(("constant_torque", p["joint"], p["coefficient"] * p["reference"]))
    return out


def _reported(found, name, joint):
    """The reported coefficient of ``name:joint``; an actuator lag may be the input-dynamics
    entry's equally good alternative (a delay and a lag share one first-order signature)."""
    match = next((e for e in found if (e["name"], e["joint"]) == (name, joint)), None)
    if match is not None:
        return match["coefficient"]
    if name == "actuator_lag":
        alt = next((e for e in found if e["name"] == "input_delay"), None)
        m = alt and re.search(r"actuator_lag ([0-9.e-]+) s fits as well", alt["note"])
        return float(m.group(1)) if m else None
    return None


COUNT, SAMPLE = 2 * math.pi / 2048, 0.002  # the simulated QUBE's encoder count (rad) and sample period (s)


def _unresolved(doc, name: str, coef: float) -> bool:
    """Whether a planted effect is below what the logged sensor resolves: a centre-of-mass offset
    under one encoder count (quantised logs), an input delay or lag under one sample."""
    if name == "com_offset":
        return doc.get("quantized", True) and abs(coef) < COUNT
    return name in ("input_delay", "actuator_lag") and abs(coef) < SAMPLE


def _planted_ok(doc) -> tuple[bool, list[str]]:
    """(every planted effect found and nothing else, coefficient errors) for one simulated log;
    a missing effect shows as "missed", or "not resolved" when it is below the sensor's
    resolution (not a miss)."""
    found = _found(doc)
    expected = _expected(doc["planted"])
    errs = []
    for name, joint, coef in expected:
        got = _reported(found, name, joint)
        missing = "not resolved" if _unresolved(doc, name, coef) else "missed"
        errs.append(missing if got is None else f"{got / coef - 1:+.0%}")
    complete = "missed" not in errs and len(found) <= len(expected)
    complete = complete and len(found) >= sum(e != "not resolved" for e in errs)
    return complete, errs


def sim_table(docs: dict[str, dict]) -> str:
    groups = defaultdict(list)
    for d in docs.values():
        groups[(d["excitation"], d["case"])].append(d)
    rows = [
        "| experiment | planted | logs | false alarms / all found, nothing else | coefficient error per log | held-out error ratio (min–median) |",
        "|---|---|---|---|---|---|",
    ]
    for (exc, case), ds in sorted(groups.items()):
        if case in DRAWN or _outside_library(ds[0]["planted"]):  # their own tables
            continue
        planted = (
            ", ".join(
                f"{p['name']}:{p['joint']} {p['coefficient']:g}"
                + (f" (rest {p['reference']:g})" if p.get("reference") else "")
                for p in ds[0]["planted"]
            )
            or "none"
        )
        ratios = sorted(_ratio(d) for d in ds)
        med = ratios[len(ratios) // 2]
        if not ds[0]["planted"]:
            alarms = sum(bool(_found(d)) for d in ds)
            rows.append(f"| {exc} | none | {len(ds)} | {alarms} false alarm(s) | - | {ratios[0]:.2f}–{med:.2f} |")
            continue
        checks = [_planted_ok(d) for d in ds]
        good = sum(ok for ok, _ in checks)
        names = [f"{n}:{j}" for n, j, _ in _expected(ds[0]["planted"])]
        errs = "; ".join(f"{n} " + " ".join(e[k] for _, e in checks) for k, n in enumerate(names))
        rows.append(f"| {exc} | {planted} | {len(ds)} | {good} of {len(ds)} | {errs} | {ratios[0]:.1f}–{med:.1f}× |")
    return "\n".join(rows)


DRAWN = ("sticky_cable",)  # simulated cases whose plant is drawn per log
# (effect, tolerance) judged on the sticky sweeps; the breakaway is Coulomb + stiction
STICKY_CRITERIA = (("spring", 0.35), ("coulomb_friction", 0.35), ("breakaway", 0.5))


def _sticky_values(effects) -> dict[str, float | None]:
    """Spring, its rest, Coulomb level and breakaway (Coulomb + stiction) on the rotor of a list of
    found or planted effects (dicts with name, joint, coefficient[, reference])."""
    by = {e["name"]: e["coefficient"] for e in effects if e["joint"] == "alpha"}
    spring, torque = by.get("spring"), by.get("constant_torque")
    rest = next((e.get("reference") for e in effects if e["name"] == "spring" and "reference" in e), None)
    if rest is None and spring and torque is not None:
        rest = torque / spring
    coulomb = by.get("coulomb_friction")
    breakaway = None if coulomb is None else coulomb + by.get("stiction", 0.0)
    return {"spring": spring, "rest": rest, "coulomb_friction": coulomb, "breakaway": breakaway}


def sticky_table(docs: dict[str, dict]) -> str:
    """Per sticky-sweep log: planted and found spring (rest), Coulomb level, breakaway; errors;
    then how many logs meet each criterion."""
    ds = sorted((d for d in docs.values() if d["case"] in DRAWN), key=lambda d: d["seed"])
    rows = [
        "| seed | rotor count repeated | planted: spring (rest), Coulomb, breakaway | found: spring (rest), Coulomb, breakaway | errors | else added | held-out ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    hits = {k: 0 for k, _ in STICKY_CRITERIA}
    ratio_ok = 0
    for d in ds:
        p, f = _sticky_values(d["planted"]), _sticky_values(_found(d))
        errs = []
        for key, tol in STICKY_CRITERIA:
            if f[key] is None:
                errs.append(f"{key} missed")
                continue
            err = f[key] / p[key] - 1
            hits[key] += abs(err) <= tol
            errs.append(f"{key} {err:+.0%}")
        ratio_ok += _ratio(d) >= 1.4
        extra = [
            f"{e['name']}:{e['joint']}"
            for e in _found(d)
            if (e["name"], e["joint"])
            not in {
                ("spring", "alpha"),
                ("constant_torque", "alpha"),
                ("coulomb_friction", "alpha"),
                ("stiction", "alpha"),
            }
        ]
        rows.append(
            f"| {d['seed']} | {d['rotor_repeat_share']:.0%} | {_sticky_text(p)} | {_sticky_text(f)} | {'; '.join(errs)} | "
            f"{', '.join(extra) or '-'} | {_ratio(d):.1f}× |"
        )
    n = len(ds)
    rows.append("")
    rows.append(
        f"Spring within ±35 %: {hits['spring']} of {n}; rotor Coulomb friction within ±35 %: "
        f"{hits['coulomb_friction']} of {n}; breakaway within ±50 %: {hits['breakaway']} of {n}; "
        f"held-out error ≥ 1.4× lower: {ratio_ok} of {n}."
    )
    return "\n".join(rows)


OUTSIDE_LIBRARY = ("hysteretic_spring",)  # plant effects the diagnosis library cannot express


def _outside_library(planted) -> bool:
    return any(p["name"] in OUTSIDE_LIBRARY for p in planted)


def outside_table(docs: dict[str, dict]) -> str:
    """Per log of a plant with an effect outside the library: what was added, what was reported
    inconsistent (with its gain), and the held-out ratio."""
    ds = sorted((d for d in docs.values() if _outside_library(d["planted"])), key=lambda d: (d["case"], d["seed"]))
    rows = [
        "| case | seed | planted | added | reported inconsistent (held-out gain) | held-out ratio |",
        "|---|---|---|---|---|---|",
    ]
    for d in ds:
        planted = ", ".join(
            f"{p['name']}:{p['joint']} {p['coefficient']:g}" + (f" (play {p['play']:g})" if p.get("play") else "")
            for p in d["planted"]
        )
        added = ", ".join(f"{n}:{j} ({v.rsplit(', t', 1)[0]})" for n, j, v in _merged(d)) or "none"
        odd = (
            ", ".join(
                f"{e['name']}:{e['joint']} ({e['evidence']['heldout_residual_reduction']:.0%})"
                for e in d["effects"]
                if e["status"] == "inconsistent"
            )
            or "-"
        )
        rows.append(f"| {d['case']} | {d['seed']} | {planted} | {added} | {odd} | {_ratio(d):.2f}× |")
    return "\n".join(rows)


def drift_table(doc: dict) -> str:
    """The oscillation's centre every 5 s after the swing, per simulated cable."""
    n = max(len(r["centre_every_5s"]) for r in doc["rigs"].values())
    rows = ["| cable | " + " | ".join(f"{5 * k}–{5 * k + 5} s" for k in range(n)) + " |", "|---" * (n + 1) + "|"]
    for name, r in doc["rigs"].items():
        rows.append(f"| {name} | " + " | ".join(f"{c:+.2f}" for c in r["centre_every_5s"]) + " |")
    return "\n".join(rows)


def rest_bound_table(doc: dict) -> str:
    """The rests' breakaway bound (true model) over the Coulomb level and over the breakaway."""
    rows = [
        "| log | seed | Coulomb (N m) | breakaway (N m) | rest windows | held (N m) | held / Coulomb | held / breakaway |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["rows"]:
        kind = f"{r['excitation']}, " + ("stiction" if r["stiction"] else "no stiction")
        rows.append(
            f"| {kind} | {r['seed']} | {r['coulomb']:.2g} | {r['breakaway']:.2g} | {r['windows']} | "
            f"{r['held']:.2g} | {r['held_over_coulomb']:.2f} | {r['held_over_breakaway']:.2f} |"
        )
    return "\n".join(rows)


def held_stop_table(doc: dict) -> str:
    """Per experiment: the stops' largest free excursion, and which stops the rule leaves out
    against whether the simulator's rotor stood still (``held`` in the file: under 0.01 rad/s
    for most of the stop)."""
    groups = defaultdict(list)
    for r in doc["rows"]:
        groups[(r["excitation"], r["case"])].append(r)
    rows = [
        "| experiment | case | logs | stops | largest free excursion (counts) | still in the simulator | "
        f"of them left out (> {doc['held_stop']:g} counts) | their share of the still samples | others left out |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (exc, case), rs in groups.items():
        held, samples = sum(r["held"] for r in rs), sum(r["held_samples"] for r in rs)
        share = f"{sum(r['held_samples_left_out'] for r in rs) / samples:.0%}" if samples else "-"
        rows.append(
            f"| {exc} | {case} | {len(rs)} | {sum(r['stops'] for r in rs)} | {max(r['max_excursion'] for r in rs):.2f} | "
            f"{held} | {sum(r['held_left_out'] for r in rs)} | {share} | {sum(r['moving_left_out'] for r in rs)} |"
        )
    return "\n".join(rows)


def _g(v) -> str:
    return "-" if v is None else f"{v:.2g}"


def _sticky_text(v: dict) -> str:
    rest = "" if v["rest"] is None else f" ({v['rest']:+.2f})"
    return f"{_g(v['spring'])}{rest}, {_g(v['coulomb_friction'])}, {_g(v['breakaway'])}"


def _effects_text(doc) -> str:
    return "; ".join(f"{n}:{j} ({v})" for n, j, v in _merged(doc)) or "none"


def real_table(docs: dict[str, dict]) -> str:
    rows = [
        "| fit on | judged on (never fitted) | found (coefficient, t) | held-out windows: before → after | unseen runs: before → after |",
        "|---|---|---|---|---|",
    ]
    for name, d in docs.items():
        fit = f"runs {min(d['fit_runs'])}–{max(d['fit_runs'])}"
        test = f"runs {', '.join(map(str, d['test_runs']))}" if d["test_runs"] else "-"
        held = f"{d['error_before']['trajectory_rmse']:.4f} → {d['error_after']['trajectory_rmse']:.4f} rad ({_ratio(d):.2f}×)"
        unseen = (
            (
                f"{d['test_error_before']['trajectory_rmse']:.4f} → {d['test_error_after']['trajectory_rmse']:.4f} rad "
                f"({_ratio(d, 'test_error'):.2f}×)"
            )
            if d.get("test_error_before")
            else "-"
        )
        rows.append(
            f"| {fit} ({name.split('_')[0]}) | {test if len(test) < 30 else 'the other ' + str(len(d['test_runs']))} | {_effects_text(d)} | {held} | {unseen} |"
        )
    return "\n".join(rows)


def _merged(doc) -> list[tuple[str, str, str]]:
    """(effect, joint, value text) of the found effects; a spring and a constant torque on one
    joint are one spring with a rest position τ0/k (the same force)."""
    found = _found(doc)
    springs = {e["joint"]: e for e in found if e["name"] == "spring" and e["coefficient"] > 0}
    out = []
    for e in found:
        if e["name"] == "constant_torque" and e["joint"] in springs:
            continue
        text = f"{e['coefficient']:.2g} {e['unit']}"
        torque = next((t for t in found if t["name"] == "constant_torque" and t["joint"] == e["joint"]), None)
        if e["name"] == "spring" and e["joint"] in springs and torque:
            text += f", rest {torque['coefficient'] / e['coefficient']:+.2g} rad"
        if not e.get("resolved", True):
            text += ", not resolved"
        out.append((e["name"], e["joint"], text + f", t {e['evidence']['z_score']:.1f}"))
    return out


def _found_text(doc) -> str:
    return ", ".join(f"{n.replace('_', ' ')} on {j} ({v.rsplit(', t', 1)[0]})" for n, j, v in _merged(doc)) or "nothing"


def agreement_table(docs: dict[str, dict]) -> str:
    """Each effect found on any independent split: its coefficient per split, and the spread."""
    splits = {k: d for k, d in docs.items() if k.startswith("split_")}
    keys = sorted({(n, j) for d in splits.values() for n, j, _ in _merged(d)})
    rows = [
        "| effect | "
        + " | ".join(f"runs {min(d['fit_runs'])}–{max(d['fit_runs'])}" for d in splits.values())
        + " | largest / smallest (resolved) |",
        "|---" * (len(splits) + 2) + "|",
    ]
    for name, joint in keys:
        found = [
            next((e for e in _found(d) if (e["name"], e["joint"]) == (name, joint)), None) for d in splits.values()
        ]
        got = [e["coefficient"] for e in found if e is not None and e.get("resolved", True)]
        if len({v > 0 for v in got}) > 1:
            spread = "signs differ"
        else:
            spread = f"{max(map(abs, got)) / min(map(abs, got)):.2f}" if len(got) > 1 else "-"
        cells = [
            "not found"
            if e is None
            else f"{e['coefficient']:.2g}" + ("" if e.get("resolved", True) else " (not resolved)")
            for e in found
        ]
        rows.append(f"| {name}:{joint} | " + " | ".join(cells) + f" | {spread} |")
    return "\n".join(rows)


def per_run_table(record: dict, docs: dict[str, dict]) -> str:
    """Per run: which independent split holds it, how far its rotor wandered, its spring alone."""
    split_of = {
        r: f"{min(d['fit_runs'])}–{max(d['fit_runs'])}"
        for k, d in docs.items()
        if k.startswith("split_")
        for r in d["fit_runs"]
    }
    far = record["far_rad"]
    rows = [
        f"| run | split | rotor angle range (rad) | RMS angle (rad) | time beyond ±{far:g} rad (s) | "
        "spring:alpha on this run alone (N m/rad, t) |",
        "|---|---|---|---:|---:|---|",
    ]
    for r in record["runs"]:
        sp = r["spring_alone"]
        added = " found" if sp["status"] == "selected" else ""
        rows.append(
            f"| {r['run']} | {split_of.get(r['run'], '-')} | {r['alpha_min']:+.2f} … {r['alpha_max']:+.2f} | "
            f"{r['alpha_rms']:.2f} | {r['seconds_beyond_far']:.1f} | {sp['coefficient']:.2g}, t {sp['t']:.1f}{added} |"
        )
    return "\n".join(rows)


def reference_table(split: dict, refs: dict[str, dict], target: float = 1.25) -> str:
    """Runs 1–5's prediction of runs 6–15 beside models of runs 6–15 fitted on themselves."""
    before = split["test_error_before"]["trajectory_rmse"]
    err = lambda d: d["test_error_after"]["trajectory_rmse"]  # noqa: E731
    rows = [
        "| model | fitted on | candidates | found | error on runs 6–15 (rad) |",
        "|---|---|---|---|---|",
        f"| declared | runs 1–5 | - | - | {before:.4f} |",
        f"| {target}× lower than the declared model | | | | {before / target:.4f} |",
        f"| runs 1–5's diagnosis (a prediction) | runs 1–5 | the library | {_found_text(split)} | "
        f"{err(split):.4f} ({before / err(split):.2f}×) |",
    ]
    for d in refs.values():
        cands = ", ".join(d["candidates"]) if d.get("candidates") else "the library"
        rows.append(
            f"| in-sample reference | runs 6–15 | {cands} | {_found_text(d)} | {err(d):.4f} ({before / err(d):.2f}×) |"
        )
    return "\n".join(rows)


def readme_line(docs: dict[str, dict]) -> str:
    """The README's real-data sentence: the fit on all fifteen runs (the README's command), then
    the independent thirds as its stability check."""
    d = docs["growing_runs01-15"]
    text = (
        f"Fitted on all 15 runs it finds {_found_text(d)}; on held-out segments of those runs, never "
        f"fitted, the open-loop error (0.1 s windows) falls {d['error_before']['trajectory_rmse']:.4f} → "
        f"{d['error_after']['trajectory_rmse']:.4f} rad (**{_ratio(d):.2f}×**)."
    )
    text += " Fitted on each third alone, as a stability check (judged on the ten runs it never saw):"
    for k in ("split_runs01-05", "split_runs06-10", "split_runs11-15"):
        o = docs[k]
        text += f" runs {min(o['fit_runs'])}–{max(o['fit_runs'])}: {_found_text(o)}, {_ratio(o, 'test_error'):.2f}×;"
    return text.rstrip(";") + "."


def match_table(doc: dict, real: dict) -> str:
    """The simulated closed loop beside the shipped runs, and the planted pendulum friction."""
    stats, cols = doc["statistics"], ["real runs 1–10", "default", "matched"]
    head = "| | shipped runs 1–10 | simulated, as it is | simulated, matched |\n|---|---|---|---|"
    rows = [
        ("u std (V)", lambda s: f"{s['u_std']:.2f}"),
        ("u power above 30 Hz", lambda s: f"{s['u_power_above_30hz']:.1%}"),
        ("u power 5–30 Hz", lambda s: f"{s['u_power_5_30hz']:.1%}"),
        ("pendulum count repeated", lambda s: f"{s['beta_repeats']:.0%}"),
        ("pendulum steps of ≥ 2 counts", lambda s: f"{s['beta_steps_of_2_or_more']:.1%}"),
        ("u on α, α̇, β − π, β̇ (V/rad, V·s/rad)", lambda s: ", ".join(f"{v:.2f}" for v in s["regression"].values())),
        ("that regression's R²", lambda s: f"{s['regression_r2']:.2f}"),
    ]
    lines = [head] + [f"| {label} | " + " | ".join(fmt(stats[c]) for c in cols) + " |" for label, fmt in rows]
    planted = doc["planted"]
    found = []
    for name, label in (("default", "as it is"), ("matched", "matched")):
        probes = [p for p in doc["probes"] if p["experiment"] == name]
        hits = [p for p in probes if p["status"] == "selected"]
        sizes = ", ".join(f"{p['coefficient']:.3g} (t {p['t']:.1f})" for p in probes)
        found.append(f"{label}: found on {len(hits)} of {len(probes)} logs ({sizes})")
    fit = real.get("growing_runs01-10")
    on_real = ""
    if fit:
        ev = next(e for e in fit["effects"] if (e["name"], e["joint"]) == (planted["name"], planted["joint"]))
        on_real = f" On the shipped runs 1–10 the same test fits {ev['coefficient']:.2g} N m ({ev['status']})."
    return (
        "\n".join(lines)
        + f"\n\nA pendulum Coulomb friction of {planted['coefficient']:g} N m planted, diagnosed with the real"
        + " runs' recipe: "
        + "; ".join(found)
        + "."
        + on_real
        + f" Experiments: `{doc['experiments']['matched']}` (matched); made by `python studies/closed_loop_match.py`"
        + f" ({doc['date']})."
    )


def blocks() -> dict[str, str]:
    real = _load(REAL)
    return {**_simulated_blocks(), **_real_blocks(real), **_single_file_blocks(real)}


def _simulated_blocks() -> dict[str, str]:
    """The simulated grids' tables, each from its results folder when it exists."""
    sim, out = _load(SIM), {}
    if sim:
        out["diagnose-sim"] = sim_table(sim)
        if any(d["case"] in DRAWN for d in sim.values()):
            out["diagnose-sim-sticky"] = sticky_table(sim)
        if any(_outside_library(d["planted"]) for d in sim.values()):
            out["diagnose-sim-outside"] = outside_table(sim)
    if uniform := _load(UNIFORM):
        out["diagnose-sim-sticky-uniform"] = sticky_table(uniform)
    if exact := _load(EXACT):
        out["diagnose-sim-exact-angles"] = sim_table(exact)
    if stop := _load(STOP):
        out["diagnose-sim-stop-dwell"] = sim_table(stop) + "\n\nThe sticky sweeps:\n\n" + sticky_table(stop)
    if held_off := _load(OFF):
        out["diagnose-sim-held-stop-off"] = sim_table(held_off) + "\n\nThe sticky sweeps:\n\n" + sticky_table(held_off)
    return out


def _real_blocks(real: dict) -> dict[str, str]:
    """The real runs' tables and README lines (the default study and its variants)."""
    out = {}
    if real:
        out["diagnose-real"] = real_table(real) + "\n\nAcross the independent splits:\n\n" + agreement_table(real)
        out["diagnose-real-readme"] = readme_line(real)
    refs = _load(REAL / "reference")
    if refs and "split_runs01-05" in real:
        out["diagnose-real-reference"] = reference_table(real["split_runs01-05"], refs)
    if real_stop := _load(REAL_STOP):
        out["diagnose-real-stop-dwell"] = readme_line(real_stop)
    if real_held_off := _load(REAL_OFF):
        out["diagnose-real-held-stop-off"] = readme_line(real_held_off)
    runs = REAL / "runs" / "per_run.json"
    if runs.exists():
        out["diagnose-real-runs"] = per_run_table(json.loads(runs.read_text()), real)
    return out


def _single_file_blocks(real: dict) -> dict[str, str]:
    """The tables made from one JSON file each."""
    out = {}
    if DRIFT.exists():
        out["diagnose-cable-drift"] = drift_table(json.loads(DRIFT.read_text()))
    if MATCH.exists():
        out["diagnose-closed-loop-match"] = match_table(json.loads(MATCH.read_text()), real)
    if RESTS.exists():
        out["diagnose-rest-bound"] = rest_bound_table(json.loads(RESTS.read_text()))
    if HELD_CALIBRATION.exists():
        out["diagnose-held-stop-calibration"] = held_stop_table(json.loads(HELD_CALIBRATION.read_text()))
    return out


def render(text: str, generated: dict[str, str]) -> str:
    for name, body in generated.items():  # each file holds some of the blocks
        text = fill_block(text, name, body, required=False)
    return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = ap.parse_args()
    generated, stale = blocks(), []
    for path in (ROOT / "docs" / "diagnose.md", ROOT / "README.md"):
        text = path.read_text()
        new = render(text, generated)
        if new != text:
            stale.append(str(path.relative_to(ROOT)))
            if not args.check:
                path.write_text(new)
    if args.check and stale:
        print(f"out of date with results/: {stale}; run python studies/diagnose_tables.py")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
