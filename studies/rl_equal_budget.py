"""SB3 SAC and PPO in one ``jit`` at the same env-step budgets, scored alike on MuJoCo (issue 46, item 4).

Both learn the swing-up of ``FurutaSwingUp-v0``; they differ in where they step and how:

* ``sac``: Stable-Baselines3 ``SAC("MlpPolicy")`` with its defaults (one gradient step per env step,
  1 torch thread) on the MuJoCo preset itself, as ``bench/sac_preset.py`` runs it. One run;
  at each budget in ``--budgets`` its deterministic policy is scored.
* ``ppo``: ``furuta_gym.rl.train_ppo`` with ``studies/rl_from_learned_models.py``'s settings
  (256 copies × 128 steps per update) on the functional env of the analytic model, one run per
  budget (its learning-rate schedule spans the run's own budget; it takes whole updates of
  32,768 steps, at least one). It never sees MuJoCo in training.

The score is ``rl_from_learned_models.py``'s: the deterministic policy on the MuJoCo preset from
x0 = 0 and 30 seeded starts near rest; success = within 0.1 rad of upright for 2 s (the control
benchmarks' rule). The largest budget is also scored on the ``cable_spring`` and ``coulomb``
plants. Training wall excludes the scoring.

    python studies/rl_equal_budget.py --algo sac [--budgets N ...]   # default: BUDGETS["sac"]
    python studies/rl_equal_budget.py --algo ppo [--budgets N ...]   # default: BUDGETS["ppo"]
    python bench/rl_wall_time.py        # the BENCHMARKS.md block

Writes ``results/rl_equal_budget/<algo>_seed<k>.json``, rewritten after every budget (an
interrupted run keeps what it finished); an existing budget is kept unless ``--force``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py: machine()

from _generated import machine  # noqa: E402
from rl_from_learned_models import CONFIG, PLANTS, evaluate_actor, train  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "rl_equal_budget"
#: the budgets of the committed results: SAC's where it learns; PPO's from one update (32,768 steps) to its recipe's 6 M
BUDGETS = {
    "sac": (5_000, 10_000, 15_000, 20_000, 25_000, 50_000, 100_000, 200_000),
    "ppo": (50_000, 100_000, 200_000, 300_000, 1_000_000, 3_000_000, 6_000_000),
}


def _save(path: Path, doc: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1) + "\n")


def _scores(actor_for, final: bool) -> dict:
    """MuJoCo scores of one policy: the nominal plant, and every variant at the last budget."""
    return {plant or "nominal": evaluate_actor(actor_for, plant) for plant in (PLANTS if final else (None,))}


def run_sac(budgets: list[int], seed: int, doc: dict, path: Path) -> None:
    import gymnasium
    import stable_baselines3
    import torch
    from stable_baselines3 import SAC

    torch.set_num_threads(1)
    env = gymnasium.make("furuta_gym/FurutaSwingUp-v0")
    env.reset(seed=seed)
    env.action_space.seed(seed)
    model = SAC("MlpPolicy", env, seed=seed, verbose=0, device="cpu")
    doc.update(library=f"stable-baselines3 {stable_baselines3.__version__}, torch {torch.__version__}")
    wall, done = 0.0, 0
    for budget in budgets:
        start = time.perf_counter()
        model.learn(total_timesteps=budget - done, reset_num_timesteps=done == 0)
        wall, done = wall + time.perf_counter() - start, budget
        actor = lambda env: lambda obs: model.predict(obs, deterministic=True)[0]  # noqa: E731
        doc["budgets"][str(budget)] = {"train_seconds": wall, "mujoco": _scores(actor, budget == budgets[-1])}
        _report(budget, doc)
        _save(path, doc)


def run_ppo(budgets: list[int], seed: int, doc: dict, path: Path, force: bool) -> None:
    import jax

    import furuta_gym
    from furuta_gym.rl import GymnasiumPolicy, PPOSettings

    furuta_gym.enable_x64()
    doc.update(
        library=f"furuta_gym.rl (jax {jax.__version__})", config={**CONFIG.__dict__, "hidden": list(CONFIG.hidden)}
    )
    for budget in budgets:
        if str(budget) in doc["budgets"] and not force:
            continue
        config = PPOSettings(**{**CONFIG.__dict__, "total_timesteps": budget})
        policy, _, wall, own = train("analytic", False, config, seed)
        scores = _scores(lambda env, policy=policy: GymnasiumPolicy(policy, env.action_space), budget == budgets[-1])
        taken = config.num_updates * config.num_envs * config.num_steps  # whole updates only
        doc["budgets"][str(budget)] = {"env_steps": taken, "train_seconds": wall, "model_return": own, "mujoco": scores}
        _report(budget, doc)
        _save(path, doc)


def _report(budget: int, doc: dict) -> None:
    row = doc["budgets"][str(budget)]
    ev = row["mujoco"]["nominal"]
    print(
        f"{doc['algo']} {budget:,} steps, {row['train_seconds']:.0f} s: x0 return {ev['x0']['return']:.0f}, "
        f"30 starts {100 * ev['seeded_success']:.0f} % (mean return {ev['seeded_mean_return']:.0f})",
        flush=True,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--algo", choices=("sac", "ppo"), required=True)
    ap.add_argument("--budgets", type=int, nargs="+", help="env-step budgets (default: BUDGETS[algo])")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--force", action="store_true", help="run budgets that have a result again")
    args = ap.parse_args(argv)
    budgets = sorted(args.budgets or BUDGETS[args.algo])
    path = OUT / f"{args.algo}_seed{args.seed}.json"
    doc = json.loads(path.read_text()) if path.is_file() and not args.force else {}
    if args.algo == "sac" and doc.get("budgets") and not args.force:
        print(f"{path} exists (--force to run SAC again: its budgets are one run)")
        return 0
    doc = {
        "algo": args.algo,
        "seed": args.seed,
        "machine": machine(),
        "date": time.strftime("%Y-%m-%d"),
        "budgets": {},
        **doc,
    }
    if args.algo == "sac":
        run_sac(budgets, args.seed, doc, path)
    else:
        run_ppo(budgets, args.seed, doc, path, args.force)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
