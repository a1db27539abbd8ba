"""Swing-up policies trained only inside learned models, run on the MuJoCo ground truth (issue 46, item 3).

PPO (``furuta_gym.rl``, the settings of ``examples/ppo_swingup.py``) trains on the functional
``FurutaSwingUp-v0`` whose dynamics is one of the full reproduction's Furuta checkpoints
(``results/reproduce/runs/furuta/<model>_<loss>/seed0/model.eqx``: DeLaN L_prop, augmented DeLaN
L_prop and their baselines DeLaN L_traj and augmented DeLaN L_aph) or the analytic model, for
reference. The policy never sees MuJoCo while training. It is then deployed on
``gym.make("furuta_gym/FurutaSwingUp-v0")`` (MuJoCo) through ``GymnasiumPolicy``, on the nominal
plant and on the ``cable_spring`` and ``coulomb`` variants, from x0 = 0 and 30 seeded starts near
rest (``controllers.near_rest_starts``, seed 0, as the control benchmarks draw them).

Success is the control benchmarks' (``controllers.episode_metrics``): the pendulum within 0.1 rad
of upright for 2 s without interruption, at any time in the 10 s episode, without divergence.
``balanced_end`` is the example's looser check (within 0.2 rad over the last 2 s).

Domain randomisation (``--randomize``), drawn anew at every training reset: for the analytic
model, every physical parameter but g within ±spread (``Plant(randomize=spread)``); a learned
model has no physical parameters, so its overall scale (the factor on L and τ_NC that free data
leave open, and the post-training scale fit sets) is drawn within ±spread — the same as an input
gain error of that size, the model's least certain number.

    python studies/rl_from_learned_models.py --model dln_prop [--randomize] [--seed 0]
    python studies/rl_from_learned_models_table.py      # the docs/rl.md block

Writes ``results/rl_learned/<model>_<nominal|randomized>_seed<k>.json`` and the policy beside it
(``.eqx``); an existing result is kept unless ``--force``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import equinox as eqx
import gymnasium
import jax
import numpy as np

from furuta_gym.controllers import episode_metrics, near_rest_starts
from furuta_gym.envs import Plant, functional
from furuta_gym.rl import GymnasiumPolicy, PPOSettings, episode_returns, train_ppo

os.environ.setdefault("MUJOCO_GL", "egl")
ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "rl_learned"
CHECKPOINTS = ROOT / "results" / "reproduce" / "runs" / "furuta"
SWINGUP = "furuta_gym/FurutaSwingUp-v0"
#: label of each row, in the table's order (the analytic model first, for reference)
MODELS = {
    "analytic": "analytic (reference)",
    "dln_prop": "DeLaN L_prop",
    "adln_prop": "augmented DeLaN L_prop",
    "dln_traj": "DeLaN L_traj (baseline)",
    "adln_aph": "augmented DeLaN L_aph (baseline)",
}
PLANTS = (None, "cable_spring", "coulomb")
#: examples/ppo_swingup.py's settings: 6 M env steps, 256 copies × 128 steps per update
CONFIG = PPOSettings(total_timesteps=6_000_000, num_envs=256, num_steps=128)
SPREAD = 0.1  # relative spread of the randomised parameters (the example's --randomize 0.1)
STARTS, STARTS_SEED = 30, 0
BALANCE_STEPS, BALANCE_TOLERANCE = 100, 0.2  # the example's check: last 2 s at 50 Hz within 0.2 rad


class ScaleRandomized(functional.FunctionalEnv):
    """The functional env of a learned model whose overall scale is drawn at every reset within
    ±``spread`` (kept in ``state.physical``, where an analytic model keeps its drawn parameters)."""

    def __init__(self, template, spread: float, **kwargs):
        super().__init__(template, **kwargs)
        self.spread = float(spread)

    def _draw_physical(self, key, params):
        nominal = eqx.combine(params.model, self._static).scale
        return nominal * (1.0 + self.spread * jax.random.uniform(key, (), float, -1.0, 1.0))

    def plant(self, params, state=None):
        model = eqx.combine(params.model, self._static)
        if state is not None and state.physical is not None:
            model = eqx.tree_at(lambda m: m.scale, model, state.physical)
        return model


def checkpoint(model: str) -> str:
    return "analytic" if model == "analytic" else str(CHECKPOINTS / model / "seed0" / "model.eqx")


def training_env(model: str, randomize: bool):
    """(env, params) PPO trains on: the model's functional swing-up, randomised if asked."""
    if not randomize:
        return functional.make(SWINGUP, dynamics=checkpoint(model))
    if model == "analytic":
        return functional.make(SWINGUP, dynamics="analytic", plant=Plant(randomize=SPREAD))
    gym_env = gymnasium.make(SWINGUP, dynamics=checkpoint(model), kernel="xla", disable_env_checker=True)
    env = ScaleRandomized(gym_env.unwrapped, SPREAD, max_steps=gym_env.spec.max_episode_steps, name=SWINGUP)
    return env, env.default_params


