"""Reproduce the paper's Tables 1 and 2 (simulated columns) and its figures with one call.

:func:`reproduce` generates the datasets (:mod:`furuta_gym.training.datagen`), trains every
model × loss pair the paper reports (DLN with L_traj and L_prop, APH with L_aph and L_prop, ADLN
with L_aph and L_prop) on both systems with :func:`furuta_gym.training.train`, evaluates each on
every test set (:mod:`furuta_gym.training.metrics`) and writes, under ``out``:

* ``tables.md`` / ``tables.csv`` — our log10 RMSE beside the paper's, cell by cell (N/A where the
  paper's APHYNITY prior fixes the quantity, X where a prediction diverged; with several seeds,
  mean ± standard deviation over seeds);
* ``figures/`` — predictions on the first 10 s of a forced test trajectory, energy as a function
  of the state (Furuta: over β and β̇) and along a trajectory, and the force decomposition on a
  forced trajectory;
* ``run.json`` — command, date, seeds, machine, package versions, timings;
* ``data/<system>/`` (generated CSVs) and ``runs/<system>/<model>_<loss>/seed<k>/`` (checkpoint,
  training history, ``metrics.json``).

The models train in this process, in a local pool of processes (``jobs``) or as Ray tasks on a
cluster (``executor="ray"``, :mod:`furuta_gym.training._ray_sweep`); the run folders, and so the
tables, are the same. Interrupted runs resume per model: a finished model (``model.eqx`` + ``metrics.json``) is reused,
an unfinished one continues from its training state. The experimental columns of Table 2
(``exp_*``) need the real QUBE-Servo 2 logs and are not reproduced.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import csv
import dataclasses
import datetime as _dt
import hashlib
import json
import math
import multiprocessing as mp
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import jax
import numpy as np

from .. import __version__, enable_x64, ensure_x64
from ..data import load_trajectories
from ..effects import WithEffects
from ..envs import Plant
from ..models import LumpedSystem, analytic_model, make_model, model_kind, system_definition
from ..signals import zero_phase_velocity
from ..systems import get_spec
from . import _ray_sweep, _reproduce_figures
from ._labels import LOSS_LABELS, MODEL_LABELS, TEST_SETS
from .checkpoint import load_model, package_versions, read_header
from .datagen import SYSTEM_DATA, MujocoGroundTruth, SensorOptions, data_package_versions, generate, system_data
from .loss_kinds import PROPOSED_LOSS, loss_kind
from .metrics import evaluate_model, metrics_to_json
from .recipe import (
    DEFAULT_LEARNING_RATE,
    DEFAULT_QUADRATURE,
    QUICK_EPOCHS,
    QUICK_PROP_EPOCHS,
    RECIPE,
    SYSTEM_ROWS,
    RunRecipe,
    recipe_row,
)
from .train import MODEL_FILE, STATE_FILE, TrainConfig, train

__all__ = [
    "PAPER_PAIRS",
    "TEST_SETS",
    "METRIC_COLUMNS",
    "ReproduceConfig",
    "training_config",
    "epoch_schedule",
    "reproduce",
    "load_paper_table",
    "build_tables",
    "run_settings",
    "same_settings",
    "machine_info",
    "worker_pool",
    "require_executor",
]

PAPER_PAIRS: tuple[tuple[str, str], ...] = (
    ("dln", "traj"),
    ("dln", "prop"),
    ("aph", "aph"),
    ("aph", "prop"),
    ("adln", "aph"),
    ("adln", "prop"),
)
#: What a selection run (``split="validation"``) is scored on instead: the validation datasets
#: (:func:`~furuta_gym.training.datagen.generate_validation`), which share no excitation with
#: the test sets; the Furuta scale is then fitted on ``val_scale_fit``, not ``scale_fit``.
VALIDATION_SETS = {name: dict(d.validation_labels) for name, d in SYSTEM_DATA.items()}
EVALUATION_SETS = {"test": TEST_SETS, "validation": VALIDATION_SETS}
SCALE_FIT_SET = {"test": "scale_fit", "validation": "val_scale_fit"}
PHYSICS_METRICS = ("inertial", "coriolis", "potential", "energy")
#: Columns of a system's metrics: each state variable's prediction error, then the physics terms.
METRIC_COLUMNS = {
    name: (*get_spec(name).joint_names, *(f"{j}_dot" for j in get_spec(name).joint_names), *PHYSICS_METRICS)
    for name in SYSTEM_DATA
}
#: How the data are measured (:attr:`ReproduceConfig.sensor`): the paper's simulated data, or as its
#: QUBE recordings were.
SENSORS = {"exact": SensorOptions(), "experiment": SensorOptions(quantize=True, velocity="filter")}
#: What the models train on (:attr:`ReproduceConfig.training_velocities`).
TRAINING_VELOCITIES = ("recorded", "zero_phase")
#: Where the models are trained (:attr:`ReproduceConfig.executor`).
EXECUTORS = ("local", "ray")
#: Table value of a model whose training failed (no finite model; reason in metrics.json).
FAILED = "fail"
# The paper's result tables, shipped with the package.
_PAPER_CSV_CANDIDATES = (Path(__file__).resolve().parent / "paper_tables.csv",)


@dataclasses.dataclass(frozen=True)
class ReproduceConfig:
    """What a reproduction run does.

    ``quick``: scaled-down datasets and far fewer epochs (minutes, not the paper's numbers);
    ``jobs``: models trained at once in separate processes (each model is mostly one core's
    work, so ``jobs`` = number of cores roughly divides the wall time by it);
    ``seeds``: model-initialisation seeds (the data come from ``data_seed``); ``systems`` /
    ``pairs``: subsets for tests; ``epochs``: override the per-system epoch schedule
    ``{system: (stage-1 epochs, stage-2 epochs)}`` of the L_traj / L_aph runs; ``prop_epochs``
    the same for L_prop, ``{system: (L_Iτ-alone epochs, stage 1, stage 2)}`` (a pair: no L_Iτ
    stage); ``small_data`` overrides the dataset size
    (default: small when quick); ``train_overrides``: extra :class:`TrainConfig` fields;
    ``model_overrides``: model hyper-parameters (:func:`~furuta_gym.models.make_model` keywords)
    for every model of the run, recorded with its settings like the defaults (a key a model kind
    does not know is an error, so runs that override F_a options name only aph / adln pairs).
    ``split``: ``"test"`` (the reproduction) or ``"validation"`` (a selection run: trained on the
    same training data, scale-fitted and scored on the validation datasets only — no test set
    is written or scored, no figure made).
    ``executor``: ``"local"`` (this process, or a local pool of ``jobs`` processes) or ``"ray"``
    (each model × seed a Ray task asking for ``cpus_per_task`` CPUs, on the cluster at
    ``address`` or, without one, on a local Ray instance running ``jobs`` tasks at once; needs
    the ``[cluster]`` extra). Neither changes a result: the run folders are the same.
    ``plant``: a plant file (a diagnosis JSON or an MJCF that furuta-gym wrote) whose MuJoCo
    plant generates the data instead of the shipped model, and whose model (its lumped parameters
    and memoryless effects) is the truth the physics columns compare with; the state columns then
    sit beside the paper's *experimental* values. ``sensor``: ``"exact"`` (the paper's simulated
    data) or ``"experiment"`` (its QUBE recordings: 2048-count encoders and the derivative filter
    ω0 = 100, ξ = 0.8 for the velocities, at 500 Hz). ``integral_span``: quadrature intervals
    summed into one L_Iτ residual in every L_prop run (1: the paper's; see
    :func:`~furuta_gym.training.losses.integral_loss_terms`, and docs/learning.md for its use on
    data whose velocities a filter estimated). ``training_velocities``: the training and
    scale-fit trajectories' velocities as the sensor gave them (``"recorded"``) or re-estimated
    offline from the angles without lag (``"zero_phase"``,
    :func:`~furuta_gym.signals.zero_phase_velocity`), as one would process logged data; the test
    sets are scored as recorded either way.
    """

    quick: bool = False
    seeds: tuple[int, ...] = (0,)
    data_seed: int = 0
    systems: tuple[str, ...] = ("nmsd", "furuta")
    pairs: tuple[tuple[str, str], ...] = PAPER_PAIRS
    epochs: dict | None = None
    prop_epochs: dict | None = None
    small_data: bool | None = None
    train_overrides: dict | None = None
    model_overrides: dict | None = None
    ground_truth: str = "auto"
    plant: str | None = None
    sensor: str = "exact"
    figures: bool = True
    progress: bool = True
    jobs: int = 1
    split: str = "test"
    executor: str = "local"
    address: str | None = None
    cpus_per_task: int = 1
    integral_span: int = 1
    training_velocities: str = "recorded"

    def __post_init__(self):
        self._check_execution()
        self._check_runs()
        self._check_data()

    def _check_execution(self) -> None:
        """What is evaluated, and how the runs are spread over processes or a cluster."""
        if self.split not in EVALUATION_SETS:
            raise ValueError(f"split must be one of {sorted(EVALUATION_SETS)}, got {self.split!r}")
        if int(self.jobs) < 1:
            raise ValueError(f"jobs must be at least 1, got {self.jobs}")
        if self.executor not in EXECUTORS:
            raise ValueError(f"executor must be one of {EXECUTORS}, got {self.executor!r}")
        if self.address is not None and self.executor != "ray":
            raise ValueError("address names a Ray cluster: it needs executor='ray'")
        if int(self.cpus_per_task) < 1:
            raise ValueError(f"cpus_per_task must be at least 1, got {self.cpus_per_task}")

    def _check_runs(self) -> None:
        """The systems, (model, loss) pairs and seeds, each run once."""
        for s in self.systems:
            get_spec(s)
        for kind, loss in self.pairs:
            if (kind, loss) not in PAPER_PAIRS:
                raise ValueError(f"pair ({kind!r}, {loss!r}) is not one the paper reports: {PAPER_PAIRS}")
        if not self.seeds:
            raise ValueError("seeds must name at least one seed")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must differ: a seed twice would count one model twice, got {self.seeds}")

    def _check_data(self) -> None:
        """How the training data are made and read."""
        if not (isinstance(self.integral_span, int) and self.integral_span >= 1):
            raise ValueError(
                f"integral_span must be a positive integer (intervals per L_Iτ residual), got {self.integral_span!r}"
            )
        if self.training_velocities not in TRAINING_VELOCITIES:
            raise ValueError(
                f"training_velocities must be one of {TRAINING_VELOCITIES}, got {self.training_velocities!r}"
            )
        if self.sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {sorted(SENSORS)}, got {self.sensor!r}")
        if self.plant is not None and self.ground_truth == "analytic":
            raise ValueError("plant= is a MuJoCo plant: it needs ground_truth 'auto' or 'mujoco'")

    @property
    def small(self) -> bool:
        return self.quick if self.small_data is None else self.small_data


# The full run's recipe is one table (:mod:`furuta_gym.training.recipe`, rows citing the decision
# log in docs/reproduce.md); the names below are views of it.
FULL_PROP_EPOCHS = {s: rows["prop"].epochs for s, rows in SYSTEM_ROWS.items()}
REPRODUCE_QUADRATURE = DEFAULT_QUADRATURE
_PROP_ROWS = {(s, k): row for (s, k, loss), row in RECIPE.items() if loss_kind(loss).proposed}
FULL_PROP_QUADRATURE = {key: row.quadrature for key, row in _PROP_ROWS.items() if row.quadrature != DEFAULT_QUADRATURE}
FULL_PROP_FINETUNE_LEARNING_RATE = {
    key: row.finetune_learning_rate
    for key, row in _PROP_ROWS.items()
    if row.finetune_learning_rate != DEFAULT_LEARNING_RATE
}


def _run_recipe(system: str, config: ReproduceConfig, loss: str, kind: str | None) -> RunRecipe:
    """The recipe row of one run: the full run's, or with ``--quick``'s / the caller's epochs."""
    name = get_spec(system).name
    if not loss_kind(loss).proposed:
        table = config.epochs or (QUICK_EPOCHS if config.quick else None)
    else:
        table = config.prop_epochs or (QUICK_PROP_EPOCHS if config.quick else None)
    return recipe_row(name, kind, loss, None if table is None else tuple(table[name]))


