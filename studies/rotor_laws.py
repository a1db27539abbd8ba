"""Issue 64's two rotor laws in the diagnosis (Method step 11): found, told apart, on simulated logs.

Each log is simulated on a rig with one law (:func:`furuta_gym.diagnose.moving_rest_rig`: a cable
whose rest moves; :func:`furuta_gym.diagnose.breakaway_rig`: a fixed cable held by a breakaway
5–10× its sliding friction; ``none``: neither cable nor friction) in one of two experiments: 0 V
releases (``excitation="rotor_releases"``, ``--releases`` releases of ``--seconds`` s) or the
sticky sweeps of issue 43 (``--sweep-segments`` 10 s segments, six by default). Each is diagnosed with the default settings, as
``furuta-gym diagnose`` would; the JSON is the diagnosis's (its ``rotor_laws`` entry says which
law the data support and why) plus the planted effects.

    python studies/rotor_laws.py [--seeds 100 101] [--experiments rotor_releases] [--laws moving_rest breakaway none]
        [--sweep-segments 6] [--out results/rotor_laws]

writes ``results/rotor_laws/<experiment>__<law>__<seed>.json``; a log already written is skipped.
``studies/rotor_laws_table.py`` summarises them (found in how many, coefficient errors, held-out
gains, the other law selected, false alarms).
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

from furuta_gym.diagnose import diagnose  # noqa: E402
from furuta_gym.rigs import breakaway_rig, measured_like, moving_rest_rig  # noqa: E402
from rotor_laws_baseline import planted  # noqa: E402  the same record of the planted effects

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "rotor_laws"
LAWS = {"moving_rest": moving_rest_rig, "breakaway": breakaway_rig, "none": lambda seed: []}


def logs(releases: int, seconds: float, sweep_segments: int = 6) -> dict[str, dict]:
    return {
        "rotor_releases": dict(n_trajectories=releases, duration=seconds),
        "sticky_sweep": dict(n_trajectories=sweep_segments, duration=10.0),
    }


def run_one(excitation: str, law: str, seed: int, log: dict, out: Path) -> dict:
    target = out / f"{excitation}__{law}__{seed}.json"
    if target.exists():
        return json.loads(target.read_text())
    t0 = time.time()
    effects = LAWS[law](seed)
    data = measured_like("furuta", effects, seed=seed, excitation=excitation, **log)
    res = diagnose(data, "furuta")
    doc = res.to_json()
    doc.update(
        excitation=excitation,
        law=law,
        seed=seed,
        log=log,
        seconds=round(time.time() - t0, 1),
        rotor_repeat_share=round(float(np.mean(np.concatenate([np.diff(tr.q[:, 0]) == 0 for tr in data]))), 3),
        planted=planted(effects),
    )
    target.write_text(json.dumps(doc, indent=1) + "\n")
    found = [(e["name"], f"{e['coefficient']:.3g}") for e in doc["effects"] if e["significant"]]
    verdicts = [r["verdict"] for r in doc.get("rotor_laws", [])]
    print(f"{excitation:15s} {law:12s} seed {seed}: {found} {verdicts} ({doc['seconds']} s)", flush=True)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(100, 110)))
    ap.add_argument("--experiments", nargs="+", default=["rotor_releases"], choices=["rotor_releases", "sticky_sweep"])
    ap.add_argument("--laws", nargs="+", default=list(LAWS), choices=list(LAWS))
    ap.add_argument("--releases", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--sweep-segments", type=int, default=6, help="10 s segments per sweep log")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        for excitation in args.experiments:
            for law in args.laws:
                run_one(
                    excitation, law, seed, logs(args.releases, args.seconds, args.sweep_segments)[excitation], args.out
                )


if __name__ == "__main__":
    main()
