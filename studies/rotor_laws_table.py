"""The docs table of ``studies/rotor_laws.py`` (issue 64's rotor laws, Method step 11), generated
from its result files.

Reads ``results/rotor_laws/<experiment>__<law>__<seed>.json`` and rewrites the block between
``<!-- generated:diagnose-rotor-laws -->`` and ``<!-- /generated:diagnose-rotor-laws -->`` in
docs/diagnose.md: per log, the planted and the found cable (stiffness; the play of a moving rest,
the rest of a fixed one), Coulomb level and breakaway, their errors, the verdict of step 11 and
the held-out error ratio; then per law how many logs found it with every coefficient within
tolerance (±35 %; the play and the breakaway ±50 %), how many chose the other law, how many gained
≥ 1.4× held-out, the logs whose held-out error rose, and the false alarms on logs without cable
or friction; and the same counts on the development seeds (``results/rotor_laws_dev``, block
``diagnose-rotor-laws-dev``). ``--check`` only compares (exit 1 when the docs disagree).

    python studies/rotor_laws_table.py [--check]
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
import furuta_gym  # noqa: F401  first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
from _generated import block_main  # noqa: E402
from furuta_gym.effects import EFFECT_KINDS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rotor_laws"
DOC = ROOT / "docs" / "diagnose.md"
BLOCK, DEV_BLOCK = "diagnose-rotor-laws", "diagnose-rotor-laws-dev"
DEV = ROOT / "results" / "rotor_laws_dev"
LONG, LONG_BLOCK = ROOT / "results" / "rotor_laws_long", "diagnose-rotor-laws-long"
TOLERANCE, WIDE = 0.35, 0.50  # coefficients; the play and the breakaway
LAW_NAMES = {"moving_rest": "moving rest", "breakaway": "fixed neutral held by friction", "none": "none"}


def load(folder: Path = RESULTS) -> list[dict]:
    docs = [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))]
    order = list(LAW_NAMES)
    return sorted(docs, key=lambda d: (d["excitation"], order.index(d["law"]), d["seed"]))


def _kinds(effects, test) -> list[dict]:
    return [e for e in effects if test(EFFECT_KINDS[e["name"]])]


def rotor(effects: list[dict]) -> dict:
    """The rotor's cable (stiffness, play or rest), Coulomb level and breakaway of ``effects``
    (planted, or found: the significant ones), in the effects' own vocabulary."""
    alpha = [e for e in effects if e["joint"] == "alpha"]
    moving = _kinds(alpha, lambda k: k.has_memory and not k.on_input)
    fixed = _kinds(alpha, lambda k: k.absorbs_constant_force)
    constant = _kinds(alpha, lambda k: k.is_constant_force)
    coulomb = _kinds(alpha, lambda k: k.is_dry_friction and not k.breakaway_above)
    stiction = _kinds(alpha, lambda k: k.is_dry_friction and bool(k.breakaway_above))
    out: dict = {"cable": None}
    if moving:
        out.update(cable="moving", k=moving[0]["coefficient"], play=moving[0]["play"])
    elif fixed:
        k = fixed[0]["coefficient"]
        rest = fixed[0].get("reference") or (constant[0]["coefficient"] / k if constant else 0.0)
        out.update(cable="fixed", k=k, rest=rest)
    fc = coulomb[0]["coefficient"] if coulomb else None
    out.update(coulomb=fc, breakaway=None if fc is None else fc + (stiction[0]["coefficient"] if stiction else 0.0))
    return out


def _found(doc: dict) -> list[dict]:
    return [e for e in doc["effects"] if e["significant"]]


def errors(doc: dict) -> dict[str, float | None]:
    """Relative errors of the found rotor's coefficients against the planted (None: missing)."""
    p, f = rotor(doc["planted"]), rotor(_found(doc))
    if p["cable"] is None:
        return {}
    keys = ["k", "play" if p["cable"] == "moving" else None, "coulomb", "breakaway"]
    out = {}
    for key in filter(None, keys):
        same = key in ("coulomb", "breakaway") or f["cable"] == p["cable"]
        out[key] = f[key] / p[key] - 1.0 if same and f.get(key) is not None and p.get(key) else None
    return out


def within(errs: dict) -> bool:
    return all(v is not None and abs(v) <= (WIDE if k in ("play", "breakaway") else TOLERANCE) for k, v in errs.items())


def ratio(doc: dict) -> float:
    return doc["error_before"]["trajectory_rmse"] / doc["error_after"]["trajectory_rmse"]


def verdict(doc: dict) -> str:
    """Step 11's verdict, and whether the law it kept fixed a spring the veto had dropped."""
    laws = doc.get("rotor_laws") or []
    if not laws:
        return "-"
    fixed = any("vetoed, then fixed by" in note for note in doc["notes"])
    return laws[0]["verdict"] + (" (fixed the vetoed spring)" if fixed else "")


def _cable(r: dict) -> str:
    if r["cable"] == "moving":
        return f"{r['k']:.2g} (play {r['play']:.2f})"
    if r["cable"] == "fixed":
        return f"{r['k']:.2g} (rest {r['rest']:+.2f})"
    return "-"


