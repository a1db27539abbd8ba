"""Which cable matches a rotor that keeps oscillating off the cable's neutral?

A real open-loop sweep showed a rotor that, after swings of about ±2 rad, oscillated for some 40 s
around a centre 0.35–0.45 rad from where it rests otherwise, never returning towards it. Two
simulated rigs, the same dry friction (Coulomb 5e-4 N m, breakaway 1e-3 N m) and cable stiffness
(2e-3 N m/rad), the same input (a 1 V, 0.5 Hz swing for 4 s, then 0.5 V at 1.5 Hz for 40 s):

* a **fixed cable** (``spring``, neutral at 0): while the rotor oscillates its friction changes
  sign each half period and averages out, so the spring pulls the centre back to the neutral;
* a **cable whose neutral is dragged along** (``hysteretic_spring``, play 0.3 rad): the swing
  leaves the neutral off zero and the oscillation stays around it.

Writes ``results/cable_centre_drift/drift.json``: the oscillation's centre (mean rotor angle over
each 5 s) for each rig; ``studies/diagnose_tables.py`` makes the docs table.

    python studies/cable_centre_drift.py
"""

from __future__ import annotations

import json
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.envs import MujocoBackend  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "cable_centre_drift"
DT, SUBSTEPS = 0.002, 10
FRICTION = [Effect("coulomb_friction", "alpha", 5e-4), Effect("stiction", "alpha", 5e-4)]
RIGS = {
    "fixed cable": [Effect("spring", "alpha", 2e-3)] + FRICTION,
    "dragged neutral": [Effect("hysteretic_spring", "alpha", 2e-3, play=0.3)] + FRICTION,
}
SWING, CREEP = 4.0, 40.0  # s


def voltage(t: np.ndarray) -> np.ndarray:
    return np.where(t < SWING, 1.0 * np.sin(2 * np.pi * 0.5 * t), 0.5 * np.sin(2 * np.pi * 1.5 * (t - SWING)))


def centres(effects) -> list[float]:
    """Mean rotor angle over each 5 s of the oscillation after the swing."""
    plant = MujocoBackend("furuta", SUBSTEPS, effects, timestep=DT / SUBSTEPS)
    plant.reset(np.zeros(4))
    t = np.arange(int(round((SWING + CREEP) / DT))) * DT
    alpha = np.array([plant.step(np.array([u]))[0] for u in voltage(t)])
    after = alpha[t >= SWING]
    per = int(round(5.0 / DT))
    return [float(np.mean(after[k : k + per])) for k in range(0, after.size - per + 1, per)]


def main() -> None:
    doc = {
        "dt": DT,
        "swing_seconds": SWING,
        "oscillation_seconds": CREEP,
        "rigs": {
            name: {
                "effects": [dict(name=e.name, coefficient=e.coefficient, play=e.play) for e in effects],
                "centre_every_5s": centres(effects),
            }
            for name, effects in RIGS.items()
        },
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "drift.json").write_text(json.dumps(doc, indent=1) + "\n")
    for name, r in doc["rigs"].items():
        print(f"{name:16s} centre every 5 s: " + " ".join(f"{c:+.3f}" for c in r["centre_every_5s"]))


if __name__ == "__main__":
    main()
