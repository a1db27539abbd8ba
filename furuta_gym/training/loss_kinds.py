"""Training losses are types, registered once: each kind carries what it is made of (L_traj,
L_Iτ, APHYNITY's ‖F_a‖²), how L_traj is weighted (1 or λ), its dual-ascent step on λ, which
recipe rows it follows and its objective, so code elsewhere asks ``loss_kind(name)`` and never
compares loss names; adding a loss is one subclass of :class:`LossKind` plus tests
(tests/test_kind_registry.py fails on a loss or model name compared outside this module and the
model registry, :data:`furuta_gym.models.MODEL_KINDS`).

The names are the public spellings (``train(..., loss="prop")``, ``--loss prop``, checkpoints'
and run records' ``"loss"``):

========  ======================================================  =====================
name      objective                                               label in the tables
========  ======================================================  =====================
``traj``  L_traj                                                  L_traj
``aph``   ‖F_a‖² + λ·L_traj, λ by dual ascent (APHYNITY)          L_aph
``prop``  L_Iτ (+ μ·P_a with F_a) + λ·L_traj (the paper's)        L_prop
``itau``  L_Iτ (+ μ·P_a with F_a) alone: no ODE solve             L_Iτ
========  ======================================================  =====================

A training stage without a horizon trains on :data:`INTEGRAL_ONLY` whatever the run's loss.
The loss terms a step reports (and a run's history records) are named by the ``*_TERM``
constants below.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

from .losses import Normalization, Windows, augmentation_penalty, integral_loss_terms, trajectory_loss

__all__ = [
    "LossKind",
    "LOSS_KINDS",
    "loss_kind",
    "StepSettings",
    "INTEGRAL_ONLY",
    "PROPOSED_LOSS",
    "TRAJECTORY_TERM",
    "INTEGRAL_TERM",
    "SHARE_TERM",
    "PENALTY_TERM",
    "TOTAL_TERM",
]

#: every loss kind by name, in registration order (the order of ``train``'s LOSSES and the CLI)
LOSS_KINDS: dict[str, "LossKind"] = {}

#: the keys of a step's loss terms (and of a run's history records)
TRAJECTORY_TERM, INTEGRAL_TERM, SHARE_TERM, PENALTY_TERM, TOTAL_TERM = "traj", "itau", "fa_share", "penalty", "total"


@dataclasses.dataclass(frozen=True)
class StepSettings:
    """What a run fixes for every step's terms: L_traj's solver keywords, L_Iτ's keywords
    (quadrature, normalisation, P_a's part, resolution tolerance, span) and μ of P_a."""

    trajectory: dict[str, Any]
    integral: dict[str, Any]
    normalization: Normalization
    augmentation_weight: float = 0.0


class LossKind:
    """One training loss, registered once by subclassing: the class attributes are its data,
    :meth:`objective` its value. Everything that differs between losses lives here, so code
    elsewhere asks a kind, never compares names."""

    name: ClassVar[str]
    #: its label in the reproduction's tables and figures
    label: ClassVar[str]
    #: holds L_traj: predictions over the stage's horizon (an ODE solve per window)
    uses_trajectory: ClassVar[bool] = False
    #: holds L_Iτ (and, for a model with F_a and μ ≠ 0, the minimum-norm term μ·P_a)
    uses_integral: ClassVar[bool] = False
    #: holds APHYNITY's ‖F_a‖² (so needs a model with a data-driven force F_a)
    penalises_augmentation: ClassVar[bool] = False
    #: L_traj enters as λ·L_traj (else 1·L_traj); λ is then shown and may be stepped
    weighs_trajectory_by_lambda: ClassVar[bool] = False
    #: APHYNITY's dual-ascent step τ₂ on λ (λ ← λ + τ₂·L_traj after every epoch) by default
    dual_ascent_step: ClassVar[float] = 0.0
    #: the paper's proposed loss: its runs follow the recipe's L_prop rows (a leading stage of
    #: L_Iτ alone, λ, μ, the stages' steps), the others the baseline rows
    proposed: ClassVar[bool] = False

    def __init_subclass__(cls, **kw):
        super().__init_subclass__(**kw)
        if "name" in cls.__dict__:
            if cls.name in LOSS_KINDS:
                raise ValueError(f"loss kind {cls.name!r} is registered twice")
            LOSS_KINDS[cls.name] = cls()

    def __repr__(self) -> str:
        return f"<loss kind {self.name}>"

    def objective(self, model, traj_b: Windows | None, int_b: Windows | None, lam, settings: StepSettings):
        """``(total, terms)``: the loss of ``model`` on one step's trajectory and integral
        windows (``None`` where the kind has no such term), with its terms by ``*_TERM`` key.
        The terms are added in one fixed order (L_Iτ, μ·P_a, ‖F_a‖², L_traj): a run's numbers
        depend on it to the last bit."""
        terms: dict[str, Any] = {}
        total: Any = 0.0
        use_share = self.uses_integral and settings.augmentation_weight != 0.0
        if self.uses_trajectory:
            assert traj_b is not None
            terms[TRAJECTORY_TERM] = trajectory_loss(model, traj_b, **settings.trajectory)
        if self.uses_integral:
            assert int_b is not None
            terms[INTEGRAL_TERM], share = integral_loss_terms(
                model, int_b, normalize=settings.normalization, with_augmentation=use_share, **settings.integral
            )
            total = total + terms[INTEGRAL_TERM]
            if use_share:
                assert share is not None  # integral_loss_terms returns it with_augmentation
                terms[SHARE_TERM] = share
                total = total + settings.augmentation_weight * share
        if self.penalises_augmentation:
            assert traj_b is not None
            terms[PENALTY_TERM] = augmentation_penalty(model, traj_b)
            total = total + terms[PENALTY_TERM]
        if self.uses_trajectory:
            total = total + (lam if self.weighs_trajectory_by_lambda else 1.0) * terms[TRAJECTORY_TERM]
        terms[TOTAL_TERM] = total
        return total, terms


def loss_kind(name: str) -> LossKind:
    """The registered loss kind of ``name`` (the public spelling: "traj", "aph", "prop", "itau")."""
    try:
        return LOSS_KINDS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown loss {name!r}; expected one of {tuple(LOSS_KINDS)}") from None


class _Trajectory(LossKind):
    name, label, uses_trajectory = "traj", "L_traj", True


class _Aphynity(LossKind):
    name, label, uses_trajectory, penalises_augmentation = "aph", "L_aph", True, True
    weighs_trajectory_by_lambda, dual_ascent_step = True, 1000.0


class _Proposed(LossKind):
    name, label, uses_trajectory, uses_integral = "prop", "L_prop", True, True
    weighs_trajectory_by_lambda, proposed = True, True


class _IntegralOnly(LossKind):
    name, label, uses_integral = "itau", "L_Iτ", True


#: the loss of a training stage without a horizon (and of the ``--horizons itau`` spelling)
INTEGRAL_ONLY: LossKind = LOSS_KINDS[_IntegralOnly.name]
#: the name of the paper's proposed loss (the reproduction compares the others against it)
PROPOSED_LOSS: str = _Proposed.name
