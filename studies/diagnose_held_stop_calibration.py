"""Calibrating the held-stop rule (``DiagnosisSettings.held_stop``) on simulated logs.

A stop is a run of at least 40 ms on one rotor count. Its free excursion is how far the declared
model's forces other than dry friction would have moved a free rotor over it (the least range
over every start velocity, in counts; ``furuta_gym.diagnose.stop_excursions``): a free joint
through a reversal or a slow pass stays within one count, so on logs without dry friction every
stop's excursion is at most about one. The threshold is set above what those logs show; the logs
with dry friction only show what it then leaves out, against whether the simulator's rotor stood
still (``held`` in the file: its speed under 0.01 rad/s, a count per 0.3 s, for most of the stop;
a free rotor reversing under a weak force can be that slow too). The grid's logs and
seeds (``studies/diagnose_simulated.py``); velocities estimated as the diagnosis estimates them.

    python studies/diagnose_held_stop_calibration.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

sys.path.insert(0, str(Path(__file__).resolve().parent))
from diagnose_simulated import simulate  # noqa: E402
from furuta_gym.data import Trajectory  # noqa: E402
from furuta_gym.diagnose import DiagnosisSettings, layout_for, stop_excursions  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "diagnose_held_stop"
SEEDS = range(100, 110)
NO_FRICTION = [("sine_sweep", "none"), ("closed_loop_prbs", "none"), ("sticky_sweep", "none")]
WITH_FRICTION = [
    ("sticky_sweep", "sticky_cable"),
    ("sine_sweep", "cable_stiction"),
    ("sine_sweep", "spring_dry_friction"),
    ("closed_loop_prbs", "coulomb_com_lag"),
]
HELD_SPEED = 0.01  # rad/s: the simulator's rotor held (a count per 0.3 s at most)


def _log(excitation: str, case: str, seed: int, held_stop: float) -> dict:
    _, data, _ = simulate(excitation, case, seed, true_velocities=True)
    layout = layout_for("furuta")
    logged = [Trajectory(t=tr.t, q=tr.q, u=tr.u, qd=None, name=tr.name) for tr in data]
    stops = stop_excursions(logged, "alpha", layout, layout.nominal())
    speed = {tr.name: np.abs(tr.qd[:, 0]) for tr in data}
    held = [float(np.mean(speed[s.trajectory][s.start : s.start + s.samples] < HELD_SPEED)) > 0.5 for s in stops]
    out = [s.excursion > held_stop for s in stops]
    return {
        "excitation": excitation,
        "case": case,
        "seed": seed,
        "stops": len(stops),
        "max_excursion": max((s.excursion for s in stops), default=0.0),
        "held": int(sum(held)),
        "held_left_out": int(sum(h and o for h, o in zip(held, out, strict=True))),
        "moving_left_out": int(sum(o and not h for h, o in zip(held, out, strict=True))),
        "held_samples": int(sum(s.samples for s, h in zip(stops, held, strict=True) if h)),
        "held_samples_left_out": int(sum(s.samples for s, h, o in zip(stops, held, out, strict=True) if h and o)),
    }


def main() -> None:
    held_stop = 2.0  # the threshold under test (counts)
    rows = []
    for excitation, case in NO_FRICTION + WITH_FRICTION:
        for seed in SEEDS:
            rows.append(_log(excitation, case, seed, held_stop))
            r = rows[-1]
            print(
                f"{excitation:16s} {case:20s} {seed}: {r['stops']} stops, max excursion {r['max_excursion']:.2f}, "
                f"held {r['held']} (left out {r['held_left_out']}), moving left out {r['moving_left_out']}",
                flush=True,
            )
    OUT.mkdir(parents=True, exist_ok=True)
    doc = {
        "held_stop": held_stop,
        "min_stop_seconds": 0.04,
        "held_speed": HELD_SPEED,
        "velocity": DiagnosisSettings().reading.velocity,
        "rows": rows,
    }
    (OUT / "calibration.json").write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
