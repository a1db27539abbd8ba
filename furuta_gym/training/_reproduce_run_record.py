"""A reproduction run's record (``run.json``): command, date, configuration, each run's schedule
and quadrature, the machine and the package versions; part of :mod:`.reproduce`."""

from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
import os
import platform
from pathlib import Path
from typing import Any

from .. import __version__, numerics
from ._reproduce_settings import REPRODUCE_QUADRATURE, ReproduceSettings, epoch_schedule, training_settings
from .checkpoint import package_versions
from .datagen import data_package_versions
from .loss_kinds import loss_kind


def machine_info() -> dict[str, Any]:
    """The platform, Python, core count and CPU, as a run record notes them. Beside the CPU's model
    name, its family / model / stepping and a digest of its feature flags: XLA:CPU compiles for the
    host's features, and two hosts of one model name can round differently, which training
    amplifies into other models (docs/reproduce.md, "Same code, another host"). And the CPU
    numerics the process ran with (:func:`furuta_gym.numerics`): pinned, two machines give the
    same bits; a record says whether it was."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "numerics": numerics(),
    }
    fields = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if not line.strip():
                    break  # the first processor's block is enough
                key, _, value = line.partition(":")
                fields[key.strip()] = value.strip()
    except OSError:
        pass
    if "model name" in fields:
        info["cpu"] = fields["model name"]
    if "cpu family" in fields:
        info["cpu_id"] = f"family {fields['cpu family']} model {fields.get('model')} stepping {fields.get('stepping')}"
    if "flags" in fields:
        info["cpu_flags_sha256"] = hashlib.sha256(" ".join(sorted(fields["flags"].split())).encode()).hexdigest()[:16]
    return info


def _prop_epochs_by_model(config: ReproduceSettings) -> dict[str, list[int]]:
    """``{"system/kind": schedule}`` of the L_prop runs whose schedule is not their system's."""
    out = {}
    for system in config.systems:
        default = epoch_schedule(system, config, "prop")
        for kind, loss in config.pairs:
            own = epoch_schedule(system, config, "prop", kind)
            if loss_kind(loss).proposed and own != default:
                out[f"{system}/{kind}"] = list(own)
    return out


def _quadrature_by_model(config: ReproduceSettings) -> dict[str, str]:
    """``{"system/kind": rule}`` of the L_prop runs whose L_Iτ rule is not the run's."""
    default = (config.train_overrides or {}).get("quadrature", REPRODUCE_QUADRATURE)
    out = {}
    for system in config.systems:
        for kind, loss in config.pairs:
            rule = training_settings(system, config, 0, loss, kind).quadrature
            if rule != default:
                out[f"{system}/{kind}"] = rule
    return out


def _write_run_record(path: Path, config: ReproduceSettings, command, timings, data_meta) -> Path:

    record = {
        "command": command,
        "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "furuta_gym_version": __version__,
        "config": dataclasses.asdict(config),
        "epochs": {s: list(epoch_schedule(s, config, "traj")) for s in config.systems},
        "prop_epochs": {s: list(epoch_schedule(s, config, "prop")) for s in config.systems},
        "prop_epochs_by_model": _prop_epochs_by_model(config),
        "quadrature": (config.train_overrides or {}).get("quadrature", REPRODUCE_QUADRATURE),
        "quadrature_by_model": _quadrature_by_model(config),
        "data": data_meta,
        "machine": machine_info(),
        "packages": package_versions() | data_package_versions(),
        "seconds": timings,
    }
    path.write_text(json.dumps(record, indent=1, default=str) + "\n")
    return path
