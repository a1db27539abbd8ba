"""Train a Furuta swing-up with PPO inside one jit, then run the policy on the MuJoCo env.

    pip install -e ".[rl]"
    python examples/ppo_swingup.py [--dynamics analytic] [--steps 6000000] [--seed 0]
                                   [--plant coulomb] [--randomize 0.1] [--out results/ppo_swingup/run.json]

Training runs on the functional env (``furuta_gym.envs.functional``: the RL preset
``furuta_gym/FurutaSwingUp-v0`` as pure JAX, on ``--dynamics``: ``analytic`` or a checkpoint
path, with an optional ``--randomize`` spread of the physical parameters per reset). The trained
policy is then deployed as people would: a NumPy callable (``furuta_gym.rl.GymnasiumPolicy``)
stepping ``gym.make("furuta_gym/FurutaSwingUp-v0")``, the MuJoCo ground truth (``--plant``: a
plant variant of it), from x0 = 0 and from 30 seeded starts near rest. A start *succeeds* when the
pendulum is balanced for the episode's last 2 s: within 0.2 rad of upright at every step.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import equinox as eqx
import gymnasium as gym
import jax
import numpy as np

import furuta_gym
from furuta_gym.envs import Plant, functional
from furuta_gym.rl import GymnasiumPolicy, PPOSettings, episode_returns, train_ppo

os.environ.setdefault("MUJOCO_GL", "egl")
SWINGUP = "furuta_gym/FurutaSwingUp-v0"
#: PPO's settings for the swing-up (PPOSettings defaults, more copies and steps)
CONFIG = PPOSettings(total_timesteps=6_000_000, num_envs=256, num_steps=128)
BALANCE_STEPS = 100  # the last 2 s at 50 Hz
UPRIGHT_TOLERANCE = 0.2  # rad from upright


def train(dynamics: str, config: PPOSettings, seed: int, randomize: float | None):
    """(policy, per-update returns, wall seconds including compilation)."""
    env, params = functional.make(SWINGUP, dynamics=dynamics, plant=Plant(randomize=randomize) if randomize else None)
    run = eqx.filter_jit(lambda key: train_ppo(env, params, config, key))
    start = time.perf_counter()
    policy, metrics = jax.block_until_ready(run(jax.random.PRNGKey(seed)))
    wall = time.perf_counter() - start
    returns = np.asarray(metrics["return"])[np.asarray(metrics["episodes"]) > 0]
    check_env, check_params = functional.make(SWINGUP, dynamics=dynamics)
    model_return = episode_returns(check_env, check_params, lambda obs, key: policy(obs), jax.random.PRNGKey(1), 32)
    return policy, returns, wall, float(np.mean(model_return))


def run_episode(act, env: gym.Env, seed: int | None, state=None) -> tuple[float, bool]:
    """(return, balanced for the last 2 s) of one preset episode on ``env``."""
    options = None if state is None else {"state": state}
    obs, _ = env.reset(seed=seed, options=options)
    total, betas = 0.0, []
    for _ in range(env.spec.max_episode_steps):
        obs, reward, terminated, truncated, info = env.step(act(obs))
        total += reward
        betas.append(info["state"][1])
        if terminated or truncated:
            break
    tail = np.asarray(betas[-BALANCE_STEPS:])
    off_upright = np.abs(np.mod(tail, 2 * math.pi) - math.pi)
    return total, len(betas) == env.spec.max_episode_steps and bool(np.all(off_upright < UPRIGHT_TOLERANCE))


def evaluate_on_mujoco(policy, plant: str | None, starts: int = 30) -> dict:
    """The policy on the MuJoCo preset env: from x0 = 0 and from ``starts`` seeded resets."""
    env = gym.make(SWINGUP, plant=plant) if plant else gym.make(SWINGUP)
    act = GymnasiumPolicy(policy, env.action_space)
    rest_return, rest_ok = run_episode(act, env, None, np.zeros(4))
    seeded = [run_episode(act, env, 10_000 + k) for k in range(starts)]
    return {
        "x0_return": rest_return,
        "x0_balanced": rest_ok,
        "seeded_returns": [r for r, _ in seeded],
        "seeded_success": float(np.mean([ok for _, ok in seeded])),
    }


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dynamics", default="analytic")
    parser.add_argument("--steps", type=int, default=CONFIG.total_timesteps)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--randomize", type=float, default=None)
    parser.add_argument("--plant", default=None, help="evaluate on this MuJoCo plant variant (e.g. coulomb)")
    parser.add_argument("--out", type=Path, default=None, help="write the results (JSON) and the policy beside them")
    args = parser.parse_args(argv)
    furuta_gym.enable_x64()
    config = PPOSettings(**{**CONFIG.__dict__, "total_timesteps": args.steps})
    policy, returns, wall, model_return = train(args.dynamics, config, args.seed, args.randomize)
    print(
        f"trained {args.steps:,} steps in {wall:.0f} s; training return {returns[-3:].mean():.1f}, "
        f"deterministic return on the training model {model_return:.1f}"
    )
    result = {
        "dynamics": args.dynamics,
        "seed": args.seed,
        "steps": args.steps,
        "randomize": args.randomize,
        "train_seconds": wall,
        "train_returns": returns.tolist(),
        "model_return": model_return,
        "mujoco": evaluate_on_mujoco(policy, args.plant),
        "plant": args.plant,
    }
    mj = result["mujoco"]
    print(
        f"MuJoCo{' (' + args.plant + ')' if args.plant else ''}: x0 = 0 return {mj['x0_return']:.1f} "
        f"balanced {mj['x0_balanced']}; 30 seeded starts: mean return {np.mean(mj['seeded_returns']):.1f}, "
        f"balanced {100 * mj['seeded_success']:.0f} %"
    )
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=1))
        eqx.tree_serialise_leaves(args.out.with_suffix(".eqx"), policy)
    return result


if __name__ == "__main__":
    main()
