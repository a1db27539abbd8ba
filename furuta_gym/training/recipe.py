"""The reproduction's training recipe as data: one row per (system, model kind, loss).

:data:`RECIPE` is what ``furuta-gym reproduce`` trains in a full run;
:func:`~furuta_gym.training.reproduce.training_settings` turns a row into a
:class:`~furuta_gym.training.TrainSettings`. Each row names the rows of the decision log
(docs/reproduce.md, "Decision log") behind its values; the measurements live there and in
results/, not here. ``--quick`` and a schedule of the caller's keep a row's λ, μ and L_Iτ step
but take their own epochs and the defaults for the per-model choices (quadrature, fine-tuning
step), which were made for the full run's schedule.
"""

from __future__ import annotations

import dataclasses

from .loss_kinds import loss_kind

__all__ = [
    "RunRecipe",
    "RECIPE",
    "SYSTEM_ROWS",
    "PAPER_SCHEDULE",
    "QUICK_EPOCHS",
    "QUICK_PROP_EPOCHS",
    "DEFAULT_QUADRATURE",
    "DEFAULT_LEARNING_RATE",
    "recipe_row",
    "FREE_RELEASE_LAMBDA",
]

DEFAULT_QUADRATURE = "simpson"
DEFAULT_LEARNING_RATE = 1e-3


@dataclasses.dataclass(frozen=True)
class RunRecipe:
    """The full run's training of one (system, model kind, loss).

    ``epochs``: L_traj / L_aph ``(2-step, long horizon)``; L_prop ``(L_Iτ alone, 2-step, long
    horizon)``, the last two with L_Iτ + λ·L_traj. ``quadrature``: L_Iτ's rule (and the Furuta
    scale fit's). ``itau_learning_rate`` / ``finetune_learning_rate``: Adam's step in the L_Iτ
    stage and in the two stages after it. ``lambda_traj``: λ of L_prop; ``augmentation_weight``:
    μ of its minimum-norm term (models with F_a). ``decisions``: decision-log rows.
    """

    epochs: tuple[int, ...]
    quadrature: str = DEFAULT_QUADRATURE
    itau_learning_rate: float = DEFAULT_LEARNING_RATE
    finetune_learning_rate: float = DEFAULT_LEARNING_RATE
    lambda_traj: float | None = None
    augmentation_weight: float | None = None
    decisions: tuple[str, ...] = ()


_BASELINE = ("baseline epochs",)
_PROP = ("λ of L_prop",)


def _prop(epochs, *, decisions=(), **settings) -> RunRecipe:
    return RunRecipe(epochs=epochs, lambda_traj=1e-3, decisions=_PROP + decisions, **settings)


#: Each system's rows before per-model choices: the baselines' schedule (also for pairs the paper
#: does not report) and L_prop's (a model kind without a row of its own takes it).
SYSTEM_ROWS = {
    "furuta": {"baseline": RunRecipe(epochs=(60, 200), decisions=_BASELINE), "prop": _prop((6000, 20, 60))},
    "nmsd": {
        "baseline": RunRecipe(epochs=(100, 100), decisions=_BASELINE),
        "prop": _prop(
            (4000, 30, 30),
            itau_learning_rate=1e-2,
            decisions=(
                "L_Iτ quadrature, N-MSD",
                "L_Iτ step, N-MSD",
                "fine-tuning step, N-MSD DeLaN and augmented DeLaN",
            ),
        ),
    },
}


def _row(system, *, replaces=(), **changes) -> RunRecipe:
    """The system's L_prop row with ``changes``; ``decisions`` are added to the base row's, less
    the base decisions this row's own ``replaces``."""
    base = SYSTEM_ROWS[system]["prop"]
    kept = tuple(d for d in base.decisions if d not in replaces)
    return dataclasses.replace(base, decisions=kept + changes.pop("decisions", ()), **changes)


