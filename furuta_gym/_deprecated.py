"""Old public names kept importable after a rename: a module's ``__getattr__`` serves each one as
the object it was renamed to, with one :class:`DeprecationWarning` per use naming the new name.

Settings objects are ``*Settings`` (CONTRIBUTING.md, "Conventions"); the names they had before
are listed in :data:`RENAMED`, one dict per module that exported them; names that left a module
for another are in :data:`MOVED`.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from typing import Any, Callable

__all__ = ["MOVED", "RENAMED", "deprecated_names"]

#: module -> {old name: (the name in that module that serves it, what to use instead)}
RENAMED: dict[str, dict[str, tuple[str, str]]] = {
    "furuta_gym.training": {"TrainConfig": ("TrainSettings", "TrainSettings")},
    "furuta_gym.training.train": {"TrainConfig": ("TrainSettings", "TrainSettings")},
    "furuta_gym.training.reproduce": {
        "ReproduceConfig": ("ReproduceSettings", "ReproduceSettings"),
        "training_config": ("training_settings", "training_settings"),
    },
    "furuta_gym.training.datagen": {
        "SensorOptions": (
            "_SensorOptions",
            "furuta_gym.sensors.Sensors (the sensor model) and the generators' sensor_rate_hz",
        ),
    },
    "furuta_gym.demo": {"DemoConfig": ("DemoSettings", "DemoSettings")},
    "furuta_gym.rl": {"PPOConfig": ("PPOSettings", "PPOSettings")},
}

#: module -> {name: the module it moved to, under the same name}
MOVED: dict[str, dict[str, str]] = {
    # the simulated rigs are test data, not the diagnosis: they left its public names
    "furuta_gym.diagnose": {
        name: "furuta_gym.rigs"
        for name in ("measured_like", "sticky_rig", "moving_rest_rig", "breakaway_rig", "ClosedLoopBalancing")
    },
}


def deprecated_names(module: str) -> Callable[[str], Any]:
    """The ``__getattr__`` of ``module``, serving its old names of :data:`RENAMED` and the names
    :data:`MOVED` out of it."""
    renamed, moved = RENAMED.get(module, {}), MOVED.get(module, {})

    def __getattr__(name: str) -> Any:
        if name in moved:
            where = moved[name]
            warnings.warn(f"{module}.{name} moved; use {where}.{name}", DeprecationWarning, stacklevel=2)
            return getattr(importlib.import_module(where), name)
        if name not in renamed:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        target, instead = renamed[name]
        warnings.warn(f"{module}.{name} is deprecated; use {instead}", DeprecationWarning, stacklevel=2)
        return getattr(sys.modules[module], target)

    return __getattr__