def epoch_schedule(system: str, config: ReproduceConfig, loss: str, kind: str | None = None) -> tuple[int, ...]:
    """Epochs per stage of ``loss`` runs of model ``kind`` on ``system`` (L_prop: ``(L_Iτ alone,
    stage 1, stage 2)``, others ``(stage 1, stage 2)``)."""
    return _run_recipe(system, config, loss, kind).epochs


def quadrature_rule(system: str, config: ReproduceConfig, loss: str, kind: str | None = None) -> str:
    """L_Iτ's quadrature (and, on the Furuta, the scale fit's) for ``loss`` runs of ``kind`` on
    ``system``, before the caller's overrides."""
    return _run_recipe(system, config, loss, kind).quadrature


def training_config(system: str, config: ReproduceConfig, seed: int, loss: str = "prop", kind: str | None = None):
    """The :class:`~furuta_gym.training.TrainConfig` of one run of model ``kind`` on ``system``
    with ``loss``: its recipe row, then the caller's ``train_overrides``."""
    name = get_spec(system).name
    row = _run_recipe(name, config, loss, kind)
    horizons = tuple(TrainConfig.for_system(name).horizons)
    proposed = loss_kind(loss).proposed
    if proposed and len(row.epochs) == 3:  # a leading stage of L_Iτ alone
        horizons = (None, *horizons)
    overrides: dict[str, Any] = dict(
        epochs=row.epochs,
        horizons=horizons,
        seed=seed,
        progress=config.progress,
        checkpoint_every=0,
        quadrature=row.quadrature,
    )
    if config.quick:  # a few hundred steps per model: compiling them is most of the run
        overrides["fast_compile"] = True
    if proposed:
        overrides["lambda_traj"] = row.lambda_traj
        overrides["integral_span"] = config.integral_span
        if row.augmentation_weight is not None:
            # written out, not left to the None default: the run record then says which μ it used
            overrides["augmentation_weight"] = row.augmentation_weight
        steps = (row.itau_learning_rate, row.finetune_learning_rate)
        if len(row.epochs) == 3 and steps != (TrainConfig.learning_rate,) * 2:
            overrides["learning_rate"] = (steps[0], steps[1], steps[1])
    overrides.update(config.train_overrides or {})
    return TrainConfig.for_system(name, **overrides)


