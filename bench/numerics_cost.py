"""What furuta_gym's pinned CPU numerics cost in speed (issue 68; docs/conventions.md, "Same numbers
on every machine").

The same work in fresh processes, pinned (the default: ``--xla_cpu_max_isa=AVX2``, YNNPACK off,
OpenBLAS's Haswell kernels, XLA's thread count) and native (``FURUTA_GYM_NATIVE_ISA=1``), alternated (pinned, native,
pinned, native) so that a shared machine's load falls on both alike; each quantity is the best of
its processes:

* a training epoch, as bench/loss_cost.py times it (Furuta DeLaN, 64 free trajectories): L_traj's
  2-step windows in minibatches of 256, and L_Iτ's one full-batch step;
* a batched env rollout (``FurutaVectorEnv.rollout``: policy and model in one ``lax.scan``), 256
  copies, of the analytic Furuta and of an (untrained) DeLaN.

Run ``python bench/numerics_cost.py`` (≈ 6 min on 2 cores): writes results/numerics_cost/results.json
and its section of BENCHMARKS.md; ``--check`` only compares that section with the results,
``--no-measure`` rewrites it from them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _generated import machine, write_section

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "numerics_cost" / "results.json"
START, END = "<!-- numerics_cost:start -->", "<!-- numerics_cost:end -->"
N_ENVS, ROLLOUT_STEPS = 256, 2000


def _policy(obs):
    import jax.numpy as jnp

    return jnp.array([2.0 * jnp.sin(obs[1]) - 0.1 * obs[2] + 0.05 * obs[3]])


def rollout_rate(dynamics, repeats: int = 3) -> float:
    """State-steps/s of a compiled rollout of ``N_ENVS`` copies over ``ROLLOUT_STEPS`` steps."""
    import jax

    from furuta_gym.envs.vector import FurutaVectorEnv

    env = FurutaVectorEnv(N_ENVS, dynamics=dynamics)
    env.reset(seed=0)
    jax.block_until_ready(env.rollout(_policy, ROLLOUT_STEPS))  # compile
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(env.rollout(_policy, ROLLOUT_STEPS))
        best = min(best, time.perf_counter() - t0)
    return N_ENVS * ROLLOUT_STEPS / best


def one_process() -> dict:
    """Every quantity, timed in this process (whatever numerics it was started with)."""
    import jax

    import furuta_gym
    from furuta_gym.models import make_model
    from loss_cost import epoch_time

    furuta_gym.enable_x64()
    return {
        "xla_flags": furuta_gym.numerics()["xla_flags"],
        "pjrt_nproc": furuta_gym.numerics()["pjrt_nproc"],
        "traj_epoch_s": epoch_time("traj", 64)["epoch_s"],
        "itau_epoch_s": epoch_time("itau", 64)["epoch_s"],
        "rollout_analytic": rollout_rate("analytic"),
        "rollout_delan": rollout_rate(make_model("furuta", "dln", jax.random.PRNGKey(0))),
    }


def measure(rounds: int) -> dict:
    runs = {"pinned": [], "native": []}
    for _ in range(rounds):
        for mode in ("pinned", "native"):
            env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "OPENBLAS_CORETYPE")}
            env["FURUTA_GYM_COMPILATION_CACHE"] = "0"
            if mode == "native":
                env["FURUTA_GYM_NATIVE_ISA"] = "1"
            else:
                env.pop("FURUTA_GYM_NATIVE_ISA", None)
            out = subprocess.run(
                [sys.executable, __file__, "--one"], env=env, capture_output=True, text=True, check=True, timeout=3600
            )
            runs[mode].append(json.loads(out.stdout.strip().splitlines()[-1]))
            print(mode, runs[mode][-1], flush=True)
    best = {}
    for mode, rs in runs.items():
        best[mode] = {
            "xla_flags": rs[0]["xla_flags"],
            "pjrt_nproc": rs[0].get("pjrt_nproc"),
            "traj_epoch_s": min(r["traj_epoch_s"] for r in rs),
            "itau_epoch_s": min(r["itau_epoch_s"] for r in rs),
            "rollout_analytic": max(r["rollout_analytic"] for r in rs),
            "rollout_delan": max(r["rollout_delan"] for r in rs),
        }
    return {
        "machine": machine(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "rounds": rounds,
        "best": best,
        "runs": runs,
    }


def _threads(pinned: dict) -> str:
    if pinned.get("pjrt_nproc") is None:
        return "XLA's thread count unpinned"
    cores = os.cpu_count()
    same = (
        " (this machine's own count: the thread pin costs nothing here)" if str(cores) == pinned["pjrt_nproc"] else ""
    )
    return f"`PJRT_NPROC={pinned['pjrt_nproc']}`{same}"


def section(res: dict) -> str:
    p, n = res["best"]["pinned"], res["best"]["native"]
    rows = [
        ("L_traj epoch (64 trajectories, 2-step windows, minibatch 256)", "traj_epoch_s", "s", True),
        ("L_Iτ epoch (64 trajectories, one full-batch step)", "itau_epoch_s", "s", True),
        (
            f"analytic Furuta rollout, {N_ENVS} copies × {ROLLOUT_STEPS} steps",
            "rollout_analytic",
            "state-steps/s",
            False,
        ),
        (f"DeLaN rollout, {N_ENVS} copies × {ROLLOUT_STEPS} steps", "rollout_delan", "state-steps/s", False),
    ]

    def fmt(v, unit):
        return f"{v * 1e3:.1f} ms" if unit == "s" else f"{v:,.0f}"

    def cell(mode, key, unit, is_time):
        """The best of the mode's processes, and in brackets its worst (the machine's noise)."""
        values = [r[key] for r in res["runs"][mode]]
        worst = max(values) if is_time else min(values)
        return f"{fmt(res['best'][mode][key], unit)} ({fmt(worst, unit)})"

    lines = [
        "## Pinned CPU numerics: what the same bits on every machine cost (`bench/numerics_cost.py`)",
        "",
        f"Machine: {res['machine']}. Date {res['date']}.",
        "",
        "Fresh processes alternated pinned / native "
        f"({res['rounds']} of each; best of each), JAX persistent cache off. Pinned: furuta_gym's default, "
        f"`XLA_FLAGS={p['xla_flags']}`, {_threads(p)} and OpenBLAS's Haswell kernels; native: "
        "`FURUTA_GYM_NATIVE_ISA=1` (XLA's own choice for this CPU, YNNPACK on, a thread per core). Each cell: the best process (in brackets the worst, the "
        "shared machine's noise); the speed ratio is of the bests, pinned ÷ native (above 1: the pin is faster).",
        "",
        "| what | pinned | native | unit | speed ratio pinned / native |",
        "|---|---:|---:|---|---:|",
    ]
    for label, key, unit, is_time in rows:
        ratio = n[key] / p[key] if is_time else p[key] / n[key]
        lines.append(
            f"| {label} | {cell('pinned', key, unit, is_time)} | {cell('native', key, unit, is_time)} "
            f"| {'epoch' if unit == 's' else unit} | {ratio:.2f} |"
        )
    lines += ["", "Results: results/numerics_cost/results.json."]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--one", action="store_true", help="(child) time everything in this process, print JSON")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--check", action="store_true", help="compare the BENCHMARKS.md section with the results")
    ap.add_argument("--no-measure", action="store_true", help="rewrite the section from the committed results")
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one_process()))
        return 0
    if not (args.check or args.no_measure):
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(measure(args.rounds), indent=2) + "\n")
    res = json.loads(RESULTS.read_text())
    return write_section(
        f"{START}\n{section(res)}\n{END}", START, END, check=args.check, how_to_fix="run python bench/numerics_cost.py"
    )


if __name__ == "__main__":
    sys.exit(main())
