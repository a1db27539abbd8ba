"""Calibrating the breakaway bound from rests (``furuta_gym.diagnose.held_at_rest``) on simulated logs.

For logs whose rotor has dry friction with no stiction (open-loop sine sweeps with a cable spring
and Coulomb friction of 4e-4 or 8e-4 N m) and for sticky sweeps with a breakaway 2–3× the Coulomb
level (``sticky_rig``), the largest force the rests held the rotor against, computed with the TRUE
model (so that only the bound itself is judged), over the Coulomb level and over the breakaway.
The diagnosis adds a stiction from rests when the bound exceeds ``min_breakaway_ratio`` × the
fitted Coulomb level: the no-stiction logs set that ratio. Writes
``results/diagnose_rest_bound/calibration.json``; ``studies/diagnose_tables.py`` makes the
docs table.

    python studies/rest_bound_calibration.py
"""

from __future__ import annotations

import json
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.diagnose import DiagnosisSettings, held_at_rest, layout_for  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.rigs import measured_like, sticky_rig  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "diagnose_rest_bound"
COUNT = 2 * np.pi / 2048
SEEDS = (100, 101, 102)
LOG = dict(n_trajectories=6, duration=10.0)


def _bound(effects, excitation: str, seed: int) -> dict:
    """The rests' bound on one simulated log, computed with the true model."""
    layout = layout_for("furuta")
    theta = layout.nominal()
    for e in effects:
        if e.name in ("spring", "coulomb_friction", "stiction"):
            theta[layout.index(f"{e.name}:{e.joint}")] = e.coefficient
        if e.name == "spring" and e.reference:
            theta[layout.index("constant_torque:alpha")] = e.coefficient * e.reference
    log = measured_like("furuta", effects, excitation=excitation, seed=seed, **LOG)
    b = held_at_rest(log, "alpha", layout, theta, window=DiagnosisSettings().rests.rest_window, count=COUNT)
    by = {e.name: e.coefficient for e in effects}
    breakaway = by["coulomb_friction"] + by.get("stiction", 0.0)
    return {
        "excitation": excitation,
        "seed": seed,
        "coulomb": by["coulomb_friction"],
        "breakaway": breakaway,
        "held": b.held,
        "windows": b.n_windows,
        "slack": b.slack,
        "held_over_coulomb": b.held / by["coulomb_friction"],
        "held_over_breakaway": b.held / breakaway,
    }


def main() -> None:
    rows = []
    for coulomb in (4e-4, 8e-4):
        effects = [Effect("spring", "alpha", 1.5e-3), Effect("coulomb_friction", "alpha", coulomb)]
        rows += [dict(_bound(effects, "sine_sweep", s), stiction=False) for s in SEEDS]
    rows += [dict(_bound(sticky_rig(s), "sticky_sweep", s), stiction=True) for s in SEEDS]
    OUT.mkdir(parents=True, exist_ok=True)
    doc = {"window_seconds": DiagnosisSettings().rests.rest_window, "count_rad": COUNT, "rows": rows}
    (OUT / "calibration.json").write_text(json.dumps(doc, indent=1) + "\n")
    for r in rows:
        print(
            f"{r['excitation']:13s} seed {r['seed']}: held {r['held']:.3g} = {r['held_over_coulomb']:.2f}x Coulomb, "
            f"{r['held_over_breakaway']:.2f}x breakaway ({r['windows']} windows)"
        )


if __name__ == "__main__":
    main()
