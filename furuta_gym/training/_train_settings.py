"""A training run's hyper-parameters (:class:`TrainSettings`) and the recipe's μ per model kind
(:data:`AUGMENTATION_WEIGHT`); part of :mod:`.train`."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ..lagrangian import QUADRATURE_RULES, QuadratureRule
from ..systems import get_spec
from .loss_kinds import loss_kind
from .losses import AUGMENTATION_PARTS, NORMALIZATIONS, Normalization
from .recipe import PAPER_SCHEDULE, RECIPE

#: μ of L_prop's minimum-norm term per (system, model kind) with F_a, when
#: TrainSettings.augmentation_weight is None: the recipe's (furuta_gym.training.recipe).
AUGMENTATION_WEIGHT = {
    (s, k): row.augmentation_weight
    for (s, k, loss), row in RECIPE.items()
    if loss_kind(loss).proposed and row.augmentation_weight is not None
}


@dataclasses.dataclass(frozen=True)
class TrainSettings:
    """Hyper-parameters of a training run.

    ``epochs[k]`` epochs are run with prediction horizon ``horizons[k]`` (an ``int`` is a number
    of samples, a ``float`` seconds; ``None``: a stage of L_Iτ alone, with the ``"prop"`` loss —
    no ODE solve, so thousands of epochs cost what tens of trajectory epochs do; the reproduction
    starts every L_prop run with one). The defaults are a short run a 2-core CPU finishes in
    minutes; :meth:`paper` gives the paper's recipe (50 k + 10 k epochs Furuta, 5 k + 1 k N-MSD,
    full batch), which costs hours on a CPU.

    ``learning_rate`` Adam's step, one value or one per stage (an L_Iτ-alone stage tolerates a
    larger step than the trajectory stages after it). ``cosine_decay_to`` within each stage the
    step follows a cosine from the stage's rate down to this fraction of it at the stage's last
    epoch (1, the default: constant; over a whole N-MSD L_Iτ stage the decay slowed the fit
    more than it steadied it, docs/reproduce.md). ``keep_best_itau`` a full-batch stage of L_Iτ alone
    hands the next stage the parameters of its lowest loss, not its last: its loss is exact (no
    minibatch noise) and at a large step it jumps by 10-100x from epoch to epoch, so the last
    epoch is a draw (N-MSD DeLaN at 1e-2: 1.4e-4 at its last epoch, 2.1e-6 twenty epochs
    before). ``batch_size`` trajectory windows per step
    (``None``: all windows, one step per epoch);
    ``lambda_traj`` λ in L_aph / L_prop; ``lambda_step`` APHYNITY's dual-ascent step τ₂ (λ ← λ +
    τ₂·L_traj after every epoch; ``None``: 1000 for ``"aph"``, 0 — a fixed λ — otherwise);
    ``quadrature`` "trapezoid" (paper) | "simpson" | "hermite" (the paper's intervals, the motion
    between samples resolved from the measured q and q̇:
    :func:`~furuta_gym.lagrangian.interval_quadrature`); ``normalize`` see
    :mod:`furuta_gym.training.losses`; ``integral_window`` samples per L_Iτ window
    (trajectories are tiled into windows overlapping by one sample); ``integral_batch_size``
    L_Iτ windows per step (``None``: all). ``augmentation_weight`` μ of the minimum-norm term
    μ·P_a that L_prop / L_Iτ add for models with a data-driven force F_a (APHYNITY, augmented
    DeLaN; :func:`~furuta_gym.training.losses.integral_loss_terms`): ``None`` means
    :data:`AUGMENTATION_WEIGHT` of the system and model kind (0 for models without F_a); 0 turns it off.
    ``augmentation_part`` what P_a measures: ``"beyond_linear"`` F_a without its linear viscous
    term W·q̇ (the same as all of F_a for a model without W), ``"full"`` all of F_a.
    ``resolution_tolerance`` (rad or m; ``None``: off, the paper's unweighted sum) weights each
    L_Iτ interval by 1 / (1 + (e / tolerance)²), e = |∫q̇ dt − Δq| over the interval, which the
    data give without any model (:func:`~furuta_gym.training.losses.resolution_weights`). Where
    the sampling under-resolves the motion the true model's residual is quadrature error of the
    size of e; unweighted, the few such intervals (a pendulum whirling at 30 rad/s at 100 Hz)
    make most of L_Iτ's floor, and a flexible model bends its physics to fit that error.
    ``integral_span`` (1: the paper) quadrature intervals summed into one L_Iτ residual
    (:func:`~furuta_gym.training.losses.span_sum`): the same equation over a longer interval, so
    an error in the estimated velocities, which enters at the interval's ends, weighs less
    against the physics' impulse.
    ``fast_compile`` compiles the steps with a trajectory loss (an ODE solve: L_traj, L_aph and
    L_prop's stages after the L_Iτ-alone one) with XLA's backend optimisation level 0: such a
    step compiles faster and runs slower, and results agree to rounding, not bit for bit. Worth it only for a few hundred trajectory steps, whose time is mostly
    compiling (``furuta-gym reproduce --quick``); an L_Iτ-alone step compiles in seconds and runs
    thousands of epochs, so it keeps the optimised code.
    """

    epochs: tuple[int, ...] = (100, 20)
    horizons: tuple[int | float | None, ...] = (2, 1.0)
    learning_rate: float | tuple[float, ...] = 1e-3
    cosine_decay_to: float = 1.0
    keep_best_itau: bool = True
    weight_decay: float = 1e-5
    batch_size: int | None = 256
    lambda_traj: float = 1.0
    lambda_step: float | None = None
    quadrature: QuadratureRule = "trapezoid"
    normalize: Normalization = "auto"
    integral_window: int = 101
    integral_batch_size: int | None = None
    augmentation_weight: float | None = None
    augmentation_part: str = "beyond_linear"
    resolution_tolerance: float | None = None
    integral_span: int = 1
    rtol: float = 1e-3
    atol: float = 1e-6
    max_steps: int = 4096
    grad_clip: float | None = 10.0
    fast_compile: bool = False
    seed: int = 0
    checkpoint_every: int = 50
    progress: bool = True

    def __post_init__(self):
        self._check_schedule()
        self._check_loss()
        self._check_batches()

    def _check_schedule(self) -> None:
        """Stages, learning rates and their decay (epochs and rates stored as tuples)."""
        object.__setattr__(self, "epochs", tuple(int(e) for e in self.epochs))
        object.__setattr__(self, "horizons", tuple(self.horizons))
        if len(self.epochs) != len(self.horizons):
            raise ValueError(f"epochs {self.epochs} and horizons {self.horizons} must have one entry per stage")
        if isinstance(self.learning_rate, (tuple, list)):
            object.__setattr__(self, "learning_rate", tuple(float(r) for r in self.learning_rate))
            if len(self.learning_rate) != len(self.epochs):
                raise ValueError(
                    f"learning_rate {self.learning_rate} must be one value or one per stage ({len(self.epochs)} stages)"
                )
        rates = self.learning_rate if isinstance(self.learning_rate, tuple) else (self.learning_rate,)
        if not all(float(r) > 0 for r in rates):
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate!r}")
        if not 0 < self.cosine_decay_to <= 1:
            raise ValueError(f"cosine_decay_to must be in (0, 1], got {self.cosine_decay_to!r}")
        if any(e < 0 for e in self.epochs):
            raise ValueError(f"epochs must be non-negative, got {self.epochs}")

    def _check_loss(self) -> None:
        """The loss's quadrature, normalisation and augmentation penalty."""
        if self.quadrature not in QUADRATURE_RULES:
            raise ValueError(f"quadrature must be one of {QUADRATURE_RULES}, got {self.quadrature!r}")
        if self.normalize not in NORMALIZATIONS:
            raise ValueError(f"normalize must be one of {NORMALIZATIONS}, got {self.normalize!r}")
        if self.augmentation_part not in AUGMENTATION_PARTS:
            raise ValueError(f"augmentation_part must be one of {AUGMENTATION_PARTS}, got {self.augmentation_part!r}")
        if self.augmentation_weight is not None and not self.augmentation_weight >= 0:
            raise ValueError(f"augmentation_weight must be non-negative or None, got {self.augmentation_weight!r}")

    def _check_batches(self) -> None:
        """How the windows are cut and batched."""
        if self.resolution_tolerance is not None and not float(self.resolution_tolerance) > 0:
            raise ValueError(f"resolution_tolerance must be positive or None, got {self.resolution_tolerance!r}")
        if not (isinstance(self.integral_span, (int, np.integer)) and self.integral_span >= 1):
            raise ValueError(f"integral_span must be a positive integer, got {self.integral_span!r}")
        if self.integral_span > 1 and self.resolution_tolerance is not None:
            raise ValueError("integral_span > 1 and resolution_tolerance cannot be combined")
        if self.batch_size is not None and self.batch_size < 1:
            raise ValueError(f"batch_size must be positive or None, got {self.batch_size}")

    def stage_learning_rate(self, stage: int) -> float:
        """Adam's step at the start of ``stage`` (0-based)."""
        if isinstance(self.learning_rate, tuple):
            return self.learning_rate[stage]
        return float(self.learning_rate)

    def epoch_learning_rate(self, epoch: int) -> float:
        """Adam's step in ``epoch`` (0-based, counted over all stages): the stage's rate, cosine
        decayed to ``cosine_decay_to`` times it at the stage's last epoch."""
        if not 0 <= epoch < self.total_epochs:
            raise ValueError(f"epoch {epoch} is outside the {self.total_epochs} epochs of this config")
        bounds = np.cumsum(self.epochs)
        stage = int(np.searchsorted(bounds, epoch, side="right"))
        rate = self.stage_learning_rate(stage)
        if self.cosine_decay_to == 1.0 or self.epochs[stage] < 2:
            return rate
        progress = (epoch - (bounds[stage] - self.epochs[stage])) / (self.epochs[stage] - 1)
        end = self.cosine_decay_to
        return rate * (end + (1.0 - end) * 0.5 * (1.0 + math.cos(math.pi * progress)))

    @property
    def total_epochs(self) -> int:
        return sum(self.epochs)

    @classmethod
    def for_system(cls, system: str, **overrides) -> "TrainSettings":
        """CPU-friendly defaults with the paper's horizons (1 s Furuta, 2 s N-MSD)."""
        base: dict[str, Any] = dict(horizons=PAPER_SCHEDULE[get_spec(system).name]["horizons"])
        base.update(overrides)
        return cls(**base)

    @classmethod
    def paper(cls, system: str, **overrides) -> "TrainSettings":
        """The paper's recipe: 2-step stage then the long horizon, full batch (appendix A.2)."""
        base: dict[str, Any] = dict(**PAPER_SCHEDULE[get_spec(system).name], batch_size=None, checkpoint_every=500)
        base.update(overrides)
        return cls(**base)

    def to_json(self) -> dict:
        return dataclasses.asdict(self)
