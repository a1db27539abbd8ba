"""The datasets of a reproduction run (generated once under ``out/data/<system>``, re-created
byte for byte when a committed run lacks its CSVs), what the models train on, and the ground
truth the physics columns compare with; part of :mod:`.reproduce`."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import tempfile
from pathlib import Path
from typing import Sequence

import numpy as np

from .. import enable_x64
from ..data import load_trajectories
from ..effects import WithEffects
from ..envs import Plant
from ..models import LumpedSystem, analytic_model, system_definition
from ..signals import zero_phase_velocity
from ._reproduce_settings import SCALE_FIT_SET, SENSORS, ReproduceSettings
from .datagen import MujocoGroundTruth, data_package_versions, generate


def _datasets(system: str, out: Path, config: ReproduceSettings):
    """Generate (or reuse) the datasets of ``system`` under ``out/data/<system>``."""
    folder = out / "data" / system
    manifest = folder / "manifest.json"
    if manifest.exists():
        meta = json.loads(manifest.read_text())
        held = (
            meta.get("seed"),
            bool(meta.get("small")),
            meta.get("split", "test"),
            meta.get("plant"),
            meta.get("sensor_name", "exact"),
        )
        wanted = (config.data_seed, config.small, config.split, _plant_json(config), config.sensor)
        if held != wanted:
            names = ("seed", "small", "split", "plant", "sensor")
            diff = ", ".join(
                f"{n}={h!r} (this run: {w!r})" for n, h, w in zip(names, held, wanted, strict=True) if h != w
            )
            raise ValueError(f"{folder}: holds data generated with {diff}; choose another --out")
        missing = [name for name, f in meta.get("files", {}).items() if not (folder / f["path"]).exists()]
        if missing:
            _regenerate_data(system, folder, meta, missing, config)
    else:
        _generate_data(system, folder, config)
    meta = json.loads(manifest.read_text())
    data = {name: load_trajectories(folder / f["path"], system) for name, f in meta["files"].items()}
    return data, meta


def _plant_json(config: ReproduceSettings) -> dict | None:
    """The plant of ``config`` as JSON (what a data manifest records), or None."""
    return None if config.plant is None else json.loads(json.dumps(Plant.load(config.plant).to_json()))


def _generate_data(system: str, folder: Path, config: ReproduceSettings) -> None:
    """Write the run's datasets of ``system`` to ``folder`` (with ``config``'s plant and sensor)."""
    truth = config.ground_truth
    if config.plant is not None:
        truth = MujocoGroundTruth(system, plant=Plant.load(config.plant))
    generate(
        system,
        folder,
        seed=config.data_seed,
        small=config.small,
        ground_truth=truth,
        sensor=SENSORS[config.sensor],
        overwrite=True,
        split=config.split,
    )
    if config.plant is not None or config.sensor != "exact":
        path = folder / "manifest.json"
        meta = json.loads(path.read_text())
        meta.update(plant=_plant_json(config), sensor_name=config.sensor)
        path.write_text(json.dumps(meta, indent=2) + "\n")


def _regenerate_data(system: str, folder: Path, meta: dict, missing: Sequence[str], config: ReproduceSettings) -> None:
    """Re-create data files a manifest lists but the folder lacks (a committed run keeps the
    manifest, not the CSVs): the data are seeded, so they must come out byte for byte as
    recorded; anything else is an error, never a silent change of the data under the models."""
    with tempfile.TemporaryDirectory() as tmp:
        fresh_config = dataclasses.replace(
            config, ground_truth=meta.get("ground_truth", "auto") if config.plant is None else config.ground_truth
        )
        _generate_data(system, Path(tmp), fresh_config)
        for name in missing:
            entry = meta["files"][name]
            fresh = Path(tmp) / entry["path"]
            digest = hashlib.sha256(fresh.read_bytes()).hexdigest()
            if entry.get("sha256") not in (None, digest):
                raise ValueError(
                    f"{folder / entry['path']}: missing, and regenerating it from its manifest gave "
                    f"other data (sha256 {digest[:12]}… ≠ {entry['sha256'][:12]}…; "
                    f"{_version_differences(meta)}). Restore the file or choose another --out"
                )
            shutil.copyfile(fresh, folder / entry["path"])


def _version_differences(meta: dict) -> str:
    """How this machine's packages differ from those the manifest's data were generated with."""
    recorded = meta.get("packages")
    if recorded is None:
        return "the manifest does not record the package versions; another MuJoCo or numpy version?"
    now = data_package_versions()
    diff = [f"{name} {v} (now {now.get(name)})" for name, v in recorded.items() if now.get(name) != v]
    return "generated with " + ", ".join(diff) if diff else "same package versions as recorded"


def _training_data(system: str, data: dict, config: ReproduceSettings):
    """``(training trajectories, scale-fit trajectories or None)`` as the run trains on them."""
    forced = None
    if system_definition(system).scale_fit_on_forced_data:
        name = SCALE_FIT_SET[config.split]
        if name not in data:  # never a run whose scale is silently left unfitted
            raise ValueError(f"{system} {config.split} data: no {name!r} set to fit the scale on (have {sorted(data)})")
        forced = data[name]
    if config.training_velocities == "recorded":
        return data["train"], forced

    def offline(trajs):
        return [dataclasses.replace(t, qd=zero_phase_velocity(np.asarray(t.q), t.dt)) for t in trajs]

    return offline(data["train"]), None if forced is None else offline(forced)


def _worker_inputs(system: str, out: Path, config: ReproduceSettings):
    """``(datasets, ground-truth model)`` of ``system`` in a worker process, read from what the
    parent generated under ``out``."""
    enable_x64()  # the parent already chose float64 (and said so): no second warning
    data, _ = _datasets(system, out, config)
    return data, truth_model(system, config)


def truth_model(system: str, config: ReproduceSettings):
    """What the physics columns compare with: the pinned analytic model, or the plant's model
    (its lumped parameters with its memoryless effects)."""
    if config.plant is None:
        return analytic_model(system)

    plant = Plant.load(config.plant)
    if plant.lumped is None:
        raise ValueError(
            f"plant {config.plant}: has no lumped parameters (a diagnosis or an MJCF furuta-gym "
            "wrote has them); a preset plant has no model to compare the physics with"
        )
    effects = [e for e in plant.effects if not e.kind.has_memory]
    base = LumpedSystem.of(system, plant.lumped)
    return WithEffects(base, effects) if effects else base
