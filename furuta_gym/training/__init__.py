"""Training learned Lagrangian models: data generation, losses, the training loop, checkpoints, metrics."""

from .._deprecated import deprecated_names
from .checkpoint import CheckpointError, load_model, read_header, save_model
from .consistency import (
    DataCoverageWarning,
    PotentialShapeWarning,
    check_data_coverage,
    check_potential_shape,
    warn_data_coverage,
    warn_potential_shape,
)
from .free_dynamics import FreeDynamicsWarning, check_free_dynamics, warn_free_dynamics
from .loss_kinds import LOSS_KINDS, LossKind, loss_kind
from .losses import (
    Windows,
    aphynity_loss,
    augmentation_penalty,
    integral_loss,
    make_windows,
    proposed_loss,
    trajectory_loss,
)
from .train import ScaleFit, ScaleFitWarning, TrainSettings, data_hash, fit_scale, train, training_step

__all__ = [
    "CheckpointError",
    "DataCoverageWarning",
    "PotentialShapeWarning",
    "check_data_coverage",
    "warn_data_coverage",
    "check_potential_shape",
    "FreeDynamicsWarning",
    "check_free_dynamics",
    "warn_free_dynamics",
    "warn_potential_shape",
    "load_model",
    "read_header",
    "save_model",
    "LOSS_KINDS",
    "LossKind",
    "loss_kind",
    "Windows",
    "aphynity_loss",
    "augmentation_penalty",
    "integral_loss",
    "make_windows",
    "proposed_loss",
    "trajectory_loss",
    "training_step",
    "ScaleFit",
    "ScaleFitWarning",
    "TrainSettings",
    "data_hash",
    "fit_scale",
    "train",
]


__getattr__ = deprecated_names(__name__)
