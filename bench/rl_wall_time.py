"""Wall time to a trained swing-up: PPO in one jit on the functional env vs SB3 SAC on the preset (issue 46).

    python bench/rl_wall_time.py [--check]

Reads what the runs wrote, trains nothing: ``results/rl_learned/*_nominal_seed0.json``
(``studies/rl_from_learned_models.py``: PPO on the functional ``FurutaSwingUp-v0`` of a model,
deployed on the MuJoCo env) and ``results/sac_preset/results.json`` (``bench/sac_preset.py``: SB3
SAC stepping the MuJoCo preset itself) and ``results/rl_equal_budget/`` (``studies/rl_equal_budget.py``:
SAC and PPO at the same env-step budgets, side by side on one machine), and writes their
BENCHMARKS.md section. SAC is not run at PPO's 6 M steps: at its measured rate they would take
most of a day here; the section projects that time from the rate instead.
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
EQUAL = ROOT / "results" / "rl_equal_budget"
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


def equal_budget_rows() -> tuple[list[str], str]:
    """The table of ``studies/rl_equal_budget.py`` (SAC and PPO at the same env steps) and what it says."""
    docs = {a: json.loads(p.read_text()) for a in ("sac", "ppo") if (p := EQUAL / f"{a}_seed0.json").is_file()}
    if len(docs) < 2:
        return [], ""
    budgets = sorted({int(b) for d in docs.values() for b in d["budgets"]})

    def cells(algo: str, budget: int) -> str:
        row = docs[algo]["budgets"].get(str(budget))
        if row is None:
            return "— | — | —" + (" | —" if algo == "ppo" else "")
        ev = row["mujoco"]["nominal"]
        taken = f"{row['env_steps']:,} | " if algo == "ppo" else ""
        return (
            f"{taken}{row['train_seconds']:.0f} | {ev['x0']['return']:.0f} | "
            f"{100 * ev['seeded_success']:.0f} % ({ev['seeded_mean_return']:.0f})"
        )

    rows = [
        "| env-step budget | SAC wall (s) | SAC x0 = 0 return | SAC 30 starts: success (mean return) | "
        "PPO steps taken | PPO wall (s) | PPO x0 = 0 return | PPO 30 starts: success (mean return) |",
        "|---|---|---|---|---|---|---|---|",
        *(f"| {b:,} | {cells('sac', b)} | {cells('ppo', b)} |" for b in budgets),
    ]
    sac_last = max(int(b) for b in docs["sac"]["budgets"])
    rate = sac_last / docs["sac"]["budgets"][str(sac_last)]["train_seconds"]
    ppo_max = max(int(b) for b in docs["ppo"]["budgets"])
    note = (
        f"{_first_success(docs)} {_variants(docs)} PPO takes whole updates of 256 copies × 128 steps (32,768 env steps; a budget "
        "below one update is not run); its settings are made for a batched env's throughput, not for few "
        f"samples. Same machine, same day, each pinned to one core ({docs['ppo']['machine']}; {docs['ppo']['date']}); "
        f"one seed (0) each. SAC ({docs['sac']['library']}) trains at {rate:.0f} env steps/s here, so PPO's "
        f"{ppo_max:,} steps would take it ~{ppo_max / rate / 3600:.0f} h (a projection from its measured rate, "
        "not a run). `studies/rl_equal_budget.py`, results/rl_equal_budget/."
    )
    return rows, note


def _variants(docs: dict) -> str:
    """What each algorithm's largest budget does on the plant variants, as one sentence."""
    parts = []
    for algo, name in (("sac", "SAC"), ("ppo", "PPO")):
        last = max(docs[algo]["budgets"], key=int)
        scores = docs[algo]["budgets"][last]["mujoco"]
        each = ", ".join(
            f"`{plant}` {100 * ev['seeded_success']:.0f} %" for plant, ev in scores.items() if plant != "nominal"
        )
        parts.append(f"{name} at {int(last):,} steps: {each}")
    return "Of the 30 starts on the plant variants, " + "; ".join(parts) + "."


def _first_success(docs: dict) -> str:
    """The smallest budget at which each algorithm succeeds from ≥ 90 % of the starts, and its wall."""
    parts = []
    for algo, name in (("sac", "SAC"), ("ppo", "PPO")):
        hits = [
            (int(b), row["train_seconds"])
            for b, row in docs[algo]["budgets"].items()
            if row["mujoco"]["nominal"]["seeded_success"] >= 0.9
        ]
        parts.append(
            f"{name} first at {min(hits)[0]:,} env steps, after {min(hits)[1]:.0f} s" if hits else f"{name} at none"
        )
    return "Smallest budget run that succeeds from ≥ 90 % of the 30 starts: " + "; ".join(parts) + "."


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
            "core (`taskset`) on the 2-core machine shared with other jobs, the learned-model rows in their "
            "checkpoints' regeneration and the analytic ones earlier (results/README.md) "
            "(`studies/rl_from_learned_models.py`, results/rl_learned/; docs/rl.md has every row). SAC is "
            "not run at PPO's 6 M steps (a projection from its rate is below); the two are run side by side "
            "at the budgets of the second table.",
            "",
            head,
            "|---|---|---|---|---|---|",
            *ppo_rows(),
            *sac_rows(),
            *_equal_budget_block(),
            END,
        ]
    )


def _equal_budget_block() -> list[str]:
    rows, note = equal_budget_rows()
    if not rows:
        return []
    return [
        "",
        "### At the same env-step budgets",
        "",
        "SB3 SAC (defaults, one gradient step per env step) learning on the MuJoCo preset itself, beside PPO "
        "in one `jit` on the analytic model's functional env, one PPO run per budget; both scored as above, "
        "training wall without the scoring.",
        "",
        *rows,
        "",
        note,
    ]


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