def load_paper_table(path: str | Path | None = None) -> dict[tuple[str, str, str, str, str], str]:
    """The paper's cells ``{(system, test_set, MODEL, loss, metric): "value" | "N/A" | "X"}``.

    Reads the copy of the paper's tables shipped beside this module.
    """
    candidates = [Path(path)] if path is not None else list(_PAPER_CSV_CANDIDATES)
    for p in candidates:
        if p.is_file():
            table = {}
            with p.open() as fh:
                lines = [ln for ln in fh if ln.strip() and not ln.startswith("#")]
            header = [h.strip() for h in lines[0].split(",")]
            for ln in lines[1:]:
                cells = [c.strip() for c in ln.split(",")]
                if len(cells) != len(header):  # zip would drop or pad silently
                    raise ValueError(f"{p}: {len(cells)} cells where the header has {len(header)}: {ln.strip()!r}")
                row = dict(zip(header, cells, strict=True))
                key = (row["system"], row["test_set"], row["model"], row["loss"], row["metric"])
                table[key] = row["log10_rmse"]
            return table
    raise FileNotFoundError(f"paper table not found; looked in {[str(c) for c in candidates]}")


# --------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------


def _log(msg: str, stream=None) -> None:
    print(msg, file=stream or sys.stderr, flush=True)


def _datasets(system: str, out: Path, config: ReproduceConfig):
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


def _plant_json(config: ReproduceConfig) -> dict | None:
    """The plant of ``config`` as JSON (what a data manifest records), or None."""
    return None if config.plant is None else json.loads(json.dumps(Plant.load(config.plant).to_json()))


def _generate_data(system: str, folder: Path, config: ReproduceConfig) -> None:
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


def _regenerate_data(system: str, folder: Path, meta: dict, missing: Sequence[str], config: ReproduceConfig) -> None:
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


#: The form of a run record (``reproduce_config.json``); a record without the key is form 1.
#: A training setting added later whose default does what runs did before it needs nothing (the
#: record lacks it and compares as that default); a change that older records cannot be compared
#: with bumps this, and runs of another form are then trained again, never guessed equal.
RUN_RECORD_SCHEMA = 1


