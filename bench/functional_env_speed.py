"""Functional env speed: steps/s of the gymnax-API swing-up beside gymnax's Pendulum-v1.

Measures, in one run, the env steps per second (copies × steps / s) of ``env.step`` — gymnax's,
with its autoreset — vmapped over N copies and scanned over time inside one ``jit``, uniform
random actions drawn in the loop, for

* ``furuta_gym/FurutaSwingUp-v0`` as a functional env (:mod:`furuta_gym.envs.functional`) on the
  analytic model and on the reproduction's DeLaN L_prop checkpoint (one env step = one 20 ms
  control period = 10 RK4 steps of the model);
* gymnax's ``Pendulum-v1`` (one explicit Euler step per env step), the reference,

at N = 1 … 4096, the ratio analytic ÷ Pendulum-v1 at each N, and the swing-up's rates per
physics step (env steps/s × the env's RK4 substeps; a Pendulum-v1 env step is its one physics
step). Best of ``--repeats`` after a compiling warm-up. The results record the cores the process
may run on and ``XLA_FLAGS`` (run it pinned, e.g. ``taskset -c 1`` with
``XLA_FLAGS="--xla_cpu_multi_thread_eigen=false"``, to time one
core). Writes ``results/functional_env_speed/results.json`` and its BENCHMARKS.md section from it
(``--no-write``: neither).

    python bench/functional_env_speed.py           # a few minutes on 2 cores
    python bench/functional_env_speed.py --quick   # N = 1, 64, 4096 with fewer steps
    python bench/functional_env_speed.py --check   # exit 1 if BENCHMARKS.md and the results differ
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import time
from pathlib import Path

from _generated import machine, write_section

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "functional_env_speed" / "results.json"
DELAN = ROOT / "results" / "reproduce" / "runs" / "furuta" / "dln_prop" / "seed0" / "model.eqx"
START, END = "<!-- bench/functional_env_speed.py:start -->", "<!-- bench/functional_env_speed.py:end -->"
SIZES = (1, 4, 16, 64, 256, 1024, 4096)
STEP_BUDGET = 1_000_000  # copies × steps per timed call (fewer copies: more steps, 200 to 20 000)


def runner(env, params, n: int, steps: int):
    """A jitted function of a key: ``steps`` autoresetting steps of ``n`` copies, random actions."""
    import jax
    import jax.numpy as jnp

    space = env.action_space(params)
    step = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def run(key):
        _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, n), params)

        def body(carry, key):
            state, total = carry
            k_act, k_step = jax.random.split(key)
            action = jax.random.uniform(k_act, (n, *space.shape), minval=space.low, maxval=space.high)
            _, state, reward, _, _, _ = step(jax.random.split(k_step, n), state, action, params)
            return (state, total + reward.sum()), None

        return jax.lax.scan(body, (state, jnp.zeros(())), jax.random.split(key, steps))[0][1]

    return jax.jit(run)


def integration_runner(env, params, n: int, steps: int):
    """:func:`runner` without the env: only each step's RK4 integration of the env's model (no
    observation, reward, termination or autoreset), what those cost nothing could reach."""
    import jax

    from furuta_gym.envs.vector import stepping_model
    from furuta_gym.simulate import rk4_zoh_step

    model = stepping_model(env.plant(params))
    advance = jax.vmap(lambda x, u: rk4_zoh_step(model, x, u, env.dt, env.substeps))

    def run(key):
        def body(x, key):
            u = jax.random.uniform(key, (n, 1), minval=-env.max_action, maxval=env.max_action)
            return advance(x, u), None

        x0 = jax.random.uniform(key, (n, 2 * env.n), minval=-0.1, maxval=0.1)
        return jax.lax.scan(body, x0, jax.random.split(key, steps))[0].sum()

    return jax.jit(run)


def steps_per_second(env, params, n: int, repeats: int, budget: int, make_runner=runner) -> float:
    import jax

    steps = min(20_000, max(200, budget // n))
    run = make_runner(env, params, n, steps)
    jax.block_until_ready(run(jax.random.PRNGKey(0)))  # compile
    best = float("inf")
    for k in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run(jax.random.PRNGKey(k + 1)))
        best = min(best, time.perf_counter() - start)
    return n * steps / best


def measure(sizes, repeats: int, budget: int) -> dict:
    import gymnax

    import furuta_gym
    from furuta_gym.envs import functional

    furuta_gym.enable_x64()
    envs = {
        "analytic": functional.make(dynamics="analytic"),
        "delan": functional.make(dynamics=str(DELAN)),
        "gymnax Pendulum-v1": gymnax.make("Pendulum-v1"),
    }
    # physics steps per env step: the swing-up's RK4 substeps; Pendulum-v1 integrates once per step
    substeps = {name: getattr(env, "substeps", 1) for name, (env, _) in envs.items()}
    rates = {name: {} for name in envs}
    for n in sizes:
        for name, (env, params) in envs.items():
            rates[name][n] = steps_per_second(env, params, n, repeats, budget)
            print(f"N = {n:5d}  {name:20s} {rates[name][n]:14,.0f} steps/s", flush=True)
    integration = {}
    for n in sizes:
        integration[n] = steps_per_second(*envs["analytic"], n, repeats, budget, integration_runner)
        print(f"N = {n:5d}  {'analytic integration':20s} {integration[n]:14,.0f} steps/s", flush=True)
    return {
        "machine": machine(),
        "cpu": cpu_conditions(),
        "date": datetime.date.today().isoformat(),
        "sizes": list(sizes),
        "repeats": repeats,
        "budget": budget,
        "steps_per_second": rates,
        "substeps": substeps,
        "analytic_integration_only": integration,
    }


def cpu_conditions() -> str:
    """The cores this process may run on and the XLA thread flags: what the rates are per."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    flags = os.environ.get("XLA_FLAGS", "")
    return f"{cores} of {os.cpu_count()} cores, XLA_FLAGS={flags!r}" if flags else f"{cores} of {os.cpu_count()} cores"