def _row(doc: dict) -> str:
    p, f = rotor(doc["planted"]), rotor(_found(doc))
    fmt = lambda x: "-" if x is None else f"{x:.2g}"  # noqa: E731
    errs = ", ".join(f"{k} {'missed' if v is None else f'{100 * v:+.0f}%'}" for k, v in errors(doc).items()) or "-"
    return (
        f"| {doc['excitation']} | {LAW_NAMES[doc['law']]} | {doc['seed']} | {_cable(p)}, {fmt(p['coulomb'])}, "
        f"{fmt(p['breakaway'])} | {_cable(f)}, {fmt(f['coulomb'])}, {fmt(f['breakaway'])} | {errs} | "
        f"{verdict(doc)} | {ratio(doc):.1f}× |"
    )


def summary(docs: list[dict]) -> list[str]:
    lines = []
    for excitation in dict.fromkeys(d["excitation"] for d in docs):
        mine = [d for d in docs if d["excitation"] == excitation]
        for law in ("moving_rest", "breakaway"):
            logs = [d for d in mine if d["law"] == law]
            if not logs:
                continue
            kind = "moving" if law == "moving_rest" else "fixed"
            found = sum(rotor(_found(d))["cable"] == kind and within(errors(d)) for d in logs)
            other = sum(rotor(_found(d))["cable"] not in (None, kind) for d in logs)
            gained = sum(ratio(d) >= 1.4 for d in logs)
            named = sum(verdict(d).startswith(LAW_NAMES[law]) for d in logs)
            vetoed = sum("fixed the vetoed spring" in verdict(d) for d in logs)
            lines.append(
                f"{excitation}, {LAW_NAMES[law]}: step 11 names the law on {named} of {len(logs)} (on {vetoed} "
                f"it fixed a spring the veto had dropped); found with every coefficient within tolerance on "
                f"{found}; the other law on {other}; held-out error ≥ 1.4× lower on {gained}."
            )
        worse = [f"{LAW_NAMES[d['law']]} {d['seed']} ({ratio(d):.2f}×)" for d in mine if ratio(d) < 1.0]
        lines.append(
            f"{excitation}: held-out error higher after the diagnosis on {len(worse)} of {len(mine)}"
            + (f": {', '.join(worse)}." if worse else ".")
        )
        none = [d for d in mine if d["law"] == "none"]
        if none:
            alarms = sum(bool(_found(d)) for d in none)
            lines.append(f"{excitation}, no cable or friction: {alarms} false alarm(s) in {len(none)}.")
    return lines


def body(folder: Path = RESULTS) -> str:
    docs = load(folder)
    head = [
        "| experiment | law | seed | planted: cable, Coulomb, breakaway (N m) | found | errors | step 11 | held-out ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    return "\n".join(head + [_row(d) for d in docs] + [""] + summary(docs))


def dev_body(folder: Path = DEV) -> str:
    """The development seeds' counts (``results/rotor_laws_dev``: where step 11's choices were
    settled, never the grid's seeds), one line per law and experiment as the grid's."""
    docs = load(folder)
    spans = "; ".join(
        f"{e}, {LAW_NAMES[law]}: seeds {min(d['seed'] for d in mine)}–{max(d['seed'] for d in mine)}"
        for (e, law), mine in _groups(docs).items()
    )
    return "\n".join([f"Development seeds ({spans}):", ""] + summary(docs))


def windows(docs: list[dict]) -> list[str]:
    """Per experiment and law, the median count of validation windows whose prediction the planted
    law's fit moves by more than a count (those that can carry its evidence), where recorded."""
    lines = []
    for (excitation, law), mine in _groups(docs).items():
        if law == "none":
            continue
        counts = [
            (f["windows_changed"], f["windows_scored"])
            for d in mine
            for r in (d.get("rotor_laws") or [])[:1]
            for name, f in r["fits"].items()
            if name == LAW_NAMES[law] and f.get("windows_changed") is not None
        ]
        if counts:
            changed, scored = (statistics.median(c) for c in zip(*counts, strict=True))
            lines.append(
                f"{excitation}, {LAW_NAMES[law]}: the law's refit moves the rotor's prediction by more than a "
                f"count on a median {changed:g} of {scored:g} validation windows (the {len(counts)} logs where step 11 "
                "refitted it)."
            )
    return lines


def _groups(docs: list[dict]) -> dict[tuple, list[dict]]:
    """``docs`` by (experiment, law), in their order."""
    out: dict[tuple, list[dict]] = {}
    for d in docs:
        out.setdefault((d["excitation"], d["law"]), []).append(d)
    return out


def long_body(folder: Path = LONG) -> str:
    """Sweeps of the development rigs logged longer (``results/rotor_laws_long``): the same counts,
    and on how many windows the planted law's evidence can sit, beside the dev block's."""
    docs, dev_sweeps = load(folder), [d for d in load(DEV) if d["excitation"] == "sticky_sweep"]
    seeds = sorted({d["seed"] for d in docs})
    head = f"The development rigs' sweeps (seeds {min(seeds)}–{max(seeds)}) logged with {_segments(docs)} segments of 10 s:"
    dev = windows(dev_sweeps)
    return "\n".join(
        [head, ""]
        + summary(docs)
        + windows(docs)
        + (["", f"{_segments(dev_sweeps)} segments:", ""] + dev if dev else [])
    )


def _segments(docs: list[dict]) -> str:
    return ", ".join(str(n) for n in sorted({d["log"]["n_trajectories"] for d in docs}))


def main(argv=None) -> int:
    status = block_main(__file__, DOC, BLOCK, body, argv)
    status |= block_main(__file__, DOC, DEV_BLOCK, dev_body, argv)
    return status | block_main(__file__, DOC, LONG_BLOCK, long_body, argv)


if __name__ == "__main__":
    raise SystemExit(main())
