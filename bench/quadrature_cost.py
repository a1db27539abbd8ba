"""Cost of one L_Iτ training step per quadrature rule (trapezoid, Simpson, Hermite), side by side.

One step is what an epoch of the reproduction's L_Iτ-alone stage runs: value + gradient + AdamW
update over all integral windows of 64 free 1 s Furuta trajectories at 100 Hz (the paper's
training set), built by :func:`furuta_gym.training.train.training_step` exactly as training builds
it (augmented DeLaN with its minimum-norm term μ·P_a, which the Hermite rule also integrates at
its interior nodes). Rules are timed interleaved, best of several rounds, in one process, so the
ratios are measured under the same load.

Run: ``python bench/quadrature_cost.py`` (≈ 1-2 min). Rewrites its section of BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import datetime
import time

from _generated import machine, write_section
from loss_cost import furuta_free_data

SECTION = "quadrature_cost"
RULES = ("trapezoid", "simpson", "hermite")


def make_step(kind: str, rule: str, trajs):
    import jax

    from furuta_gym.models import make_model
    from furuta_gym.training.losses import make_windows
    from furuta_gym.training.train import AUGMENTATION_WEIGHT, TrainSettings, training_step

    model = make_model("furuta", kind, jax.random.PRNGKey(0))
    config = TrainSettings.for_system("furuta", quadrature=rule, progress=False)
    mu = AUGMENTATION_WEIGHT.get(("furuta", kind), 0.0)
    step, params, opt_state = training_step(model, config, "itau", augmentation_weight=mu)
    windows = make_windows(trajs, 101, stride=100, cover_end=True)
    return step, params, opt_state, windows


def measure(kinds=("dln", "adln"), rounds: int = 5, steps: int = 20) -> dict:
    import jax
    import jax.numpy as jnp

    import furuta_gym

    furuta_gym.enable_x64()
    trajs = furuta_free_data(64, samples=101)
    lam, lr = jnp.asarray(0.0), jnp.asarray(1e-3)
    results = {}
    for kind in kinds:
        cases = {rule: make_step(kind, rule, trajs) for rule in RULES}
        for step, params, opt, w in cases.values():
            jax.block_until_ready(step(params, opt, None, w, lam, lr)[2]["total"])  # compile
        best = {rule: float("inf") for rule in RULES}
        for _ in range(rounds):
            for rule, (step, params, opt, w) in cases.items():
                t0 = time.perf_counter()
                for _ in range(steps):
                    out = step(params, opt, None, w, lam, lr)
                jax.block_until_ready(out[2]["total"])
                best[rule] = min(best[rule], (time.perf_counter() - t0) / steps)
        results[kind] = best
    return results


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args(argv)
    header = machine()  # its load average is read now, before the measurement
    results = measure()
    lines = [
        f"<!-- {SECTION}:start -->",
        "## L_Iτ step cost per quadrature rule (`python bench/quadrature_cost.py`)",
        "",
        f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC, {header}. One full-batch L_Iτ step (value + gradient + AdamW) over 64 free 1 s "
        "Furuta trajectories at 100 Hz, best of 5 rounds of 20 steps, the rules interleaved in one "
        "process. Augmented DeLaN includes its minimum-norm term μ·P_a.",
        "",
        "| model | trapezoid ms | Simpson ms | Hermite ms | Hermite / Simpson |",
        "|---|---:|---:|---:|---:|",
    ]
    for kind, best in results.items():
        lines.append(
            f"| {kind} | {best['trapezoid'] * 1e3:.1f} | {best['simpson'] * 1e3:.1f} | "
            f"{best['hermite'] * 1e3:.1f} | {best['hermite'] / best['simpson']:.2f} |"
        )
    lines += [
        "",
        "Hermite evaluates ∂L/∂q + τ_NC (and, with F_a, M̂⁻¹F_a) at two Gauss nodes per sampling "
        "interval instead of once per sample; the momentum is still taken at the samples.",
        f"<!-- {SECTION}:end -->",
    ]
    text = "\n".join(lines)
    print(text)
    if not args.no_write:
        write_section(text, f"<!-- {SECTION}:start -->", f"<!-- {SECTION}:end -->")


if __name__ == "__main__":
    main()