def run_settings(system: str, kind: str, loss: str, seed: int, config: ReproduceConfig) -> dict:
    """What a run directory's ``reproduce_config.json`` records for this run — its training
    settings (the progress bar aside) and architecture — in JSON's own form (lists, not tuples),
    so it compares with a saved record as it is."""
    train = training_config(system, config, seed, loss, kind).to_json()
    train.pop("progress", None)
    settings = {
        "schema": RUN_RECORD_SCHEMA,
        "system": system,
        "model": kind,
        "loss": loss,
        "seed": seed,
        "train": train,
        "model_hparams": _default_hparams(system, kind, config.model_overrides),
    }
    if config.split != "test":  # the scale is fitted on the split's own trajectory
        settings["split"] = config.split
    if config.training_velocities != "recorded":
        settings["training_velocities"] = config.training_velocities
    return json.loads(json.dumps(settings))


def same_settings(saved: dict, current: dict) -> bool:
    """Whether a run directory's recorded settings are this run's: the same record form
    (:data:`RUN_RECORD_SCHEMA`) and the same values, where a training setting the record lacks
    counts as its default (it was added later, with a default that keeps what runs did)."""
    if saved.get("schema", 1) != current.get("schema", 1):
        return False
    defaults = json.loads(json.dumps(TrainConfig().to_json()))
    saved = {k: v for k, v in saved.items() if k != "schema"}
    current = {k: v for k, v in current.items() if k != "schema"}
    saved["train"] = dict(saved.get("train", {}))
    for key, value in current.get("train", {}).items():
        if key not in saved["train"] and key in defaults and value == defaults[key]:
            saved["train"][key] = value
    # keep_best_itau acts on stages of L_Iτ alone only: without one, runs agree whatever it says
    saved, current = (_without_inert_settings(d) for d in (saved, current))
    return saved == current


def _without_inert_settings(settings: dict) -> dict:
    train = dict(settings.get("train", {}))
    if None not in train.get("horizons", [None]):
        train.pop("keep_best_itau", None)
    return dict(settings, train=train)


def _default_hparams(system: str, kind: str, overrides: dict | None = None) -> dict:
    """The architecture a new model of this kind gets, with ``overrides`` (so a run trained with
    another is never silently reused)."""
    model = make_model(system, kind, jax.random.PRNGKey(0), **(overrides or {}))
    return json.loads(json.dumps(dict(model.hparams), default=str))


def _run_one(system, kind, loss, seed, data, run_dir: Path, config: ReproduceConfig, truth):
    """Train (or resume / reuse) one model and evaluate it; returns its metrics dict."""
    metrics_path = run_dir / "metrics.json"
    model_path = run_dir / MODEL_FILE
    tcfg = training_config(system, config, seed, loss, kind)
    cfg_json = run_settings(system, kind, loss, seed, config)
    cfg_path = run_dir / "reproduce_config.json"
    if cfg_path.exists():
        saved = json.loads(cfg_path.read_text())
        if "model_hparams" not in saved and model_path.exists():
            # a record from before the architecture was recorded: the checkpoint's header knows it

            saved["model_hparams"] = json.loads(json.dumps(read_header(model_path).get("hparams", {}), default=str))
        if not same_settings(saved, cfg_json):
            raise ValueError(f"{run_dir}: holds a run with other settings ({cfg_path}); choose another --out")
    if metrics_path.exists():
        metrics = json.loads(metrics_path.read_text())
        if model_path.exists() or "_error" in metrics:
            return metrics, 0.0, "reused"
    run_dir.mkdir(parents=True, exist_ok=True)
    cfg_path.write_text(json.dumps(cfg_json, indent=1) + "\n")
    t0 = time.perf_counter()
    status = "trained"
    if model_path.exists():
        model = load_model(model_path, expected_system=system)
        status = "loaded"
    else:
        resume = (run_dir / STATE_FILE).exists()
        status = "resumed" if resume else "trained"
        train_trajs, forced = _training_data(system, data, config)
        try:
            train(
                kind,
                system,
                loss,
                train_trajs,
                tcfg,
                out_dir=run_dir,
                resume=resume,
                forced_trajs=forced,
                hparams=config.model_overrides,
            )
            error = None if model_path.exists() else "training ended without a finite model"
        except (ValueError, FloatingPointError, RuntimeError) as exc:  # e.g. a failed scale fit
            error = f"{type(exc).__name__}: {exc}"
        if error is not None:
            # recorded, never hidden: every cell of this model reads "fail" in the tables
            metrics: dict[str, Any] = {
                label: {m: FAILED for m in METRIC_COLUMNS[system]} for label in EVALUATION_SETS[config.split][system]
            }
            metrics["_error"] = error
            metrics_path.write_text(json.dumps(metrics, indent=1) + "\n")
            return metrics, time.perf_counter() - t0, "failed"
        model = load_model(model_path, expected_system=system)
    t_train = time.perf_counter() - t0
    metrics = {}
    for label, name in EVALUATION_SETS[config.split][system].items():
        m = evaluate_model(model, data[name], truth, physics=not model_kind(kind).analytic_prior)
        metrics[label] = metrics_to_json(m)
    metrics["_seconds"] = {"train": round(t_train, 1), "evaluate": round(time.perf_counter() - t0 - t_train, 1)}
    metrics_path.write_text(json.dumps(metrics, indent=1) + "\n")
    return metrics, t_train, status


def _training_data(system: str, data: dict, config: ReproduceConfig):
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


def _worker_inputs(system: str, out: Path, config: ReproduceConfig):
    """``(datasets, ground-truth model)`` of ``system`` in a worker process, read from what the
    parent generated under ``out``."""
    enable_x64()  # the parent already chose float64 (and said so): no second warning
    data, _ = _datasets(system, out, config)
    return data, truth_model(system, config)


