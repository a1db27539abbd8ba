"""Does the simulated closed loop look like the shipped QUBE runs, and does it matter for the
pendulum's dry friction?

The diagnosis of the shipped runs tests a Coulomb friction on the pendulum and fits it negative,
while on the simulated balancing experiment (``measured_like(..., excitation="closed_loop_prbs")``)
it finds a planted one. Is the simulated experiment too unlike the real one? Statistics of the
shipped runs 1–10 (the diagnosis' fit runs; 0.5 s start dropped) beside the simulated closed
loop, as it is (:class:`~furuta_gym.diagnose.ClosedLoopBalancing` defaults) and a variant chosen
by hand to match those statistics (:data:`MATCHED`): the input's spread and spectrum, the
pendulum's encoder (share of samples that repeat the count, of steps of two counts or more), and
one linear regression of u on (α − mean, α̇, β − π, β̇), velocities a 20 rad/s filtered
difference of the angles, the same estimator on both (the references and feed-forward it leaves
out bias both alike). Then the diagnosis with the real runs' recipe (0.1 s windows, 64
output-error windows) on each experiment with a pendulum Coulomb friction of 1e-4 N·m planted.

Writes ``results/closed_loop_match/match.json``; ``studies/diagnose_tables.py`` makes the docs
table.

    python studies/closed_loop_match.py [--seeds 100 101 102] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.datasets import load_qube_closed_loop  # noqa: E402
from furuta_gym.diagnose import diagnose  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.rigs import ClosedLoopBalancing, measured_like  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "results" / "closed_loop_match"
FIT_RUNS, SKIP = list(range(1, 11)), 0.5
COUNT = 2 * np.pi / 2048
#: the simulated experiment, as it is and matched by hand to the shipped runs' statistics
EXPERIMENTS = {
    "default": ClosedLoopBalancing(),
    "matched": ClosedLoopBalancing(velocity_cutoff=30.0, pendulum_reference=0.04),
}
MATCHED = EXPERIMENTS["matched"]
PLANTED = Effect("coulomb_friction", "beta", 1e-4)
LOG = dict(n_trajectories=6, duration=10.0)
RECIPE = dict(window=0.1, oe_max_windows=64)


def _filtered_velocities(q: np.ndarray, dt: float, cutoff: float = 20.0) -> np.ndarray:
    s, v, out = 1.0 - np.exp(-cutoff * dt), np.zeros(q.shape[1]), np.empty_like(q)
    for k in range(len(q)):
        if k:
            v = v + s * ((q[k] - q[k - 1]) / dt - v)
        out[k] = v
    return out


def statistics(trajs) -> dict:
    """The input's and the pendulum encoder's statistics, and the regression of u on the state."""
    stds, above30, band, repeats, jumps, rows, us = [], [], [], [], [], [], []
    for tr in trajs:
        q, u, dt = np.asarray(tr.q), np.asarray(tr.u)[:, 0], tr.dt
        spectrum = np.abs(np.fft.rfft((u - u.mean()) * np.hanning(len(u)))) ** 2
        f = np.fft.rfftfreq(len(u), dt)
        total = spectrum[f > 0.2].sum()
        stds.append(u.std())
        above30.append(spectrum[f > 30].sum() / total)
        band.append(spectrum[(f > 5) & (f <= 30)].sum() / total)
        steps = np.abs(np.diff(np.round(q[:, 1] / COUNT)))
        repeats.append(np.mean(steps == 0))
        jumps.append(np.mean(steps >= 2))
        v = _filtered_velocities(q, dt)
        tilt = (q[:, 1] - np.pi + np.pi) % (2 * np.pi) - np.pi
        rows.append(np.column_stack([q[:, 0] - q[:, 0].mean(), v[:, 0], tilt, v[:, 1], np.ones(len(q))]))
        us.append(u)
    X, y = np.vstack(rows), np.concatenate(us)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r2 = 1.0 - np.var(y - X @ coef) / np.var(y)
    return {
        "u_std": float(np.mean(stds)),
        "u_power_above_30hz": float(np.mean(above30)),
        "u_power_5_30hz": float(np.mean(band)),
        "beta_repeats": float(np.mean(repeats)),
        "beta_steps_of_2_or_more": float(np.mean(jumps)),
        "regression": dict(zip(("alpha", "alpha_dot", "beta_minus_pi", "beta_dot"), map(float, coef[:4]), strict=True)),
        "regression_r2": float(r2),
    }


def probe(name: str, seed: int) -> dict:
    """The diagnosis on experiment ``name`` with the pendulum's Coulomb friction planted."""
    data = measured_like("furuta", [PLANTED], excitation=EXPERIMENTS[name], seed=seed, **LOG)
    res = diagnose(data, "furuta", **RECIPE)
    ev = next(e for e in res.effects if (e.name, e.joint) == (PLANTED.name, PLANTED.joint))
    return {
        "experiment": name,
        "seed": seed,
        "status": ev.status,
        "coefficient": ev.coefficient,
        "improvement": ev.improvement,
        "t": ev.z_score,
        "found": [f"{e.name}:{e.joint}" for e in res.found],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[100, 101, 102])
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args()
    real = load_qube_closed_loop(FIT_RUNS, skip_seconds=SKIP)
    rows = {"real runs 1–10": statistics(real)}
    for name, experiment in EXPERIMENTS.items():
        rows[name] = statistics(measured_like("furuta", excitation=experiment, seed=args.seeds[0], **LOG))
    cases = [(name, seed) for name in EXPERIMENTS for seed in args.seeds]
    with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        probes = list(pool.map(probe, *zip(*cases, strict=True)))
    doc = {
        "statistics": rows,
        "experiments": {name: repr(e) for name, e in EXPERIMENTS.items()},
        "planted": {"name": PLANTED.name, "joint": PLANTED.joint, "coefficient": PLANTED.coefficient},
        "log": LOG,
        "recipe": RECIPE,
        "probes": probes,
        "machine": f"{platform.machine()}, {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "match.json").write_text(json.dumps(doc, indent=1) + "\n")
    for p in probes:
        print(p, flush=True)


if __name__ == "__main__":
    main()
