"""Checkpoints live with the models (:mod:`furuta_gym.models.checkpoint`), so that envs load a
learned model without depending on training; this module keeps the old import path."""

from ..models.checkpoint import (  # noqa: F401
    HEADER_FORMAT,
    MAGIC,
    CheckpointError,
    __all__,
    load_model,
    load_training_state,
    package_versions,
    read_header,
    save_model,
    save_training_state,
)