def section(results: dict) -> str:
    rates, sizes, substeps = results["steps_per_second"], results["sizes"], results["substeps"]
    pendulum = rates["gymnax Pendulum-v1"]
    rk4 = {name: {n: rates[name][n] * substeps[name] for n in sizes} for name in ("analytic", "delan")}
    integration = results.get("analytic_integration_only")
    rows = [
        f"| {n:,} | {rates['analytic'][n]:,.0f} | {rates['delan'][n]:,.0f} | {pendulum[n]:,.0f} | "
        f"{rates['analytic'][n] / pendulum[n]:.2f} | {rk4['analytic'][n]:,.0f} | {rk4['delan'][n]:,.0f} |"
        + (f" {integration[n]:,.0f} | {integration[n] / pendulum[n]:.2f} |" if integration else "")
        for n in sizes
    ]
    extra_head = " analytic, integration only | its ÷ Pendulum-v1 |" if integration else ""
    top = max(sizes)
    extra_text = (
        " The integration-only columns time the analytic env's RK4 integration alone (the same 10 steps per env step, "
        "nothing else: no observation, reward, termination or autoreset), the most any saving outside the "
        f"physics could reach: at N = {top:,} it is {integration[top] / pendulum[top]:.2f} of Pendulum-v1's env "
        f"steps/s, and per physics step the swing-up runs at {rk4['analytic'][top] / pendulum[top]:.2f} of "
        "Pendulum-v1's rate."
        if integration
        else ""
    )
    return "\n".join(
        [
            START,
            "## Functional env vs gymnax Pendulum-v1 (`bench/functional_env_speed.py`)",
            "",
            "Env steps per second (copies × steps / s) of gymnax's `env.step` (autoreset included), vmapped "
            "over N copies and scanned inside one `jit`, uniform random actions, best of "
            f"{results['repeats']}. `FurutaSwingUp-v0` as a functional env (one step: a 20 ms control period, "
            "10 RK4 steps of the model; analytic model and the reproduction's DeLaN L_prop) beside gymnax's "
            f"Pendulum-v1 (one Euler step) in the same run. The two RK4 columns are the swing-up's "
            f"rates per physics step (env steps/s × {substeps['analytic']} RK4 steps per env step), beside Pendulum-v1's "
            f"env steps/s, which are its Euler steps/s.{extra_text} Generated from "
            f"`results/functional_env_speed/results.json` ({results['machine']}; run on {results['cpu']}; "
            f"{results['date']}).",
            "",
            "| N | analytic | DeLaN | gymnax Pendulum-v1 | analytic ÷ Pendulum-v1 | analytic, RK4 steps/s "
            "| DeLaN, RK4 steps/s |" + extra_head,
            "|---|---|---|---|---|---|---|" + ("---|---|" if integration else ""),
            *rows,
            END,
        ]
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="N = 1, 64, 4096 and a smaller step budget")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument(
        "--check",
        action="store_true",
        help="measure nothing: exit 1 if BENCHMARKS.md's section differs from the committed results",
    )
    args = parser.parse_args(argv)
    if args.check:
        return write_section(
            committed_section(), START, END, check=True, how_to_fix="run python bench/functional_env_speed.py"
        )
    sizes, budget = ((1, 64, 4096), STEP_BUDGET // 4) if args.quick else (SIZES, STEP_BUDGET)
    results = measure(sizes, args.repeats, budget)
    if not args.no_write:
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(results, indent=1))
        write_section(committed_section(), START, END)
    return 0


def committed_section() -> str:
    """The section of the results file (JSON keeps the copy counts N as strings)."""
    results = json.loads(RESULTS.read_text())
    return section(
        results
        | {"steps_per_second": {k: {int(n): v for n, v in r.items()} for k, r in results["steps_per_second"].items()}}
        | (
            {"analytic_integration_only": {int(n): v for n, v in results["analytic_integration_only"].items()}}
            if "analytic_integration_only" in results
            else {}
        )
    )


if __name__ == "__main__":
    raise SystemExit(main())
