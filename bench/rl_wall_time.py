"""Wall time to a trained swing-up: PPO in one jit on the functional env vs SB3 SAC on the preset (issue 46).

    python bench/rl_wall_time.py [--check]

Reads what the runs wrote, trains nothing: ``results/rl_learned/*_nominal_seed0.json``
(``studies/rl_from_learned_models.py``: PPO on the functional ``FurutaSwingUp-v0`` of a model,
deployed on the MuJoCo env) and ``results/sac_preset/results.json`` (``bench/sac_preset.py``: SB3
SAC stepping the MuJoCo preset itself), and writes their BENCHMARKS.md section. SAC is not run at
PPO's env-step budget: at its measured rate that budget would take days on this machine; its
row is its own 20 000-step run, so the comparison is wall time to a policy and what the policy
does, not equal env steps.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from _generated import write_section

ROOT = Path(__file__).resolve().parents[1]
PPO = ROOT / "results" / "rl_learned"
SAC = ROOT / "results" / "sac_preset" / "results.json"
START, END = "<!-- bench/rl_wall_time.py:start -->", "<!-- bench/rl_wall_time.py:end -->"
ORDER = ("analytic", "dln_prop", "adln_prop", "dln_traj", "adln_aph")  # docs/rl.md's row order


def ppo_rows() -> list[str]:
    rows = []
    for model in ORDER:
        path = PPO / f"{model}_nominal_seed0.json"
        if not path.is_file():
            continue
        doc = json.loads(path.read_text())
        ev = doc["mujoco"]["nominal"]
        rows.append(
            f"| PPO in one `jit`, functional env on {doc['label']} | {doc['steps']:,} | "
            f"{doc['train_seconds']:.0f} | {ev['x0']['return']:.0f} | {ev['seeded_mean_return']:.0f} | "
            f"{100 * ev['seeded_success']:.0f} % |"
        )
    return rows


def sac_rows() -> list[str]:
    if not SAC.is_file():
        return []
    doc = json.loads(SAC.read_text())
    runs = [r for r in doc["runs"] if r["env"] == "preset"]
    final = [r["curve"][-1]["return"] for r in runs]
    seconds = [r["seconds"] for r in runs]
    return [
        f"| SB3 SAC on the MuJoCo preset (`bench/sac_preset.py`, {len(runs)} seeds, wall includes its "
        f"evaluations) | {runs[0]['curve'][-1]['steps']:,} | {min(seconds):.0f}–{max(seconds):.0f} | — | "
        f"{np.mean(final):.0f} (fresh resets, mean of seeds) | not scored |"
    ]


def section() -> str:
    head = (
        "| how | env steps | training wall (s) | MuJoCo return, x0 = 0 | MuJoCo mean return, 30 starts | "
        "success, 30 starts |"
    )
    return "\n".join(
        [
            START,
            "## Wall time to a trained swing-up (`bench/rl_wall_time.py`)",
            "",
            "Training wall time (compilation included) and what the deterministic policy then does on the MuJoCo "
            "`FurutaSwingUp-v0` (return of 500; success: within 0.1 rad of upright for 2 s, as the control "
            "benchmarks score it, from `near_rest_starts(30, seed=0)`). PPO rows: one seed each, pinned to one "
            "core with a one-thread XLA pool on the 2-core machine shared with other jobs "
            "(`studies/rl_from_learned_models.py`, results/rl_learned/; docs/rl.md has every row). SAC is "
            "not run at PPO's budget: at its rate the same env steps would take days here.",
            "",
            head,
            "|---|---|---|---|---|---|",
            *ppo_rows(),
            *sac_rows(),
            END,
        ]
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if BENCHMARKS.md's section is stale")
    args = ap.parse_args(argv)
    text = section()
    status = write_section(text, START, END, check=args.check, how_to_fix="run python bench/rl_wall_time.py")
    if not args.check:
        print(text)
    return status


if __name__ == "__main__":
    sys.exit(main())
