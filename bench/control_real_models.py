"""Controllers designed on real-data models, run on the plant variant that matches the rig (issue 28).

    python bench/control_real_models.py [--episodes 30] [--seed 0] [--no-write]

Design models: the analytic model fitted by ``diagnose`` on the real QUBE runs 1–5 plus the
effects it found (``model_after``), and the learned models trained on the same runs by
``studies/real_models.py`` (``results/real_models/runs/*/selected.eqx``, the snapshot each
run kept on validation and the docs/learning.md table scores). Plant: the MuJoCo
ground truth with the effects ``diagnose`` found written into it — the closest stand-in for the
rig this package has (its masses and lengths stay nominal: MuJoCo takes physical parameters,
the fit gives lumped ones). Swing-up + LQR (volts), 5 V, 500 Hz, 8 s episodes, x0 = 0 plus
seeded starts near the hanging rest, as ``bench/control_benchmark.py``. Writes its section of
BENCHMARKS.md unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

from _generated import machine, publish
from control_benchmark import SECONDS, TABLE_HEADER, _row

ROOT = Path(__file__).resolve().parents[1]
START, END = "<!-- control_real_models:start -->", "<!-- control_real_models:end -->"
#: the catch: logs of upright balancing support the LQR about the top, whatever the swing-up does
CATCH_SECONDS = 4.0
LEARNED = ("adln_aph", "dln_traj", "adln_prop", "dln_prop", "adln_prop_span", "dln_prop_span")


def _designs(res, load_model):
    """(label, design model) pairs: the diagnosed analytic model, then each real-data checkpoint."""
    out = [("diagnosed analytic (runs 1–5)", res.model_after)]
    for name in LEARNED:
        path = ROOT / "results" / "real_models" / "runs" / name / "selected.eqx"
        if path.exists():
            out.append((f"{name} trained on runs 1–5", load_model(path, expected_system="furuta")))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)

    furuta_gym.enable_x64()
    import gymnasium as gym

    from furuta_gym.controllers import LQR, SwingUpLQR, evaluate_on_env, near_rest_starts, near_upright_starts
    from furuta_gym.datasets import load_qube_closed_loop
    from furuta_gym.diagnose import diagnose
    from furuta_gym.envs import Episode, Plant
    from furuta_gym.training.checkpoint import load_model

    res = diagnose(load_qube_closed_loop(range(1, 6)), "furuta", window=0.1, oe_max_windows=64)
    found = [e for e in res.found if e.name not in ("input_delay", "actuator_lag")]
    plant = ", ".join(f"{e.name}:{e.joint} {e.coefficient:.2g}" for e in found) or "none"
    starts = np.concatenate([np.zeros((1, 4)), near_rest_starts(args.episodes, args.seed, False)])
    make_env = lambda: gym.make("furuta_gym/Furuta-v0", episode=Episode(seconds=None), plant=Plant(effects=found))  # noqa: E731
    rows, notes = [], []
    # first the exact upright (the "x0" column of the catch rows), then the seeded starts
    catch_starts = np.concatenate([[[0.0, np.pi, 0.0, 0.0]], near_upright_starts(args.episodes, args.seed)])
    for label, model in _designs(res, load_model):
        for name, design, x0s, seconds in (
            ("swing-up + LQR (volts)", lambda m: SwingUpLQR.from_model(m, seed=args.seed), starts, SECONDS),
            ("LQR catch near upright (volts)", LQR.from_model, catch_starts, CATCH_SECONDS),
        ):
            try:
                ctrl = design(model)
            except Exception as exc:  # a learned design can fail: say how, keep the table
                notes.append(f"{name}, {label}: design failed — {type(exc).__name__}: {exc}.")
                continue
            t = time.perf_counter()
            recs = evaluate_on_env(ctrl, make_env, x0s, seconds, seed=args.seed)
            rows.append(_row(name, label, f"mujoco + {plant}", recs, time.perf_counter() - t))
            print(rows[-1], flush=True)
    stamp = f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC"
    lines = [
        START,
        "### Designed on real-data models, run on the matching plant variant",
        "",
        f"`python bench/control_real_models.py --episodes {args.episodes}` — {stamp}, {machine()}. "
        f"Plant: MuJoCo + what `diagnose` found on runs 1–5 ({plant}); nominal masses and lengths. "
        "Swing-up: x0 = 0 and seeded starts near the hanging rest; the LQR catch alone: seeded starts "
        f"near upright (β − π, α ~ U(±0.1 rad), velocities ~ U(±0.2 rad/s), {CATCH_SECONDS:g} s; its x0 column: "
        "the exact upright), what "
        "models learned from upright balancing logs saw.",
        "",
        TABLE_HEADER,
        *rows,
        *[f"- {x}" for x in notes],
        END,
    ]
    return publish("\n".join(lines), START, END, write=not args.no_write)


if __name__ == "__main__":
    sys.exit(main())
