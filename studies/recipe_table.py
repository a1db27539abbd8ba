"""docs/reproduce.md's table of the training recipe, written from the recipe itself.

    python studies/recipe_table.py           # rewrite the docs block
    python studies/recipe_table.py --check   # exit 1 if the docs block is stale

One row per (system, model kind, loss) of :data:`furuta_gym.training.recipe.RECIPE`: the stages'
epochs, L_Iτ's quadrature, Adam's step in the L_Iτ stage and in the stages after it, λ, μ, the
F_a design the model kind has by default on that system (its network's activation, W's unit,
odd in q̇ or general) and the decision-log rows behind them.
"""

from __future__ import annotations

import sys
from pathlib import Path

from furuta_gym.training.recipe import RECIPE

sys.path.append(str(Path(__file__).resolve().parents[1] / "bench"))  # bench/_generated.py writes the blocks
from _generated import block_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "reproduce.md"
NAME = "recipe-table"  # the docs/reproduce.md block this writes
LOSS = {"traj": "L_traj", "aph": "L_aph", "prop": "L_prop"}
SYSTEM = {"furuta": "Furuta", "nmsd": "N-MSD"}


def _value(x) -> str:
    return "—" if x is None else f"{x:g}"


def _force_design(system: str, kind: str) -> str:
    """The model's default F_a as the recipe trains it (read from a fresh model's hyper-parameters)."""
    import furuta_gym
    from furuta_gym.models import make_model

    furuta_gym.enable_x64()
    if kind == "dln":
        return "—"
    hp = dict(make_model(system, kind, 0).hparams)
    linear = {"diagonal": "W per joint", True: "W full", False: "no W"}[hp["linear_velocity"]]
    unit = f" (unit {_value(hp['damping_scale'])})" if hp["linear_velocity"] is not False else ""
    return f"{hp['force_activation']}, {linear}{unit}" + (", odd in q̇" if hp["odd_in_velocity"] else "")


def table() -> str:
    lines = [
        "| system | model | loss | epochs per stage | L_Iτ quadrature | step: L_Iτ / after | λ | μ | F_a | "
        "decision-log rows |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (system, kind, loss), row in sorted(
        RECIPE.items(), key=lambda kv: (kv[0][0] != "furuta", kv[0][1], kv[0][2] == "prop")
    ):
        prop = loss == "prop"
        epochs = " + ".join(f"{e:,}".replace(",", " ") for e in row.epochs)
        lines.append(
            f"| {SYSTEM[system]} | {kind.upper()} | {LOSS[loss]} | {epochs} | "
            f"{row.quadrature if prop else '—'} | "
            f"{_value(row.itau_learning_rate) + ' / ' + _value(row.finetune_learning_rate) if prop else _value(row.finetune_learning_rate)} | "
            f"{_value(row.lambda_traj)} | {_value(row.augmentation_weight)} | {_force_design(system, kind)} | "
            f"{'; '.join(row.decisions)} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    return block_main(__file__, DOCS, NAME, table, argv)


if __name__ == "__main__":
    raise SystemExit(main())
