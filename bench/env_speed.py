"""Single-env speed: furuta_gym's envs vs Gymnasium's InvertedPendulum-v5 (issues 2 and 4).

Measures in one run, with one harness, side by side:

* Gymnasium ``InvertedPendulum-v5`` ``env.step`` calls per second (the reference);
* ``furuta_gym/Furuta-v0`` with the MuJoCo backend: env.step/s and its ratio to
  InvertedPendulum-v5 (target ≥ 1.5);
* the raw ``mj_step`` rate of ``assets/furuta.xml`` (one RK4 step = one 500 Hz control period),
  called from Python and in MuJoCo's own loop (``mj_step(m, d, nstep)``): the ceiling;
* ``Furuta-v0`` with ``dynamics="analytic"`` (the closed-form model in JAX, RK4):
  env.step/s and its ratio to the MuJoCo-backed env (target ≥ 0.5), with the default step kernel
  (C, when a compiler exists) and with ``kernel="xla"``;
* ``Furuta-v0`` with a learned model, an untrained DeLaN of the default architecture (a step
  costs the same whatever the weights): env.step/s and its ratio to the MuJoCo env (target ≥ 0.5),
  both kernels;
* the XLA-kernel envs in a child process that opted into
  :func:`furuta_gym.inline_cpu_dispatch` (JAX runs CPU computations inline instead of handing
  each to a worker thread), with that process's own MuJoCo env measured beside them;
* for information: a plant variant that needs MuJoCo's passive callback (``plant="coulomb"``),
  and ``NMSD-v0`` on both backends.

Harness: ``gymnasium.make(id)`` with its default wrappers (the same for every env), pre-drawn
uniform random actions in each env's action space, timed with ``time.perf_counter`` over runs of
``--steps`` steps; an episode end is reset *outside* the timed segments. Runs of the envs are
interleaved and the best of ``--repeats`` is kept (the machine is shared). Writes/refreshes its
section of BENCHMARKS.md (between markers) unless ``--no-write``.

    python bench/env_speed.py            # ~1 min
    python bench/env_speed.py --quick    # smoke run
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
MARK_START = "<!-- bench/env_speed.py:start -->"
MARK_END = "<!-- bench/env_speed.py:end -->"


def env_steps_per_second(env, actions: np.ndarray) -> float:
    """env.step calls per second over ``actions``; resets happen outside the timed segments."""
    env.reset(seed=0)
    elapsed = 0.0
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            elapsed += time.perf_counter() - start
            env.reset()
            start = time.perf_counter()
    elapsed += time.perf_counter() - start
    return len(actions) / elapsed


def mj_step_rates(steps: int) -> tuple[float, float]:
    """(Python-loop mj_step/s, MuJoCo-loop mj_step/s) of furuta.xml."""
    import mujoco

    from furuta_gym.assets import asset_path

    model = mujoco.MjModel.from_xml_path(str(asset_path("furuta.xml")))
    data = mujoco.MjData(model)
    data.qpos[1] = 0.5
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    python_loop = steps / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    mujoco.mj_step(model, data, steps)
    native_loop = steps / (time.perf_counter() - t0)
    return python_loop, native_loop


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=4000, help="env steps per timed run")
    parser.add_argument("--repeats", type=int, default=7, help="interleaved runs; best is kept")
    parser.add_argument("--quick", action="store_true", help="smoke run: few steps and repeats")
    parser.add_argument("--no-write", action="store_true", help="print only, do not touch BENCHMARKS.md")
    parser.add_argument("--inline-dispatch-child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.repeats = 500, 2
    if args.inline_dispatch_child:
        return _inline_dispatch_child(args)

    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    where = machine()
    mj_python = mj_native = 0.0

    def between_repeats(r: int, best: dict[str, float]) -> None:
        nonlocal mj_python, mj_native
        p, nat = mj_step_rates(args.steps)
        mj_python, mj_native = max(mj_python, p), max(mj_native, nat)
        print(f"repeat {r + 1}/{args.repeats}: " + ", ".join(f"{k} {v:,.0f}/s" for k, v in best.items()))

    best = best_rates(make_cases(), args.steps, args.repeats, between_repeats)

    inline = _measure_inline_dispatch(args)
    ip, fu, an = best["InvertedPendulum-v5"], best["Furuta-v0 mujoco"], best["Furuta-v0 analytic"]
    ratio_ip = fu / ip
    ratio_an = an / fu
    lines = [
        MARK_START,
        "## Single-env speed (`bench/env_speed.py`)",
        "",
        f"Measured {when} on {where}. `gymnasium.make(id)` with its default wrappers for every env, "
        f"uniform random actions, best of {args.repeats} interleaved runs of {args.steps} steps "
        "(resets not timed).",
        "",
        "| quantity | steps/s | ratio | target |",
        "|---|---:|---:|---:|",
        f"| Gymnasium `InvertedPendulum-v5` env.step | {ip:,.0f} | 1 | |",
        f"| `furuta_gym/Furuta-v0` (MuJoCo) env.step | {fu:,.0f} | **{ratio_ip:.2f}** × InvertedPendulum-v5 | ≥ 1.5 |",
        f"| raw `mj_step` of `furuta.xml`, Python loop (ceiling) | {mj_python:,.0f} | {mj_python / fu:.2f} × Furuta-v0 | |",
        f"| raw `mj_step` of `furuta.xml`, MuJoCo's loop | {mj_native:,.0f} | {mj_native / fu:.2f} × Furuta-v0 | |",
        f'| `Furuta-v0`, `dynamics="analytic"` env.step (default `kernel="auto"`: C) | {an:,.0f} | **{ratio_an:.2f}** × MuJoCo env | ≥ 0.5 |',
        f'| — same, `kernel="xla"` (one jitted XLA call per step) | {best["Furuta-v0 analytic xla"]:,.0f} | {best["Furuta-v0 analytic xla"] / fu:.2f} × MuJoCo env | |',
        f"| `Furuta-v0`, `dynamics=<DeLaN>` (untrained, default architecture) env.step (default: C) | {best['Furuta-v0 DeLaN']:,.0f} | **{best['Furuta-v0 DeLaN'] / fu:.2f}** × MuJoCo env | ≥ 0.5 |",
        f'| — same, `kernel="xla"` | {best["Furuta-v0 DeLaN xla"]:,.0f} | {best["Furuta-v0 DeLaN xla"] / fu:.2f} × MuJoCo env | |',
        f"| in a process after `furuta_gym.inline_cpu_dispatch()`: MuJoCo env | {inline['Furuta-v0 mujoco']:,.0f} | 1 | |",
        f'| — `dynamics="analytic"`, `kernel="xla"` env.step | {inline["Furuta-v0 analytic xla"]:,.0f} | {inline["Furuta-v0 analytic xla"] / inline["Furuta-v0 mujoco"]:.2f} × its MuJoCo env | |',
        f'| — `dynamics=<DeLaN>`, `kernel="xla"` env.step | {inline["Furuta-v0 DeLaN xla"]:,.0f} | {inline["Furuta-v0 DeLaN xla"] / inline["Furuta-v0 mujoco"]:.2f} × its MuJoCo env | |',
        f'| `Furuta-v0`, `plant="coulomb"` (passive callback) | {best["Furuta-v0 mujoco plant=coulomb"]:,.0f} | {best["Furuta-v0 mujoco plant=coulomb"] / fu:.2f} × MuJoCo env | |',
        f"| `NMSD-v0` (MuJoCo + cubic-term callback) env.step | {best['NMSD-v0 mujoco']:,.0f} | | |",
        f'| `NMSD-v0`, `dynamics="analytic"` env.step | {best["NMSD-v0 analytic"]:,.0f} | {best["NMSD-v0 analytic"] / best["NMSD-v0 mujoco"]:.2f} × NMSD MuJoCo | |',
        "",
        "One Furuta env.step is one RK4 step of 2 ms (500 Hz control). InvertedPendulum-v5 takes two "
        "RK4 steps of 20 ms with collision detection per env.step; Furuta-v0 skips MuJoCo's "
        "constraint pipeline (no contacts) and keeps its Python step lean (scalar fast paths, "
        "cached MjData views; allocations only for the returned observation and info). A model "
        "backend's step is one JAX function (RK4 of the forward dynamics JAX derives by autodiff). "
        'With `kernel="xla"` it is one jitted XLA call per env.step: a DeLaN step compiles to '
        "~150 XLA:CPU kernels and the call costs ~19 µs or more of fixed dispatch and per-kernel "
        'overhead for ~12 k multiply-adds. The default `kernel="auto"` lowers the same jaxpr to '
        "one C function (`furuta_gym/_ckernel/`, compiled once per model structure with the "
        "system's C compiler and cached on disk) called through ctypes on fixed buffers: ~5 µs for "
        "the DeLaN step. `furuta_gym.inline_cpu_dispatch()` (opt-in, process-wide, before any JAX "
        "computation) runs JAX's CPU computations on the calling thread; its rows come from a child "
        "process that measured its own MuJoCo env beside them. The machine is shared, so absolute "
        "rates vary between runs; the ratios are measured side by side.",
        MARK_END,
    ]
    return publish("\n".join(lines), MARK_START, MARK_END, write=not args.no_write)


def make_cases(names=None) -> dict:
    """The envs this benchmark times, by name (all of them, or those in ``names``)."""
    import gymnasium as gym
    import jax

    from furuta_gym.models import make_model

    furuta_gym.enable_x64()

    def delan():
        return make_model("furuta", "dln", key=jax.random.PRNGKey(0))

    makers = {
        "InvertedPendulum-v5": lambda: gym.make("InvertedPendulum-v5"),
        "Furuta-v0 mujoco": lambda: gym.make("furuta_gym/Furuta-v0"),
        "Furuta-v0 analytic": lambda: gym.make("furuta_gym/Furuta-v0", dynamics="analytic"),
        "Furuta-v0 analytic xla": lambda: gym.make("furuta_gym/Furuta-v0", dynamics="analytic", kernel="xla"),
        "Furuta-v0 DeLaN": lambda: gym.make("furuta_gym/Furuta-v0", dynamics=delan()),
        "Furuta-v0 DeLaN xla": lambda: gym.make("furuta_gym/Furuta-v0", dynamics=delan(), kernel="xla"),
        "Furuta-v0 mujoco plant=coulomb": lambda: gym.make("furuta_gym/Furuta-v0", plant="coulomb"),
        "NMSD-v0 mujoco": lambda: gym.make("furuta_gym/NMSD-v0"),
        "NMSD-v0 analytic": lambda: gym.make("furuta_gym/NMSD-v0", dynamics="analytic"),
    }
    return {name: make() for name, make in makers.items() if names is None or name in names}


def best_rates(cases: dict, steps: int, repeats: int, between_repeats=None) -> dict[str, float]:
    """Best env.step/s of each env over ``repeats`` interleaved runs of ``steps`` pre-drawn uniform
    random actions, after a warm-up run (JIT compiles, caches)."""
    rng = np.random.default_rng(0)
    actions = {
        name: rng.uniform(env.action_space.low, env.action_space.high, (steps, 1)) for name, env in cases.items()
    }
    for name, env in cases.items():
        env_steps_per_second(env, actions[name][: min(300, steps)])
    best = {name: 0.0 for name in cases}
    for r in range(repeats):
        for name, env in cases.items():
            best[name] = max(best[name], env_steps_per_second(env, actions[name]))
        if between_repeats is not None:
            between_repeats(r, best)
    return best


#: the envs the inline-dispatch child process times (its own MuJoCo env is the reference)
INLINE_CASES = ("Furuta-v0 mujoco", "Furuta-v0 analytic xla", "Furuta-v0 DeLaN xla")


def _inline_dispatch_child(args) -> int:
    """Child process: opt into inline dispatch before JAX starts, measure, print JSON."""
    import json

    furuta_gym.inline_cpu_dispatch()
    best = best_rates(make_cases(INLINE_CASES), args.steps, args.repeats)
    print("INLINE " + json.dumps(best))
    return 0


def _measure_inline_dispatch(args) -> dict[str, float]:
    import json
    import subprocess

    cmd = [
        sys.executable,
        __file__,
        "--inline-dispatch-child",
        "--steps",
        str(args.steps),
        "--repeats",
        str(args.repeats),
    ]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    line = next(l for l in out.stdout.splitlines() if l.startswith("INLINE "))
    result = json.loads(line[len("INLINE ") :])
    print("inline dispatch (child process): " + ", ".join(f"{k} {v:,.0f}/s" for k, v in result.items()))
    return result


if __name__ == "__main__":
    sys.exit(main())