def truth_model(system: str, config: ReproduceConfig):
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


def _run_task(system, kind, loss, seed, out, config, data=None, truth=None):
    """One model of the run (also the body of a worker process): ``(metrics, seconds, status)``."""
    if data is None:  # in a worker process
        data, truth = _worker_inputs(system, out, config)
    run_dir = out / "runs" / system / f"{kind}_{loss}" / f"seed{seed}"
    t0 = time.perf_counter()
    metrics, _, status = _run_one(system, kind, loss, seed, data, run_dir, config, truth)
    return metrics, round(time.perf_counter() - t0, 1), status


#: Seconds one model takes (training + evaluation, one seed), as a full and a --quick run on a
#: 2-core machine measured them (their run.json). Only the order in which a pool of jobs starts
#: the models reads them: longest first, so no job is left with a long model at the end while
#: the others idle (LPT scheduling).
EXPECTED_SECONDS = {
    "full": {
        ("nmsd", "dln", "traj"): 349,
        ("nmsd", "dln", "prop"): 953,
        ("nmsd", "aph", "aph"): 60,
        ("nmsd", "aph", "prop"): 175,
        ("nmsd", "adln", "aph"): 449,
        ("nmsd", "adln", "prop"): 943,
        ("furuta", "dln", "traj"): 55,
        ("furuta", "dln", "prop"): 297,
        ("furuta", "aph", "aph"): 42,
        ("furuta", "aph", "prop"): 105,
        ("furuta", "adln", "aph"): 61,
        ("furuta", "adln", "prop"): 1808,
    },
    "quick": {
        ("nmsd", "dln", "traj"): 38,
        ("nmsd", "dln", "prop"): 56,
        ("nmsd", "aph", "aph"): 32,
        ("nmsd", "aph", "prop"): 39,
        ("nmsd", "adln", "aph"): 44,
        ("nmsd", "adln", "prop"): 62,
        ("furuta", "dln", "traj"): 42,
        ("furuta", "dln", "prop"): 39,
        ("furuta", "aph", "aph"): 36,
        ("furuta", "aph", "prop"): 44,
        ("furuta", "adln", "aph"): 45,
        ("furuta", "adln", "prop"): 49,
    },
}


def _longest_first(tasks, config: ReproduceConfig) -> list:
    """``tasks`` in the order a pool should start them: longest expected first (ties: as given)."""
    table = EXPECTED_SECONDS["quick" if config.quick else "full"]
    return sorted(tasks, key=lambda t: -table.get(t[:3], 0))


def _figures_task(system: str, out: Path, config: ReproduceConfig, data=None, truth=None):
    """The figures of one system (also the body of a worker process): ``(paths | error text,
    seconds)``. A failure is returned, not raised: figures must never lose the tables."""
    t0 = time.perf_counter()
    try:
        if data is None:  # in a worker process
            data, truth = _worker_inputs(system, out, config)
        one = dataclasses.replace(config, systems=(system,))
        result = _reproduce_figures.make_figures(out, one, {system: {"data": data, "truth": truth}})
    except Exception as exc:
        result = f"{type(exc).__name__}: {exc}"
    return result, round(time.perf_counter() - t0, 1)


def _run_all(tasks, out: Path, config: ReproduceConfig, loaded: dict, log) -> Iterator[tuple[str, Any, Any]]:
    """Yield ``("model", task, (metrics, seconds, status))`` for every task, ``config.jobs`` at a
    time (or as Ray schedules them), and with ``config.figures`` ``("figures", system, (paths |
    error, seconds))`` once per system, made as soon as that system's last model is done (in the
    pool: beside the models still training, and in the worker that has most likely compiled the
    models' predictions already)."""

    def report(task, result):
        system, kind, loss, seed = task
        log(f"[{system}] {MODEL_LABELS[kind]} ({LOSS_LABELS[loss]}) seed {seed}: {result[2]} in {result[1]} s")

    if config.executor == "local" and (config.jobs == 1 or len(tasks) == 1):
        yield from _run_in_process(tasks, out, config, loaded, report)
        return
    # Progress bars of parallel workers would overwrite each other: the log lines stay.
    worker_config = dataclasses.replace(config, progress=False)
    with worker_pool(config) as executor:
        yield from _drain(executor, tasks, executor.folder(out), worker_config, report)


def _run_in_process(tasks, out: Path, config: ReproduceConfig, loaded: dict, report):
    """:func:`_run_all` one model after the other in this process, on the data it has loaded."""
    for task in tasks:
        system, kind, loss, seed = task
        result = _run_task(system, kind, loss, seed, out, config, loaded[system]["data"], loaded[system]["truth"])
        report(task, result)
        yield "model", task, result
    if config.figures:
        for system in dict.fromkeys(t[0] for t in tasks):
            yield "figures", system, _figures_task(system, out, config, loaded[system]["data"], loaded[system]["truth"])


def require_executor(config: ReproduceConfig) -> None:
    """Raise the ImportError :func:`worker_pool` would, before any work: ``executor="ray"`` without
    Ray installed (one line naming the ``[cluster]`` extra)."""
    if config.executor == "ray":
        _ray_sweep._import_ray()


