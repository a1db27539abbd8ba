"""Where the batched JAX env overtakes Gymnasium's SyncVectorEnv of single envs (issue 27).

    python bench/vector_crossover.py [--repeats 3] [--no-write]

For a model backend (the analytic model and an untrained DeLaN of the default architecture: a
step's cost does not depend on the weights) and N = 1 … 256 copies, measures side by side, in
state-steps/s (copies × env steps per second):

* ``sync``: ``gymnasium.make_vec(..., vectorization_mode="sync")`` — N single envs, each stepping
  its own compiled kernel (C when a compiler exists);
* ``batched``: :class:`furuta_gym.envs.vector.FurutaVectorEnv` — one jitted, vmapped XLA step for
  all copies.

``gymnasium.make_vec``'s default (the registered vector entry point) gives the sync env below
:data:`furuta_gym.envs.vector.BATCHED_FROM` copies and the batched env from there on; this
benchmark is what that threshold is read from. Writes its section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

from _generated import machine, write_section
from batched_speed import batched_env_rate, best_rate, calibrated_steps

os.environ.setdefault("MUJOCO_GL", "egl")

START, END = "<!-- bench/vector_crossover.py:start -->", "<!-- bench/vector_crossover.py:end -->"
ENV_ID = "furuta_gym/Furuta-v0"
NS = (1, 2, 4, 8, 16, 32, 64, 128, 256)


def sync_env_rate(dynamics, n: int, seconds: float, repeats: int) -> float:
    import gymnasium as gym

    env = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="sync", dynamics=dynamics)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    for a in rng.uniform(-5.0, 5.0, size=(20, n, 1)):  # compiles each copy's kernel
        env.step(a)
    actions = rng.uniform(-5.0, 5.0, size=(10, n, 1))

    def run_for(steps):
        for a in actions[:steps]:
            env.step(a)

    steps = calibrated_steps(run_for, n, seconds, 5000)
    actions = rng.uniform(-5.0, 5.0, size=(steps, n, 1))
    rate = best_rate(lambda: run_for(steps), n * steps, repeats)
    env.close()
    return rate


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=1.0, help="wall time of one timed run")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)

    import jax

    from furuta_gym.envs.vector import BATCHED_FROM
    from furuta_gym.models import make_model

    furuta_gym.enable_x64()
    backends = {
        "analytic": "analytic",
        "DeLaN (untrained, default architecture)": make_model("furuta", "dln", key=jax.random.PRNGKey(0)),
    }
    rows = []
    for label, dynamics in backends.items():
        for n in NS:
            sync = sync_env_rate(dynamics, n, args.seconds, args.repeats)
            batched, _ = batched_env_rate(dynamics, n, args.seconds, args.repeats)
            rows.append((label, n, sync, batched))
            print(f"{label} N={n}: sync {sync:,.0f}, batched {batched:,.0f} ({batched / sync:.2f}x)", flush=True)
    lines = [
        START,
        "## Vector env crossover (issue 27): `bench/vector_crossover.py`",
        "",
        f"{machine()}; {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC. "
        "State-steps/s (copies × `step` calls per second), wall clock, best of "
        f"{args.repeats}, measured side by side in one run. `make_vec`'s default switches from "
        f"sync to batched at N = `BATCHED_FROM` = {BATCHED_FROM}.",
        "",
        "| backend | N | sync (N single envs) | batched (one vmapped XLA step) | batched / sync |",
        "|---|---|---|---|---|",
    ]
    for label, n, sync, batched in rows:
        lines.append(f"| {label} | {n} | {sync:,.0f} | {batched:,.0f} | {batched / sync:.2f} |")
    crossings = []
    for label in backends:
        faster = [n for lab, n, s, b in rows if lab == label and b >= s]
        crossings.append(f"{label}: from N = {min(faster)}" if faster else f"{label}: never up to 256")
    lines += ["", "Batched at least as fast as sync — " + "; ".join(crossings) + ".", END]
    text = "\n".join(lines)
    if args.no_write:
        print(text)
    else:
        write_section(text, START, END)
    return 0


if __name__ == "__main__":
    sys.exit(main())