RECIPE: dict[tuple[str, str | None, str], RunRecipe] = {
    **{
        (s, k, loss): SYSTEM_ROWS[s]["baseline"]
        for s in SYSTEM_ROWS
        for k, loss in (("dln", "traj"), ("aph", "aph"), ("adln", "aph"))
    },
    ("furuta", "dln", "prop"): _row(
        "furuta",
        epochs=(12000, 20, 60),
        finetune_learning_rate=1e-6,
        decisions=("L_Iτ quadrature, Furuta DeLaN", "L_Iτ epochs, Furuta DeLaN", "fine-tuning step, Furuta DeLaN"),
    ),
    ("furuta", "aph", "prop"): _row(
        "furuta",
        quadrature="hermite",
        finetune_learning_rate=1e-4,
        augmentation_weight=0.1,
        decisions=(
            "L_Iτ quadrature, Furuta APHYNITY",
            "fine-tuning step, APHYNITY",
            "μ per system and kind",
            "F_a design",
        ),
    ),
    ("furuta", "adln", "prop"): _row(
        "furuta",
        epochs=(24000, 20, 60),
        quadrature="hermite",
        finetune_learning_rate=3e-4,
        augmentation_weight=10.0,
        decisions=(
            "L_Iτ epochs, Furuta augmented DeLaN",
            "fine-tuning step, Furuta augmented DeLaN",
            "L_Iτ quadrature, Furuta augmented DeLaN",
            "μ per system and kind",
            "F_a design",
        ),
    ),
    ("nmsd", "dln", "prop"): _row("nmsd", epochs=(8000, 30, 30), decisions=("L_Iτ epochs, N-MSD DeLaN",)),
    ("nmsd", "aph", "prop"): _row(
        "nmsd",
        quadrature="trapezoid",
        finetune_learning_rate=1e-4,
        augmentation_weight=1e-4,
        replaces=("L_Iτ quadrature, N-MSD", "fine-tuning step, N-MSD DeLaN and augmented DeLaN"),
        decisions=(
            "L_Iτ quadrature, N-MSD APHYNITY",
            "fine-tuning step, APHYNITY",
            "μ per system and kind",
            "F_a design",
        ),
    ),
    ("nmsd", "adln", "prop"): _row(
        "nmsd",
        quadrature="trapezoid",
        augmentation_weight=1e-2,
        replaces=("L_Iτ quadrature, N-MSD",),
        decisions=(
            "L_Iτ quadrature, N-MSD augmented DeLaN",
            "μ per system and kind",
            "F_a design",
            "N-MSD augmented DeLaN F_a odd in q̇",
        ),
    ),
}

#: the paper's training schedule per system (appendix A.2): epochs of the 2-step and the
#: long-horizon stage, and the horizons (2 samples, then 1 s Furuta / 2 s N-MSD)
PAPER_SCHEDULE = {
    "furuta": {"epochs": (50_000, 10_000), "horizons": (2, 1.0)},
    "nmsd": {"epochs": (5_000, 1_000), "horizons": (2, 2.0)},
}

#: ``--quick``: a few epochs per stage, for a pipeline check (minutes, not the paper's numbers)
QUICK_EPOCHS = {"nmsd": (8, 2), "furuta": (4, 1)}
QUICK_PROP_EPOCHS = {"nmsd": (300, 8, 2), "furuta": (300, 4, 1)}

#: λ of L_prop that ``furuta-gym train`` takes on measured free releases (u = 0, velocities
#: estimated) when none is given: with λ = 1
#: L_Iτ's pull left a lightly damped rig's free dynamics wrong on some seeds where L_traj's
#: trajectories are right (docs/learning.md, "Free releases")
FREE_RELEASE_LAMBDA = 10.0


def recipe_row(system: str, kind: str | None, loss: str, epochs: tuple[int, ...] | None = None) -> RunRecipe:
    """The row of ``(system, kind, loss)`` (a pair without one: its system's baseline or L_prop
    row); with ``epochs`` (``--quick`` or the caller's own schedule) those epochs and the default
    quadrature and fine-tuning step."""
    row = RECIPE.get((system, kind, loss)) or SYSTEM_ROWS[system]["prop" if loss_kind(loss).proposed else "baseline"]
    if epochs is None:
        return row
    return dataclasses.replace(
        row, epochs=tuple(epochs), quadrature=DEFAULT_QUADRATURE, finetune_learning_rate=DEFAULT_LEARNING_RATE
    )