@contextlib.contextmanager
def worker_pool(config: ReproduceConfig) -> Iterator[Any]:
    """The workers that train ``config``'s models, behind one interface: ``submit(fn, args,
    name)`` → a handle, ``first_done(handles)`` → the finished ones, ``result(handle)``, and
    ``folder(out)``: ``out`` as the workers must see it. A local pool of ``config.jobs`` processes,
    or with ``executor="ray"`` Ray tasks of ``cpus_per_task`` CPUs each (retried when their worker
    is lost; :mod:`~furuta_gym.training._ray_sweep`), on the cluster at ``address`` or a local
    instance running ``jobs`` at once; without Ray installed, one ImportError naming the extra.
    A study that trains runs of its own (studies/select_option.py) takes its workers from here."""
    if config.executor == "ray":
        with _ray_sweep.ray_executor(config.address, config.jobs, config.cpus_per_task) as executor:
            yield executor
        return
    # "spawn": a forked copy of a process that already runs JAX's thread pools can deadlock.
    with cf.ProcessPoolExecutor(max_workers=config.jobs, mp_context=mp.get_context("spawn")) as pool:
        yield _PoolExecutor(pool)


class _PoolExecutor:
    """A local process pool behind the interface :func:`_drain` uses (Ray's is in _ray_sweep)."""

    def __init__(self, pool: cf.Executor):
        self._pool = pool

    def folder(self, out: Path) -> Path:
        """``out`` as it is: the workers share this process's working folder."""
        return out

    def submit(self, fn, args, name: str):
        return self._pool.submit(fn, *args)

    def first_done(self, handles) -> list:
        return list(cf.wait(handles, return_when=cf.FIRST_COMPLETED)[0])

    def result(self, handle):
        return handle.result()


def _drain(executor, tasks, out: Path, config: ReproduceConfig, report):
    """:func:`_run_all` on workers: every model submitted longest first, each system's figures
    submitted once its last model is done; events yielded as they finish."""
    left: dict[str, int] = {}
    for t in tasks:
        left[t[0]] = left.get(t[0], 0) + 1
    pending = {
        executor.submit(_run_task, (*task, out, config), _task_name(task)): ("model", task)
        for task in _longest_first(tasks, config)
    }
    while pending:
        for handle in executor.first_done(pending):
            what, item = pending.pop(handle)
            result = executor.result(handle)
            if what == "figures":
                yield "figures", item, result
                continue
            report(item, result)
            yield "model", item, result
            left[item[0]] -= 1
            if config.figures and left[item[0]] == 0:
                handle = executor.submit(_figures_task, (item[0], out, config), f"{item[0]}/figures")
                pending[handle] = ("figures", item[0])


def _task_name(task) -> str:
    """A model's name on a cluster's dashboard: its run folder under ``runs/``."""
    system, kind, loss, seed = task
    return f"{system}/{kind}_{loss}/seed{seed}"


def reproduce(
    out: str | Path,
    config: ReproduceConfig = ReproduceConfig(),
    *,
    command: str | None = None,
    log: Callable[[str], None] = _log,
) -> dict[str, Path]:
    """Run the reproduction into ``out``; returns the paths of the written tables, figures and
    run record. See the module docstring."""
    ensure_x64()
    if config.split != "test":  # the figures show the test sets
        config = dataclasses.replace(config, figures=False)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    timings: dict[str, Any] = {}
    results: dict[tuple, list] = {}  # (system, kind, loss) -> [metrics per seed]
    data_meta = {}
    models_for_figures: dict[str, dict] = {}
    for system in config.systems:
        t0 = time.perf_counter()
        data, meta = _datasets(system, out, config)
        data_meta[system] = {k: meta.get(k) for k in ("seed", "small", "ground_truth", "seconds")}
        timings[f"{system}/data"] = round(time.perf_counter() - t0, 1)
        log(f"[{system}] data ready ({meta.get('ground_truth')} ground truth) in {timings[f'{system}/data']} s")
        models_for_figures[system] = {"data": data, "truth": truth_model(system, config)}
    tasks = [
        (system, kind, loss, seed) for system in config.systems for kind, loss in config.pairs for seed in config.seeds
    ]
    figure_paths: dict[str, dict] = {}
    for what, item, result in _run_all(tasks, out, config, models_for_figures, log):
        if what == "figures":
            made, seconds = result
            timings[f"figures/{item}"] = seconds
            if isinstance(made, str):
                log(f"[{item}] figures failed: {made}")
            else:
                figure_paths[item] = made
            continue
        (system, kind, loss, seed), (metrics, dt, status) = item, result
        timings[f"{system}/{kind}_{loss}/seed{seed}"] = {"seconds": dt, "status": status}
        if status == "reused" and isinstance(metrics.get("_seconds"), dict):
            # what the model cost when it was trained (an earlier or interrupted invocation)
            timings[f"{system}/{kind}_{loss}/seed{seed}"]["original"] = metrics["_seconds"]
        results[(system, kind, loss, seed)] = metrics
    # the paper's row order and seed order, whatever order the jobs finished in
    results = {
        (s, k, l): [results[(s, k, l, seed)] for seed in config.seeds] for s in config.systems for k, l in config.pairs
    }
    paths = {}
    rows = build_tables(results, config)
    paths["tables.csv"] = _write_csv(out / "tables.csv", rows)
    paths["tables.md"] = _write_markdown(out / "tables.md", rows, config, data_meta)
    for system in config.systems:
        paths.update(figure_paths.get(system, {}))
    if config.figures:
        # seconds spent making figures, all systems (with jobs > 1, beside the training)
        timings["figures"] = round(sum(timings.get(f"figures/{s}", 0.0) for s in config.systems), 1)
    timings["total"] = round(time.perf_counter() - t_start, 1)
    paths["run.json"] = _write_run_record(out / "run.json", config, command, timings, data_meta)
    log(f"done in {timings['total']} s: {out / 'tables.md'}")
    return paths


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------


