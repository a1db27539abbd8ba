"""How a reproduction run names what it reports: the models, the losses and each system's test
sets (shared by :mod:`.reproduce` and its figures)."""

from __future__ import annotations

from ..models import MODEL_KINDS
from .datagen import SYSTEM_DATA
from .loss_kinds import LOSS_KINDS

__all__ = ["MODEL_LABELS", "LOSS_LABELS", "TEST_SETS"]

#: each kind's label, which its type carries (models' MODEL_KINDS, training's LOSS_KINDS)
MODEL_LABELS = {name: cls.label for name, cls in MODEL_KINDS.items()}
LOSS_LABELS = {name: kind.label for name, kind in LOSS_KINDS.items()}
#: The paper's test-set labels and our dataset names.
TEST_SETS = {name: dict(d.test_labels) for name, d in SYSTEM_DATA.items()}