def train(model: str, randomize: bool, config: PPOSettings, seed: int):
    """(policy, last training returns, wall seconds with compilation, deterministic return on
    the nominal training model)."""
    env, params = training_env(model, randomize)
    run = eqx.filter_jit(lambda key: train_ppo(env, params, config, key))
    start = time.perf_counter()
    policy, metrics = jax.block_until_ready(run(jax.random.PRNGKey(seed)))
    wall = time.perf_counter() - start
    returns = np.asarray(metrics["return"])[np.asarray(metrics["episodes"]) > 0]
    check_env, check_params = functional.make(SWINGUP, dynamics=checkpoint(model))
    own = episode_returns(check_env, check_params, lambda obs, key: policy(obs), jax.random.PRNGKey(1), 32)
    return policy, returns, wall, float(np.mean(own))


def run_episode(act, env: gymnasium.Env, x0: np.ndarray, seed: int) -> dict:
    """One preset episode from ``x0``: its return, the benchmarks' success, the example's check."""
    obs, info = env.reset(seed=seed, options={"state": x0})
    xs, us, total = [info["state"]], [], 0.0
    for _ in range(env.spec.max_episode_steps):
        obs, reward, terminated, truncated, info = env.step(act(obs))
        total += float(reward)
        xs.append(info["state"])
        us.append(float(np.asarray(info["action"]).reshape(-1)[0]))
        if terminated or truncated:
            break
    xs = np.asarray(xs, float)
    full = len(us) == env.spec.max_episode_steps
    if terminated or info.get("diverged", False):
        xs = np.concatenate([xs, np.full((1, 4), np.inf)])  # scored as diverged, as evaluate_on_env does
    metrics = episode_metrics(xs, np.asarray(us), float(env.unwrapped.dt))
    tail = np.abs(np.mod(xs[-BALANCE_STEPS:, 1], 2 * math.pi) - math.pi)
    return {
        "return": total,
        "success": metrics.success,
        "time_to_upright": metrics.time_to_upright,
        "balanced_end": bool(full and not terminated and np.all(tail < BALANCE_TOLERANCE)),
    }


def evaluate(policy, plant: str | None) -> dict:
    """The policy on the MuJoCo preset (``plant`` variant) from x0 = 0 and the seeded starts."""
    return evaluate_actor(lambda env: GymnasiumPolicy(policy, env.action_space), plant)


def evaluate_actor(actor_for: Callable[[gymnasium.Env], Callable], plant: str | None) -> dict:
    """:func:`evaluate` for any policy: ``actor_for(env)`` gives the observation → action map."""
    env = gymnasium.make(SWINGUP, plant=plant) if plant else gymnasium.make(SWINGUP)
    try:
        act = actor_for(env)
        x0s = np.concatenate([np.zeros((1, 4)), near_rest_starts(STARTS, STARTS_SEED, include_rest=False)])
        episodes = [run_episode(act, env, x0, seed) for seed, x0 in enumerate(x0s)]
    finally:
        env.close()
    seeded = episodes[1:]
    return {
        "x0": episodes[0],
        "seeded": seeded,
        "seeded_success": float(np.mean([e["success"] for e in seeded])),
        "seeded_balanced_end": float(np.mean([e["balanced_end"] for e in seeded])),
        "seeded_mean_return": float(np.mean([e["return"] for e in seeded])),
    }


def result_path(model: str, randomize: bool, seed: int) -> Path:
    return OUT / f"{model}_{'randomized' if randomize else 'nominal'}_seed{seed}.json"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", choices=tuple(MODELS), required=True)
    ap.add_argument("--randomize", action="store_true", help=f"domain randomisation (spread {SPREAD})")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=CONFIG.total_timesteps)
    ap.add_argument("--force", action="store_true", help="train again even if the result exists")
    args = ap.parse_args(argv)
    path = result_path(args.model, args.randomize, args.seed)
    if path.is_file() and not args.force:
        print(f"{path} exists (--force to train again)")
        return 0
    furuta_gym.enable_x64()
    config = PPOSettings(**{**CONFIG.__dict__, "total_timesteps": args.steps})
    policy, returns, wall, own = train(args.model, args.randomize, config, args.seed)
    print(f"{args.model}: {args.steps:,} steps in {wall:.0f} s; return on its own model {own:.1f}", flush=True)
    randomization = None
    if args.randomize:
        randomization = {"spread": SPREAD, "over": "physical parameters" if args.model == "analytic" else "scale"}
    doc = {
        "model": args.model,
        "label": MODELS[args.model],
        "dynamics": checkpoint(args.model).replace(str(ROOT) + os.sep, ""),
        "randomize": randomization,
        "seed": args.seed,
        "steps": args.steps,
        "train_seconds": wall,
        "train_returns": returns.tolist(),
        "model_return": own,
        "starts_seed": STARTS_SEED,
        "mujoco": {plant or "nominal": evaluate(policy, plant) for plant in PLANTS},
    }
    for plant, ev in doc["mujoco"].items():
        print(
            f"  MuJoCo {plant}: x0 success {ev['x0']['success']} (return {ev['x0']['return']:.0f}); "
            f"{STARTS} starts: {100 * ev['seeded_success']:.0f} % success",
            flush=True,
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1))
    eqx.tree_serialise_leaves(path.with_suffix(".eqx"), policy)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