def _aggregate(values: Sequence[Any]) -> tuple[str, float | None, float | None, int]:
    """(cell text, mean, std, n diverged or failed) over seeds."""
    diverged = sum(1 for v in values if v == "X")
    failed = sum(1 for v in values if v == FAILED)
    finite = [float(v) for v in values if v not in ("X", FAILED, None)]
    n = len(values)
    if not finite:
        text = "X" if diverged else (FAILED if failed else "N/A")
        return text, None, None, diverged + failed
    mean = float(np.mean(finite))
    std = float(np.std(finite, ddof=1)) if len(finite) > 1 else None
    text = f"{mean:.4f}" if std is None else f"{mean:.2f} ± {std:.2f}"
    if diverged:
        text += f" ({diverged}/{n} X)"
    if failed:
        text += f" ({failed}/{n} {FAILED})"
    return text, mean, std, diverged + failed


def build_tables(results: dict[tuple, list], config: ReproduceConfig) -> list[dict]:
    """One row per (system, test set, model, loss, metric): ours (text, mean, std) and paper."""
    paper = load_paper_table() if config.split == "test" else {}  # no paper value for validation
    rows = []
    for system in config.systems:
        for label in EVALUATION_SETS[config.split][system]:
            for kind, loss in config.pairs:
                per_seed = results.get((system, kind, loss), [])
                for metric in METRIC_COLUMNS[system]:
                    paper_value = paper.get(
                        (system, label, MODEL_LABELS[kind], loss, _paper_metric(metric, config)), ""
                    )
                    values = []
                    if model_kind(kind).analytic_prior and metric in PHYSICS_METRICS:
                        ours_text, mean, std, ndiv = "N/A", None, None, 0
                    else:
                        values = [m[label].get(metric) for m in per_seed]
                        values = [float(v) if isinstance(v, str) and v not in ("X", FAILED) else v for v in values]
                        ours_text, mean, std, ndiv = _aggregate(values)
                    rows.append(
                        dict(
                            system=system,
                            test_set=label,
                            model=MODEL_LABELS[kind],
                            loss=loss,
                            metric=metric,
                            ours=ours_text,
                            ours_mean="" if mean is None else f"{mean:.4f}",
                            ours_std="" if std is None else f"{std:.4f}",
                            n_seeds=len(per_seed),
                            # each seed's own value, in the order of config.seeds: the spread's source
                            ours_per_seed=" ".join(_seed_text(v) for v in values),
                            n_diverged=ndiv,
                            paper=paper_value,
                            better_or_equal=_compare(mean, ours_text, paper_value),
                        )
                    )
    return rows


def _paper_metric(metric: str, config: ReproduceConfig) -> str:
    """The paper's column for ``metric``: on a plant (a calibrated rig), a state's error sits beside
    the paper's experimental column (``exp_<state>``); physics columns have no experimental value."""
    if config.plant is None:
        return metric
    return "" if metric in PHYSICS_METRICS else f"exp_{metric}"


def _seed_text(value) -> str:
    """One seed's cell in ``ours_per_seed``: the number, or X / fail / N/A."""
    if value is None:
        return "N/A"
    return value if isinstance(value, str) else f"{value:.4f}"


def _compare(mean, ours_text, paper_value) -> str:
    """ "yes"/"no" when both cells are numbers (lower is better), "" otherwise."""
    try:
        p = float(paper_value)
    except (TypeError, ValueError):
        return ""
    if mean is None or not math.isfinite(mean) or "X" in ours_text or FAILED in ours_text:
        return "no" if ours_text.startswith(("X", FAILED)) else ""
    return "yes" if mean <= p else "no"


def _write_csv(path: Path, rows: list[dict]) -> Path:

    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return path


_METRIC_HEADERS = {
    "p": "p",
    "p_dot": "ṗ",
    "alpha": "α",
    "beta": "β",
    "alpha_dot": "α̇",
    "beta_dot": "β̇",
    "inertial": "Inertial",
    "coriolis": "Coriolis",
    "potential": "Potential-derived",
    "energy": "Energy",
}


def _write_markdown(path: Path, rows: list[dict], config: ReproduceConfig, data_meta) -> Path:

    lines = [
        "# Reproduction of Tables 1 and 2 (simulated systems)",
        "",
        "log10 RMSE, lower is better. Each cell: **ours** (paper). N/A: given by the APHYNITY prior "
        "(as in the paper); X: the prediction diverged on at least one test trajectory; fail: "
        "training produced no finite model (reason in the run's metrics.json). "
        + (
            f"Ours: mean ± sample standard deviation over {len(config.seeds)} model-initialisation "
            f"seeds ({', '.join(map(str, config.seeds))}; each seed's value is in tables.csv, "
            "ours_per_seed); the data are the same for every seed."
            if len(config.seeds) > 1
            else f"Ours: one model seed ({', '.join(map(str, config.seeds))})."
        )
        + " A ✓ marks our cell at or below the paper's.",
        "",
    ]
    if config.quick:
        lines += [
            "> **Quick run**: scaled-down data and a few epochs — checks the pipeline, not the paper's numbers.",
            "",
        ]
    for system in config.systems:
        cols = METRIC_COLUMNS[system]
        title = system_definition(system).table_title
        gt = data_meta.get(system, {}).get("ground_truth")
        lines += [f"## {title}", "", f"Data: {gt} ground truth, seed {config.data_seed}.", ""]
        lines.append("| Test set | Model | " + " | ".join(_METRIC_HEADERS[c] for c in cols) + " |")
        lines.append("|---|---|" + "---|" * len(cols))
        for label in EVALUATION_SETS[config.split][system]:
            for kind, loss in config.pairs:
                cells = []
                for c in cols:
                    r = next(
                        r
                        for r in rows
                        if (r["system"], r["test_set"], r["model"], r["loss"], r["metric"])
                        == (system, label, MODEL_LABELS[kind], loss, c)
                    )
                    mark = " ✓" if r["better_or_equal"] == "yes" else ""
                    paper = r["paper"] or "–"
                    cells.append(f"**{r['ours']}**{mark} ({paper})")
                lines.append(f"| {label} | {MODEL_LABELS[kind]} ({LOSS_LABELS[loss]}) | " + " | ".join(cells) + " |")
        lines.append("")
    lines += _summary_lines(rows, config)
    path.write_text("\n".join(lines) + "\n")
    return path


