"""SAC (Stable-Baselines3) on the RL preset against the default env, same number of env steps (issue 27).

    python bench/sac_preset.py [--steps 20000] [--seeds 0 1 2] [--eval-every 5000]
    python bench/sac_preset.py --table-only      # regenerate docs/envs.md from the results file
    python bench/sac_preset.py --check           # exit 1 if docs/envs.md and the results differ

Two envs, the same algorithm: SB3's ``SAC("MlpPolicy")`` with its default hyperparameters
(γ = 0.99, lr 3e-4, batch 256, one gradient step per env step), the MuJoCo ground truth in both:

* ``default``: ``furuta_gym/Furuta-v0`` as it comes — 500 Hz, raw (α, β, α̇, β̇) float64, actions
  in volts, 10 s episodes (5 000 steps);
* ``preset``: ``furuta_gym/FurutaSwingUp-v0`` — 50 Hz, (cos α, sin α, cos β, sin β, α̇, β̇) float32,
  actions in [−1, 1] × 5 V, 500-step (10 s) episodes.

Every ``--eval-every`` env steps the deterministic policy runs ``--eval-episodes`` 10 s episodes
from fresh resets of its own env (seeds not used for training). Both envs score the same task
reward (upright × centred × small voltage × small β̇, in [0, 1]) of the same physical state, so
the score is put on one scale: the **return of a 10 s episode at 50 Hz**, i.e. 500 × the
time-averaged reward (0 hanging still, 500 balanced for the whole episode). Results go to
``results/sac_preset/results.json``; the table in docs/envs.md is written from that file.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import time
from pathlib import Path

import furuta_gym  # noqa: F401  first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

from _generated import machine, write_section

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "sac_preset" / "results.json"
DOCS = ROOT / "docs" / "envs.md"
START, END = "<!-- bench/sac_preset.py:start -->", "<!-- bench/sac_preset.py:end -->"
ENVS = {"default": "furuta_gym/Furuta-v0", "preset": "furuta_gym/FurutaSwingUp-v0"}
EPISODE_SECONDS = 10.0
PRESET_RATE_HZ = 50.0  # the common scale: a 10 s episode's return at 50 Hz
EVAL_SEED_BASE = 10_000  # evaluation resets never reuse a training seed


def make_env(name: str, seed: int):
    import gymnasium as gym

    env = gym.make(ENVS[name])
    env.reset(seed=seed)
    env.action_space.seed(seed)
    return env


def evaluate(model, env, episodes: int, seed: int) -> float:
    """Mean time-averaged task reward of the deterministic policy, scaled to a 50 Hz 10 s return."""
    scores = []
    for k in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED_BASE + 100 * seed + k)
        rewards, t = [], 0.0
        dt = 1.0 / env.metadata["render_fps"]  # one frame per control period
        while t < EPISODE_SECONDS - 1e-9:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            rewards.append(float(reward))
            t += dt
            if terminated:  # a diverged episode scores zero for the rest of its 10 s
                rewards += [0.0] * int(round((EPISODE_SECONDS - t) / dt))
                break
        scores.append(PRESET_RATE_HZ * EPISODE_SECONDS * float(np.mean(rewards)))
    return float(np.mean(scores))


def run_one(name: str, seed: int, steps: int, eval_every: int, eval_episodes: int) -> dict:
    import torch
    from stable_baselines3 import SAC

    torch.set_num_threads(1)
    env, eval_env = make_env(name, seed), make_env(name, EVAL_SEED_BASE + seed)
    model = SAC("MlpPolicy", env, seed=seed, verbose=0, device="cpu")
    curve, t0 = [], time.perf_counter()
    for done in range(eval_every, steps + 1, eval_every):
        model.learn(total_timesteps=eval_every, reset_num_timesteps=False)
        curve.append({"steps": done, "return": evaluate(model, eval_env, eval_episodes, seed)})
        print(f"{name} seed {seed}: {done} steps, return {curve[-1]['return']:.1f}", flush=True)
    return {"env": name, "seed": seed, "curve": curve, "seconds": time.perf_counter() - t0}


def table(results: dict) -> str:
    runs = results["runs"]
    steps = sorted({p["steps"] for r in runs for p in r["curve"]})
    seeds = sorted({r["seed"] for r in runs})
    head = (
        "| env steps | "
        + " | ".join(f"{name} (seed {s})" for name in ENVS for s in seeds)
        + " | mean default | mean preset |"
    )
    lines = [head, "|" + "---|" * (len(ENVS) * len(seeds) + 3)]
    for n in steps:
        by = {(r["env"], r["seed"]): p["return"] for r in runs for p in r["curve"] if p["steps"] == n}
        cells = [f"{by[(name, s)]:.1f}" for name in ENVS for s in seeds]
        means = [np.mean([by[(name, s)] for s in seeds]) for name in ENVS]
        lines.append(f"| {n:,} | " + " | ".join(cells) + f" | {means[0]:.1f} | **{means[1]:.1f}** |")
    return "\n".join(lines)


def _verdict(results: dict) -> str:
    """Whether the preset scored higher than the default env, seed by seed, at every evaluation."""
    by = {(r["env"], r["seed"], p["steps"]): p["return"] for r in results["runs"] for p in r["curve"]}
    pairs = [(by[("preset", s, n)], v) for (e, s, n), v in by.items() if e == "default" and ("preset", s, n) in by]
    wins = sum(p > d for p, d in pairs)
    return f"The preset scores higher than the default env in {wins} of {len(pairs)} (seed, steps) pairs. "


def section(results: dict) -> str:
    return "\n".join(
        [
            START,
            "### SAC on the preset vs the default env (`bench/sac_preset.py`)",
            "",
            f'Stable-Baselines3 {results["sb3"]} `SAC("MlpPolicy")` with its default hyperparameters, '
            "the same number of env steps on each env, MuJoCo ground truth. Score: the deterministic "
            "policy's return of a 10 s episode on one scale (500 × the time-averaged task reward, "
            "0 = hanging still, 500 = balanced throughout), mean of "
            f"{results['eval_episodes']} evaluation episodes from fresh resets. "
            f"Generated from `results/sac_preset/results.json` ({results['machine']}, {results['date']}).",
            "",
            table(results),
            "",
            _verdict(results) + "At 500 Hz γ = 0.99 discounts over ~0.2 s, shorter than the ~1 s a swing-up takes, and "
            "the default env's 5 000-step episodes give 4 episodes in 20 000 steps; at 50 Hz the same γ "
            "looks ~2 s ahead and the same steps are 40 episodes.",
            END,
        ]
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--eval-every", type=int, default=5_000)
    ap.add_argument("--eval-episodes", type=int, default=3)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--envs", nargs="+", default=list(ENVS), choices=list(ENVS))
    ap.add_argument("--table-only", action="store_true", help="rewrite docs/envs.md from the results")
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/envs.md is stale")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument(
        "--out", help="write the runs here and stop (for runs split over processes; merge them with --merge)"
    )
    ap.add_argument("--merge", nargs="+", help="result files of split runs to merge into the results")
    args = ap.parse_args(argv)
    if args.check:
        return write_section(
            section(json.loads(RESULTS.read_text())),
            START,
            END,
            path=DOCS,
            check=True,
            how_to_fix="run python bench/sac_preset.py --table-only",
        )
    if args.merge:
        parts = [json.loads(Path(f).read_text()) for f in args.merge]
        merged = dict(parts[0], runs=[r for p in parts for r in p["runs"]])
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(merged, indent=1) + "\n")
    elif not args.table_only:
        import stable_baselines3

        results = {
            "sb3": stable_baselines3.__version__,
            "machine": machine(),
            "date": datetime.date.today().isoformat(),
            "eval_episodes": args.eval_episodes,
            "runs": [],
        }
        out = Path(args.out) if args.out else RESULTS
        for seed in args.seeds:
            for name in args.envs:
                results["runs"].append(run_one(name, seed, args.steps, args.eval_every, args.eval_episodes))
                if not args.no_write:  # after every run: an interrupted sweep keeps what it finished
                    out.parent.mkdir(parents=True, exist_ok=True)
                    out.write_text(json.dumps(results, indent=1) + "\n")
        if args.no_write:
            print(table(results))
            return 0
        if args.out:
            return 0
    results = json.loads(RESULTS.read_text())
    write_section(section(results), START, END, path=DOCS)
    print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
