"""Batched model-backed env speed vs the MuJoCo ground-truth env (issue 4 benchmark).

Measures, in one run on this machine, side by side:

* the MuJoCo ``furuta_gym/Furuta-v0`` single env: ``env.step`` calls per second (the reference);
* the same env with a DeLaN backend (single copy): ``env.step``/s, and its ratio to MuJoCo, with
  the default step kernel (C when a compiler exists) and with ``kernel="xla"``;
* the DeLaN-backed batched env (:class:`furuta_gym.envs.vector.FurutaVectorEnv`, one jitted vmapped
  step per ``env.step``) in state-steps/s (copies × steps per second) at N = 1, 64, 1024, 4096,
  16384, and the pure-JAX rollout (``FurutaVectorEnv.rollout``: a jittable policy inside
  ``lax.scan``) at the same N; both divided by the MuJoCo env.step/s (target at N = 4096: ≥ 10);
* the analytic backend at N = 4096 for comparison.

The DeLaN is a trained checkpoint when ``--checkpoint PATH`` is given, otherwise an *untrained*
DeLaN of the default Furuta architecture (``make_model("furuta", "dln")``: the cost of a step does
not depend on the weights' values). Times are wall-clock, best of ``--repeats``, after a warm-up
that compiles. Writes/refreshes its section of BENCHMARKS.md (between markers) unless ``--no-write``.

    python bench/batched_speed.py            # ~3-5 min on 2 cores
    python bench/batched_speed.py --quick    # smaller N list and fewer steps, for a smoke run
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

from _generated import machine, publish

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parents[1]
MARK_START = "<!-- bench/batched_speed.py:start -->"
MARK_END = "<!-- bench/batched_speed.py:end -->"
ENV_ID = "furuta_gym/Furuta-v0"


class Rate(float):
    """Work per wall-clock second (the float value), with ``.cpu``: work per CPU-second of this
    process (all its threads). On a shared machine the CPU-time rate depends far less on what
    the other users run, so the CPU-time ratios are the steadier comparison."""

    cpu: float

    def __new__(cls, wall: float, cpu: float):
        obj = super().__new__(cls, wall)
        obj.cpu = cpu
        return obj


def best_rate(fn, work: float, repeats: int, cpu_clock=time.process_time) -> Rate:
    """``work`` units per second of ``fn()``, best of ``repeats`` (fn already warmed up)."""
    best_wall = best_cpu = np.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), cpu_clock()
        fn()
        best_wall = min(best_wall, time.perf_counter() - t0)
        best_cpu = min(best_cpu, cpu_clock() - c0)
    return Rate(work / best_wall, work / max(best_cpu, 1e-9))


def cpu_seconds_with(pids) -> float:
    """CPU time of this process plus the (running) processes ``pids``, from /proc (Linux)."""
    ticks = os.sysconf("SC_CLK_TCK")
    total = time.process_time()
    for pid in pids:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        total += (int(fields[11]) + int(fields[12])) / ticks  # utime + stime
    return total


def single_env_rate(env, steps: int, repeats: int) -> float:
    rng = np.random.default_rng(0)
    actions = rng.uniform(-5.0, 5.0, size=(steps, 1))
    env.reset(seed=0)
    for a in actions[:200]:  # warm-up (compiles a model backend)
        env.step(a)

    def run():  # the episode continues across runs (10 s truncation resets it); no reset timed
        for a in actions:
            env.step(a)

    return best_rate(run, steps, repeats)


def calibrated_steps(run_for, n: int, seconds: float, max_steps: int) -> int:
    """Steps so that one timed run lasts about ``seconds`` (from a short probe run)."""
    probe = 10
    t0 = time.perf_counter()
    run_for(probe)
    per_step = (time.perf_counter() - t0) / probe
    return int(np.clip(seconds / max(per_step, 1e-9), 10, max_steps))


def batched_env_rate(dynamics, n: int, seconds: float, repeats: int, **split) -> tuple[float, int]:
    """State-steps/s of ``FurutaVectorEnv(n, dynamics, **split)`` (``chunks=`` / ``workers=``)."""
    from furuta_gym.envs.vector import FurutaVectorEnv

    env = FurutaVectorEnv(n, dynamics=dynamics, **split)
    pids = [p.pid for p in env._workers._processes] if env.workers else []
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    env.step(rng.uniform(-5.0, 5.0, size=(n, 1)))  # compile

    def run_for(steps):  # episodes continue across runs (autoreset included); no reset timed
        for a in actions[:steps]:
            env.step(a)

    actions = rng.uniform(-5.0, 5.0, size=(10, n, 1))
    steps = calibrated_steps(run_for, n, seconds, 5000)
    actions = rng.uniform(-5.0, 5.0, size=(steps, n, 1))
    rate = best_rate(lambda: run_for(steps), n * steps, repeats, lambda: cpu_seconds_with(pids))
    env.close()
    return rate, steps


def policy(obs):
    """A jittable linear feedback (its cost is negligible next to the model's)."""
    import jax.numpy as jnp

    return jnp.array([2.0 * jnp.sin(obs[1]) - 0.1 * obs[2] + 0.05 * obs[3]])


def rollout_rate(dynamics, n: int, seconds: float, repeats: int) -> tuple[float, int]:
    import jax

    from furuta_gym.envs.vector import FurutaVectorEnv

    env = FurutaVectorEnv(n, dynamics=dynamics)
    env.reset(seed=0)
    probe = 20
    jax.block_until_ready(env.rollout(policy, probe))  # compile the probe length
    t0 = time.perf_counter()
    jax.block_until_ready(env.rollout(policy, probe))
    per_step = (time.perf_counter() - t0) / probe
    steps = int(np.clip(seconds / per_step, probe, 20000))
    jax.block_until_ready(env.rollout(policy, steps))  # compile the timed length

    def run():
        jax.block_until_ready(env.rollout(policy, steps))

    return best_rate(run, n * steps, repeats), steps


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--checkpoint", help="a trained Furuta DeLaN checkpoint (default: untrained)")
    parser.add_argument("--quick", action="store_true", help="smoke run: fewer N and steps")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-write", action="store_true", help="print only, do not touch BENCHMARKS.md")
    args = parser.parse_args(argv)

    import jax

    furuta_gym.enable_x64()
    import gymnasium as gym

    from furuta_gym.models import make_model

    started = datetime.datetime.now(datetime.timezone.utc)
    host = machine()
    if args.checkpoint:
        from furuta_gym.training.checkpoint import load_model

        delan = load_model(args.checkpoint, expected_system="furuta")
        delan_name = f"trained DeLaN from {args.checkpoint}"
    else:
        delan = make_model("furuta", "dln", key=jax.random.PRNGKey(0))
        delan_name = "untrained DeLaN (make_model('furuta', 'dln'), default architecture)"
    ns = [1, 64, 1024] if args.quick else [1, 64, 1024, 4096, 16384]
    seconds = 0.5 if args.quick else 2.0  # wall time of one timed run
    single_steps = 2000 if args.quick else 10000

    lines = []

    def say(msg):
        print(msg, flush=True)

    mujoco_env = gym.make(ENV_ID)
    mujoco_rate = single_env_rate(mujoco_env, single_steps, args.repeats)
    say(f"MuJoCo Furuta-v0 single env: {mujoco_rate:,.0f} env.step/s")
    delan_env = gym.make(ENV_ID, dynamics=delan)  # kernel="auto": C when a compiler exists
    delan_kernel = delan_env.unwrapped.backend.kernel
    delan_single = single_env_rate(delan_env, single_steps, args.repeats)
    say(f"DeLaN single env (kernel {delan_kernel}): {delan_single:,.0f} env.step/s ({delan_single / mujoco_rate:.2f}x)")
    delan_xla_single = single_env_rate(gym.make(ENV_ID, dynamics=delan, kernel="xla"), single_steps // 2, args.repeats)
    say(f"DeLaN single env (kernel xla): {delan_xla_single:,.0f} env.step/s ({delan_xla_single / mujoco_rate:.2f}x)")

    from furuta_gym.envs.vector import auto_chunks

    workers = min(2, os.cpu_count() or 1)
    rows = []
    for n in ns:
        env_rate, env_steps = batched_env_rate(delan, n, seconds, args.repeats)
        one_rate, _ = batched_env_rate(delan, n, seconds, args.repeats, chunks=1)
        worker_rate, _ = batched_env_rate(delan, n, seconds, args.repeats, workers=min(workers, n))
        roll_rate, roll_steps = rollout_rate(delan, n, seconds, args.repeats)
        rows.append((n, env_rate, one_rate, worker_rate, roll_rate))
        say(
            f"DeLaN N={n:>6}: batched env {env_rate:>12,.0f} state-steps/s "
            f"({env_rate / mujoco_rate:6.2f}x, {auto_chunks(n)} chunks, {env_steps} steps), one "
            f"execution {one_rate:>12,.0f} ({one_rate / mujoco_rate:6.2f}x), workers={min(workers, n)} "
            f"{worker_rate:>12,.0f} ({worker_rate / mujoco_rate:6.2f}x), rollout {roll_rate:>12,.0f} "
            f"({roll_rate / mujoco_rate:6.2f}x, {roll_steps} steps)"
        )
    n_ref = 4096 if 4096 in ns else ns[-1]
    analytic_env, _ = batched_env_rate("analytic", n_ref, seconds, args.repeats)
    analytic_roll, _ = rollout_rate("analytic", n_ref, seconds, args.repeats)
    say(
        f"analytic N={n_ref}: batched env {analytic_env:,.0f} ({analytic_env / mujoco_rate:.2f}x), "
        f"rollout {analytic_roll:,.0f} ({analytic_roll / mujoco_rate:.2f}x)"
    )
    # the machine is shared and its load drifts: measure the reference again at the end and
    # divide by the faster of the two (the conservative ratio)
    mujoco_end = single_env_rate(mujoco_env, single_steps, args.repeats)
    say(f"MuJoCo Furuta-v0 single env again: {mujoco_end:,.0f} env.step/s")
    mujoco_start, mujoco_rate = mujoco_rate, max(mujoco_rate, mujoco_end)
    mujoco_cpu = max(mujoco_start.cpu, mujoco_end.cpu)
    finished = datetime.datetime.now(datetime.timezone.utc)

    ref = {n: rest for n, *rest in rows}[n_ref]

    def row(what, rate, unit):
        return (
            f"| {what} | {rate:,.0f} {unit} | {rate / mujoco_rate:.2f} | {rate.cpu:,.0f} | "
            f"{rate.cpu / mujoco_cpu:.2f} |"
        )

    lines += [
        MARK_START,
        "## Batched model-backed env (issue 4): `bench/batched_speed.py`",
        "",
        f"Run {started:%Y-%m-%d %H:%M}–{finished:%H:%M} UTC on {host}."
        + (" Quick mode (smoke run)." if args.quick else ""),
        f"Model: {delan_name}. Float64. Ratios divide by the MuJoCo `Furuta-v0` single env's "
        "env.step/s measured in the same run with the same harness (random actions in ±5 V, "
        f"best of {args.repeats}).",
        "",
        "| what | rate (wall clock) | ÷ MuJoCo | rate per CPU-second | ÷ MuJoCo (CPU) |",
        "|---|---:|---:|---:|---:|",
        f"| MuJoCo `Furuta-v0` single env (reference: the faster of start {mujoco_start:,.0f} "
        f"and end {mujoco_end:,.0f} env.step/s) | {mujoco_rate:,.0f} env.step/s | 1 | "
        f"{mujoco_cpu:,.0f} | 1 |",
        row(
            f'**DeLaN single env (`dynamics=model`, default `kernel="auto"` → `{delan_kernel}`)**, target ≥ 0.5',
            delan_single,
            "env.step/s",
        ),
        row('DeLaN single env, `kernel="xla"` (one jitted XLA call per step)', delan_xla_single, "env.step/s"),
        row(
            f"**DeLaN batched env, N = {n_ref}, `workers={min(workers, n_ref)}`** (worker "
            "processes; CPU includes theirs), target ≥ 10",
            ref[2],
            "state-steps/s",
        ),
        row(
            f"DeLaN batched env, N = {n_ref}, default (in this process, {auto_chunks(n_ref)} concurrent chunks)",
            ref[0],
            "state-steps/s",
        ),
        row(f"DeLaN batched env, N = {n_ref}, one XLA execution (`chunks=1`)", ref[1], "state-steps/s"),
        row(
            f"DeLaN pure-JAX rollout (`lax.scan`), N = {n_ref} (default: one concurrent chunk per core)",
            ref[3],
            "state-steps/s",
        ),
        row(f"analytic batched env, N = {n_ref}", analytic_env, "state-steps/s"),
        row(f"analytic pure-JAX rollout, N = {n_ref} (default chunks)", analytic_roll, "state-steps/s"),
        "",
        "Scaling with N (DeLaN; state-steps/s = copies × env steps per second):",
        "",
        f"| N | env, default (chunks) | ÷ MuJoCo | env, `chunks=1` | ÷ MuJoCo | env, "
        f"`workers={workers}` | ÷ MuJoCo | ÷ MuJoCo (CPU) | pure-JAX rollout | ÷ MuJoCo |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n, e, one, w, r in rows:
        lines.append(
            f"| {n} | {e:,.0f} ({auto_chunks(n)}) | {e / mujoco_rate:.2f} | {one:,.0f} | "
            f"{one / mujoco_rate:.2f} | {w:,.0f} | {w / mujoco_rate:.2f} | "
            f"{w.cpu / mujoco_cpu:.2f} | {r:,.0f} | {r / mujoco_rate:.2f} |"
        )
    lines += [
        "",
        "Rates are state-steps/s (copies × env steps per second). The batched env pays one "
        "Python `step` call (host↔device copies, autoreset bookkeeping, info arrays) per step for "
        "all copies; the rollout runs the policy and the model inside one compiled `lax.scan`. "
        "`workers=K` steps the copies in K worker processes whose XLA thread pool has one thread "
        "(one execution in one process keeps ~1.3 of 2 cores busy); their start-up (~3 s) is not "
        "timed. The machine is shared, so absolute rates vary between runs; the "
        'ratios are measured side by side. "Per CPU-second" divides the work by the CPU time '
        "this process used (all threads), which depends much less on the other users' load.",
        MARK_END,
    ]
    return publish("\n".join(lines), MARK_START, MARK_END, write=not args.no_write)


if __name__ == "__main__":
    sys.exit(main())