def _summary_lines(rows: list[dict], config: ReproduceConfig) -> list[str]:
    out = ["## Summary", ""]
    prop = [r for r in rows if loss_kind(r["loss"]).proposed and r["better_or_equal"] in ("yes", "no")]
    if prop:
        n_yes = sum(r["better_or_equal"] == "yes" for r in prop)
        out.append(f"- L_prop rows: {n_yes} of {len(prop)} numeric cells at or below the paper's.")
    allnum = [r for r in rows if r["better_or_equal"] in ("yes", "no")]
    if allnum:
        n_yes = sum(r["better_or_equal"] == "yes" for r in allnum)
        out.append(f"- All rows: {n_yes} of {len(allnum)} numeric cells at or below the paper's.")
    for system in config.systems:
        out += _main_claim_lines(rows, config, system)
    out.append("")
    return out


def _main_claim_lines(rows: list[dict], config: ReproduceConfig, system: str) -> list[str]:
    """The summary's lines on ``system``'s main claim, metric by metric (none without a claim)."""
    claim = system_data(system).main_claim
    if claim is None:
        return []
    out = [
        f"- Main claim ({claim}: L_prop gives a better force decomposition than L_traj for "
        "DLN and than L_aph for ADLN), ours:"
    ]
    for model, base in (("DLN", "traj"), ("ADLN", "aph")):
        if ((model.lower(), base) not in config.pairs) or ((model.lower(), PROPOSED_LOSS) not in config.pairs):
            continue
        for label in EVALUATION_SETS[config.split][system]:
            parts = [
                _claim_part(
                    _row_of(rows, system, label, model, PROPOSED_LOSS, metric),
                    _row_of(rows, system, label, model, base, metric),
                    metric,
                )
                for metric in ("inertial", "coriolis", "potential")
            ]
            out.append(f"  - {model} {label}: " + "; ".join(parts))
    return out


def _row_of(rows: list[dict], system, label, model, loss, metric) -> Any:
    """The row (a dict) of this cell, or None."""
    return next(
        (
            r
            for r in rows
            if (r["system"], r["test_set"], r["model"], r["loss"], r["metric"]) == (system, label, model, loss, metric)
        ),
        None,
    )


def _claim_part(prop_row, base_row, metric: str) -> str:
    """One metric of a main-claim line: L_prop's mean against the baseline's, and on how many seeds it holds."""
    a, b = _mean_of(prop_row), _mean_of(base_row)
    if a is None or b is None:
        return f"{metric}: n/a"
    seeds = _seeds_holding(prop_row, base_row)
    return f"{metric} {a:.2f} vs {b:.2f} ({'holds' if a < b else 'does not hold'}{seeds})"


def _mean_of(row) -> float | None:
    return float(row["ours_mean"]) if row and row["ours_mean"] else None


def _seeds_holding(prop_row: dict, base_row: dict) -> str:
    """With several seeds, on how many the claim holds seed by seed (seed k of L_prop against
    seed k of the baseline): a mean can hold on one lucky seed."""
    prop, base = prop_row["ours_per_seed"].split(), base_row["ours_per_seed"].split()
    if len(prop) < 2 or len(prop) != len(base):  # seed k against seed k needs the same seeds on both rows
        return ""
    pairs = list(zip(prop, base, strict=True))
    numeric = [(float(a), float(b)) for a, b in pairs if _is_number(a) and _is_number(b)]
    return f"; on {sum(a < b for a, b in numeric)} of {len(pairs)} seeds"


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def machine_info() -> dict[str, Any]:
    """The platform, Python, core count and CPU, as a run record notes them. Beside the CPU's model
    name, its family / model / stepping and a digest of its feature flags: XLA:CPU compiles for the
    host's features, and two hosts of one model name can round differently, which training
    amplifies into other models (docs/reproduce.md, "Same code, another host")."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
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


def _prop_epochs_by_model(config: ReproduceConfig) -> dict[str, list[int]]:
    """``{"system/kind": schedule}`` of the L_prop runs whose schedule is not their system's."""
    out = {}
    for system in config.systems:
        default = epoch_schedule(system, config, "prop")
        for kind, loss in config.pairs:
            own = epoch_schedule(system, config, "prop", kind)
            if loss_kind(loss).proposed and own != default:
                out[f"{system}/{kind}"] = list(own)
    return out


def _quadrature_by_model(config: ReproduceConfig) -> dict[str, str]:
    """``{"system/kind": rule}`` of the L_prop runs whose L_Iτ rule is not the run's."""
    default = (config.train_overrides or {}).get("quadrature", REPRODUCE_QUADRATURE)
    out = {}
    for system in config.systems:
        for kind, loss in config.pairs:
            rule = training_config(system, config, 0, loss, kind).quadrature
            if rule != default:
                out[f"{system}/{kind}"] = rule
    return out


def _write_run_record(path: Path, config: ReproduceConfig, command, timings, data_meta) -> Path:

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
