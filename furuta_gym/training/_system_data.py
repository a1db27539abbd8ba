"""What the training layer knows about one system: :class:`SystemData`."""

from __future__ import annotations

import dataclasses
from typing import Callable, Mapping

__all__ = ["SystemData"]


@dataclasses.dataclass(frozen=True)
class SystemData:
    """One system's datasets and how the reproduction reports them; each system's module
    (``_furuta_data.py``, ``_nmsd_data.py``) makes one, :data:`~.datagen.SYSTEM_DATA` lists them.

    ``recipe``: its recipe dataclass (``recipe()`` the paper's datasets, ``recipe.small()`` a
    scaled-down one). ``make_test(recipe, ground_truth, seed, oversample)`` and
    ``make_validation``: ``{dataset: [clean trajectories on the sensor grid]}`` with the names of
    ``test_names`` / ``validation_names``, in that order. ``test_labels`` /
    ``validation_labels``: the reproduction table's label of each evaluated set.
    ``forced_set`` / ``energy_set``: the test sets of the reproduction's prediction and energy
    figures; ``state_labels``: their axis labels. ``main_claim``: the system's short name in the
    reproduction summary's check of the paper's main claim (L_prop's force decomposition against
    its baseline's); ``None``: the summary does not check it on this system.
    """

    system: str
    recipe: type
    test_names: tuple[str, ...]
    validation_names: tuple[str, ...]
    make_test: Callable
    make_validation: Callable
    test_labels: Mapping[str, str]
    validation_labels: Mapping[str, str]
    forced_set: str
    energy_set: str
    state_labels: tuple[str, ...]
    main_claim: str | None = None
