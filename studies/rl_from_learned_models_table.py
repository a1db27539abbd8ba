"""The docs/rl.md table of ``studies/rl_from_learned_models.py``, generated from its results.

Reads ``results/rl_learned/*.json`` and rewrites the block between ``<!-- generated:rl-learned -->``
and ``<!-- /generated:rl-learned -->`` in docs/rl.md: per model PPO trained on (with and without
domain randomisation), its MuJoCo success from x0 = 0 and over the 30 seeded starts near rest, on
the nominal plant and the ``cable_spring`` and ``coulomb`` variants. A row without a result says
so. ``--check`` only compares (exit 1 when the docs disagree with the results).

    python studies/rl_from_learned_models_table.py [--check]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl_learned"
DOC = ROOT / "docs" / "rl.md"
NAME = "rl-learned"
#: the rows' order and labels (those of rl_from_learned_models.py, not imported: that needs jax)
MODELS = {
    "analytic": "analytic (reference)",
    "dln_prop": "DeLaN L_prop",
    "adln_prop": "augmented DeLaN L_prop",
    "dln_traj": "DeLaN L_traj (baseline)",
    "adln_aph": "augmented DeLaN L_aph (baseline)",
}
PLANTS = ("nominal", "cable_spring", "coulomb")
COMMAND = (
    "python studies/rl_from_learned_models.py --model MODEL [--randomize] && "
    "python studies/rl_from_learned_models_table.py"
)


def load(folder: Path = RESULTS) -> dict[tuple[str, bool], dict]:
    """Seed-0 results by (model, randomised)."""
    docs = {}
    for path in sorted(folder.glob("*_seed0.json")):
        doc = json.loads(path.read_text())
        docs[(doc["model"], doc["randomize"] is not None)] = doc
    return docs


def _randomization(doc: dict) -> str:
    r = doc["randomize"]
    return "—" if r is None else f"±{100 * r['spread']:.0f} % {r['over']}"


def _plant_cells(ev: dict) -> list[str]:
    x0 = ev["x0"]
    mark = "✓" if x0["success"] else "✗"
    return [f"{mark} {x0['return']:.0f}", f"**{100 * ev['seeded_success']:.0f} %** ({ev['seeded_mean_return']:.0f})"]


def table(docs: dict[tuple[str, bool], dict]) -> str:
    head = ["trained on", "randomisation", "train s", "own-model return"]
    for plant in PLANTS:
        head += [f"{plant}: x0 = 0", f"{plant}: 30 starts"]
    rows = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for model, label in MODELS.items():
        for randomized in (False, True):
            doc = docs.get((model, randomized))
            if doc is None:
                rows.append(f"| {label} | {'yes' if randomized else '—'} | not run |" + " |" * (len(head) - 3))
                continue
            cells = [label, _randomization(doc), f"{doc['train_seconds']:.0f}", f"{doc['model_return']:.0f}"]
            for plant in PLANTS:
                cells += _plant_cells(doc["mujoco"][plant])
            rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def body() -> str:
    docs = load()
    steps = sorted({d["steps"] for d in docs.values()})
    return "\n".join(
        [
            f"PPO ({', '.join(f'{s:,}' for s in steps) or '—'} env steps, `examples/ppo_swingup.py`'s settings), "
            "**one training seed (0) per row**, trained only on the model in the first column, then run on "
            "the MuJoCo `FurutaSwingUp-v0`. x0 = 0: ✓ when it succeeds, and its return (of 500); 30 starts: "
            "share of `near_rest_starts(30, seed=0)` that succeed (mean return). Success: within 0.1 rad of "
            "upright for 2 s without interruption, as the control benchmarks score it. Own-model return: the "
            "deterministic policy on its (nominal) training model, 32 episodes. Train s: wall time of the "
            "training, compilation included, on one core of a 2-core machine shared with other jobs.",
            "",
            table(docs),
            "",
            f"Generated from `results/rl_learned/*.json` by `{COMMAND}`.",
        ]
    )


if __name__ == "__main__":
    sys.exit(block_main(__file__, DOC, NAME, body))
