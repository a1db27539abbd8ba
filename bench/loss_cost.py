"""Cost of one training epoch: trajectory loss L_traj versus the integral inverse loss L_Iτ.

Same model (Furuta DeLaN, the paper's (16, 16) MLPs), same data, same run: 64 free Furuta
trajectories × 100 samples at 100 Hz (the paper's training set), then 256. One epoch is what
:func:`furuta_gym.training.train` runs: L_Iτ = one full-batch step on all trajectories; L_traj =
all 2-step windows (the paper's first curriculum stage), in minibatches of 256 windows (our
default) and as one full batch (the paper's recipe). Each step is value + gradient + AdamW
update. Also: first-call (compile) time of each step in a fresh process, cold and warm with JAX's
persistent compilation cache (which also turns on furuta_gym's cache of traced steps, see
furuta_gym/training/_step_cache.py), and where the first call's time goes (trace, lower, XLA
compile, run) without any cache.

Run: ``python bench/loss_cost.py`` (≈ 5-10 min on 2 cores). Rewrites its section of
BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _generated import write_section

ROOT = Path(__file__).resolve().parents[1]
SECTION = "loss_cost"


def furuta_free_data(n: int, seed: int = 0, samples: int = 100):
    """n free Furuta trajectories (the paper's sampling: α, β ~ U(−π, π), velocities ~ U(−5, 5))."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from furuta_gym.data import Trajectory
    from furuta_gym.models import Furuta
    from furuta_gym.simulate import rollout_zoh

    rng = np.random.default_rng(seed)
    x0 = np.concatenate([rng.uniform(-np.pi, np.pi, (n, 2)), rng.uniform(-5, 5, (n, 2))], axis=1)
    us = jnp.zeros((samples - 1, 1))
    xs = np.asarray(jax.jit(jax.vmap(lambda x: rollout_zoh(Furuta(), x, us, 0.01, 10)))(jnp.asarray(x0)))
    t = np.arange(samples) * 0.01
    return [Trajectory(t, x[:, :2], np.zeros((samples, 1)), x[:, 2:], name=str(i)) for i, x in enumerate(xs)]


def _setup(loss: str, n_traj: int, batch_size):
    import jax

    from furuta_gym.models import make_model
    from furuta_gym.training.losses import make_windows
    from furuta_gym.training.train import TrainSettings, training_step

    trajs = furuta_free_data(n_traj)
    model = make_model("furuta", "dln", jax.random.PRNGKey(0))
    config = TrainSettings.for_system("furuta", batch_size=batch_size, progress=False)
    step, params, opt_state = training_step(model, config, "itau" if loss == "itau" else "traj")
    if loss == "itau":
        w = make_windows(trajs, 100, stride=99, cover_end=True)
        batches = [(None, w)]
    else:
        w = make_windows(trajs, 3, stride=1)
        bs = w.n_windows if batch_size is None else batch_size
        batches = [(w.take(slice(k * bs, (k + 1) * bs)), None) for k in range(w.n_windows // bs)]
    return step, params, opt_state, batches


def epoch_time(loss: str, n_traj: int, batch_size=256, repeats: int = 3) -> dict:
    import jax
    import jax.numpy as jnp

    step, params, opt_state, batches = _setup(loss, n_traj, batch_size)
    lam = jnp.asarray(1.0)
    lr = jnp.asarray(1e-3)

    def one_epoch(params, opt_state):
        for tb, ib in batches:
            params, opt_state, terms, ok = step(params, opt_state, tb, ib, lam, lr)
        jax.block_until_ready(terms["total"])
        return params, opt_state

    t0 = time.perf_counter()
    params, opt_state = one_epoch(params, opt_state)  # compile + first epoch
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        params, opt_state = one_epoch(params, opt_state)
        times.append(time.perf_counter() - t0)
    return {
        "loss": loss,
        "n_traj": n_traj,
        "full_batch": batch_size is None,
        "steps": len(batches),
        "first_epoch_s": first,
        "epoch_s": min(times),
        "epoch_s_median": sorted(times)[len(times) // 2],
    }


def compile_probe(loss: str, cache_dir: str) -> float:
    """In this (fresh) process: seconds until the first step of ``loss`` has run."""
    import jax

    jax.config.update("jax_compilation_cache_dir", cache_dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    import jax.numpy as jnp

    step, params, opt_state, batches = _setup(loss, 64, 256)
    tb, ib = batches[0]
    t0 = time.perf_counter()
    out = step(params, opt_state, tb, ib, jnp.asarray(1.0), jnp.asarray(1e-3))
    jax.block_until_ready(out[2]["total"])
    return time.perf_counter() - t0


def breakdown_probe(loss: str) -> dict:
    """In this (fresh, cache-less) process: seconds spent tracing, lowering, compiling and running
    the first step of ``loss`` (jax.stages: the jaxpr traced once is reused by ``lower``)."""
    import jax
    import jax.numpy as jnp

    step, params, opt_state, batches = _setup(loss, 64, 256)
    tb, ib = batches[0]
    args = (params, opt_state, tb, ib, jnp.asarray(1.0), jnp.asarray(1e-3))
    t0 = time.perf_counter()
    jax.make_jaxpr(step)(*args)  # traces the jitted step (and fills JAX's trace cache)
    t1 = time.perf_counter()
    lowered = step.lower(*args)
    t2 = time.perf_counter()
    compiled = lowered.compile()
    t3 = time.perf_counter()
    out = compiled(*args)
    jax.block_until_ready(out[2]["total"])
    t4 = time.perf_counter()
    callbacks = re.findall(r"custom_call @\w*callback", lowered.as_text())
    return {"trace": t1 - t0, "lower": t2 - t1, "compile": t3 - t2, "run": t4 - t3, "host_callbacks": len(callbacks)}


def _probe_subprocess(loss: str, cache_dir: str | None, step_cache: bool = True, breakdown: bool = False):
    env = dict(os.environ, JAX_ENABLE_X64="1")
    env.pop("EQX_ON_ERROR", None)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    env["FURUTA_GYM_STEP_CACHE"] = "1" if step_cache else "0"
    cmd = [sys.executable, __file__, "--probe", loss]
    cmd += ["--breakdown"] if breakdown else ["--cache", cache_dir]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result if breakdown else float(result["seconds"])


def write_section_text(text: str) -> None:
    start, end = f"<!-- {SECTION}:start -->", f"<!-- {SECTION}:end -->"
    write_section(f"{start}\n{text.rstrip()}\n{end}", start, end)


def _compile_rows() -> dict[tuple[str, bool], tuple[float, float]]:
    """(loss, step cache on) -> first-call seconds (cold, warm), each in a fresh process."""
    compile_rows = {}
    for loss, step_cache in (("itau", True), ("traj", True), ("traj", False)):
        cache = tempfile.mkdtemp(prefix="furuta_gym_jax_cache_")
        try:
            cold = _probe_subprocess(loss, cache, step_cache)
            warm = _probe_subprocess(loss, cache, step_cache)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
        compile_rows[(loss, step_cache)] = (cold, warm)
        print(loss, step_cache, cold, warm, flush=True)
    return compile_rows


def _epoch_row(rows: list[dict], loss: str, n: int, full: bool) -> dict:
    """The epoch timing of ``loss`` on ``n`` trajectories (L_traj: full batch or minibatches)."""
    for r in rows:
        if r["loss"] == loss and r["n_traj"] == n and (r["full_batch"] == full or loss == "itau"):
            return r
    raise KeyError((loss, n, full))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--probe", choices=["traj", "itau"])
    parser.add_argument("--cache")
    parser.add_argument("--breakdown", action="store_true", help="with --probe: time trace/lower/compile")
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument("--sizes", default="64,256", help="numbers of trajectories (smoke test: 4,8)")
    args = parser.parse_args()
    import furuta_gym

    furuta_gym.enable_x64()
    if args.probe:
        if args.breakdown:
            print(json.dumps(breakdown_probe(args.probe)))
        else:
            print(json.dumps({"seconds": compile_probe(args.probe, args.cache)}))
        return

    load_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    sizes = tuple(int(v) for v in args.sizes.split(","))
    rows = []
    for n in sizes:
        rows.append(epoch_time("itau", n))
        rows.append(epoch_time("traj", n, batch_size=256))
        rows.append(epoch_time("traj", n, batch_size=None, repeats=2))
        print(rows[-3:], flush=True)
    compile_rows = _compile_rows()
    breakdown = {loss: _probe_subprocess(loss, None, breakdown=True) for loss in ("traj", "itau")}
    print(breakdown, flush=True)

    def get(loss, n, full=False):
        return _epoch_row(rows, loss, n, full)

    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    lines = [
        "## Loss cost: L_traj versus L_Iτ per epoch (`bench/loss_cost.py`)",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load average {load_start:.1f} at the start, {load[0]:.1f} at the end (shared machine: absolute times are inflated, the "
        f"ratios are measured side by side in one run). Python {platform.python_version()}, "
        f"jax {__import__('jax').__version__}. Date {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC.",
        "",
        "Furuta DeLaN (16, 16), float64, free trajectories × 100 samples at 100 Hz. One epoch = what",
        "`train` runs: L_Iτ one full-batch step; L_traj every 2-step window (Tsit5, PID rtol 1e-3 / atol",
        "1e-6) in minibatches of 256 or as one full batch. Each step = value + gradient + AdamW update.",
        "Best of 3 epochs after the first.",
        "",
        "| trajectories | L_Iτ epoch | L_traj epoch (minibatch 256) | L_traj epoch (full batch) | ratio minibatch / L_Iτ | ratio full / L_Iτ |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for n in sizes:
        i, tm, tf = get("itau", n), get("traj", n), get("traj", n, full=True)
        lines.append(
            f"| {n} | {i['epoch_s'] * 1e3:.1f} ms | {tm['epoch_s']:.2f} s ({tm['steps']} steps) | "
            f"{tf['epoch_s']:.2f} s | {tm['epoch_s'] / i['epoch_s']:.0f}× | {tf['epoch_s'] / i['epoch_s']:.0f}× |"
        )
    i64, i256 = get("itau", sizes[0]), get("itau", sizes[-1])
    t64, t256 = get("traj", sizes[0]), get("traj", sizes[-1])
    lines += [
        "",
        f"Scaling {sizes[0]} → {sizes[-1]} trajectories: L_Iτ ×{i256['epoch_s'] / i64['epoch_s']:.1f}, "
        f"L_traj (minibatch) ×{t256['epoch_s'] / t64['epoch_s']:.1f}.",
        "",
        "First call (trace + compile + one step) in a fresh process, JAX persistent compilation cache",
        '(`jax.config.update("jax_compilation_cache_dir", ...)`) empty (cold) then filled (warm). With',
        "that cache on, `_make_step` also stores the traced step (`jax.export`) beside it, so a warm",
        "process skips Python tracing too; `FURUTA_GYM_STEP_CACHE=0` turns that part off:",
        "",
        "| step | cold | warm | target |",
        "|---|---:|---:|---:|",
    ]
    for key, label in (
        (("itau", True), "L_Iτ (64 traj.)"),
        (("traj", True), "L_traj 2-step (256 windows)"),
        (("traj", False), "L_traj 2-step, `FURUTA_GYM_STEP_CACHE=0` (XLA cache only)"),
    ):
        cold, warm = compile_rows[key]
        lines.append(f"| {label} | {cold:.1f} s | {warm:.1f} s | ≤ 4 s |")
    lines += [
        "",
        "Where a first call's time goes without any cache (fresh process; `jax.stages`: trace, lower,",
        "XLA compile, first run):",
        "",
        "| step | trace | lower | XLA compile | run | host callbacks in the HLO |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for loss, label in (("itau", "L_Iτ (64 traj.)"), ("traj", "L_traj 2-step (256 windows)")):
        b = breakdown[loss]
        lines.append(
            f"| {label} | {b['trace']:.1f} s | {b['lower']:.1f} s | {b['compile']:.1f} s | "
            f"{b['run']:.2f} s | {b['host_callbacks']} |"
        )
    lines += [
        "",
        "Before (commit 823962f; this breakdown run on that tree and on this one back to back at load",
        "≈ 10): L_traj trace 11.0 s → 7.4 s, lower 1.3 s → 0.65 s, XLA compile 21.2 s → 20.0 s, host",
        "callbacks 6 → 0. The callbacks were Equinox's runtime checks inside diffrax, which JAX refuses",
        "to store, so the warm first call was 24 s. Now the checks are traced as NaNs (a failed check",
        "is a non-finite loss the NaN guard skips, like a failed solve), the vector field is one jitted",
        "function inside the solve (traced once instead of 7 times), and the stored traced step skips",
        "the remaining tracing. The loss and its gradient are unchanged to 1e-12",
        "(tests/test_compile_cache.py).",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        write_section_text(text)


if __name__ == "__main__":
    main()
