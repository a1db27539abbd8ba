"""How a reproduction run names what it reports: the models, the losses and each system's test
sets (shared by :mod:`.reproduce` and its figures)."""

from __future__ import annotations

from .datagen import SYSTEM_DATA

__all__ = ["MODEL_LABELS", "LOSS_LABELS", "TEST_SETS"]

MODEL_LABELS = {"dln": "DLN", "aph": "APH", "adln": "ADLN"}
LOSS_LABELS = {"traj": "L_traj", "aph": "L_aph", "prop": "L_prop"}
#: The paper's test-set labels and our dataset names.
TEST_SETS = {name: dict(d.test_labels) for name, d in SYSTEM_DATA.items()}
