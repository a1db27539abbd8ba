"""What today's diagnosis finds on issue 64's two rotor laws: the starting point for fitting them.

Each log is simulated as a user would record it on a rig with one of the laws
(:func:`furuta_gym.diagnose.moving_rest_rig`: a cable whose rest moves, the play operator;
:func:`furuta_gym.diagnose.breakaway_rig`: a fixed cable held by a breakaway 5–10× the sliding
friction) in one of two experiments: the sticky sweeps of issue 43 (six 10 s segments) or free
releases of the rotor at 0 V (six releases of 8 s, ``excitation="rotor_releases"``). Each is
diagnosed with the default settings, as ``furuta-gym diagnose`` would. The diagnosis library holds
neither law whole (no moving rest; a stiction, but judged on its fit), so this records what it
makes of them: the effects it adds, their coefficients beside the planted ones, the held-out gain;
and what the log's rests say without a fit (:func:`furuta_gym.diagnose.rest_drift`, ``rests``).

    python studies/rotor_laws_baseline.py [--seeds 100 101]

writes ``results/rotor_laws_baseline/<experiment>__<law>__<seed>.json`` (the diagnosis's JSON
plus the planted effects); a log already written is skipped.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.diagnose import diagnose, rest_drift  # noqa: E402
from furuta_gym.rigs import breakaway_rig, measured_like, moving_rest_rig  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "rotor_laws_baseline"
LAWS = {"moving_rest": moving_rest_rig, "breakaway": breakaway_rig}
LOGS = {"sticky_sweep": dict(n_trajectories=6, duration=10.0), "rotor_releases": dict(n_trajectories=6, duration=8.0)}


def planted(effects) -> list[dict]:
    return [
        dict(
            name=e.name,
            joint=e.joint,
            coefficient=e.coefficient,
            reference=e.reference,
            **({"play": e.play} if e.play else {}),
            **({"stribeck_velocity": e.stribeck_velocity} if e.kind.is_dry_friction else {}),
        )
        for e in effects
    ]


def simulate(excitation: str, law: str, seed: int):
    effects = LAWS[law](seed)
    return effects, measured_like("furuta", effects, seed=seed, excitation=excitation, **LOGS[excitation])


def run_one(excitation: str, law: str, seed: int, out: Path) -> dict:
    target = out / f"{excitation}__{law}__{seed}.json"
    if target.exists():  # the rests' reading was added after the first diagnoses: no fit needed
        doc = json.loads(target.read_text())
        if "rests" not in doc:
            doc["rests"] = rest_drift(simulate(excitation, law, seed)[1]).to_json()
            target.write_text(json.dumps(doc, indent=1) + "\n")
        return doc
    t0 = time.time()
    effects, data = simulate(excitation, law, seed)
    doc = diagnose(data, "furuta").to_json()
    doc.update(
        excitation=excitation,
        law=law,
        seed=seed,
        log=LOGS[excitation],
        seconds=round(time.time() - t0, 1),
        rotor_repeat_share=round(float(np.mean(np.concatenate([np.diff(tr.q[:, 0]) == 0 for tr in data]))), 3),
        planted=planted(effects),
        rests=rest_drift(data).to_json(),
    )
    target.write_text(json.dumps(doc, indent=1) + "\n")
    found = [(e["name"], e["joint"], f"{e['coefficient']:.3g}") for e in doc["effects"] if e["significant"]]
    print(f"{excitation:15s} {law:12s} seed {seed}: {found} ({doc['seconds']} s)", flush=True)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 101])
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        for excitation in LOGS:
            for law in LAWS:
                run_one(excitation, law, seed, args.out)


if __name__ == "__main__":
    main()
