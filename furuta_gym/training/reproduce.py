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

The pipeline's parts, one module each: :mod:`._reproduce_settings` (the run's settings and each
model's training recipe), :mod:`._reproduce_data` (datasets and ground truth),
:mod:`._reproduce_one_model` (train, resume or reuse, and score one model),
:mod:`._reproduce_executors` (in process, a local pool or Ray), :mod:`._reproduce_tables`
(ours beside the paper's) and :mod:`._reproduce_run_record` (``run.json``). The names users and
studies import are all here.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Any, Callable

from .. import ensure_x64
from .._deprecated import deprecated_names
from ._labels import TEST_SETS
from ._reproduce_data import _datasets, truth_model
from ._reproduce_executors import EXPECTED_SECONDS, _run_all, require_executor, worker_pool
from ._reproduce_one_model import RUN_RECORD_SCHEMA, run_settings, same_settings
from ._reproduce_run_record import _write_run_record, machine_info
from ._reproduce_settings import (
    EVALUATION_SETS,
    EXECUTORS,
    FAILED,
    FULL_PROP_EPOCHS,
    FULL_PROP_FINETUNE_LEARNING_RATE,
    FULL_PROP_QUADRATURE,
    METRIC_COLUMNS,
    PAPER_PAIRS,
    PHYSICS_METRICS,
    REPRODUCE_QUADRATURE,
    SCALE_FIT_SET,
    SENSORS,
    TRAINING_VELOCITIES,
    VALIDATION_SETS,
    ReproduceSettings,
    epoch_schedule,
    quadrature_rule,
    training_settings,
)
from ._reproduce_tables import _write_csv, _write_markdown, build_tables, load_paper_table

__all__ = [
    "PAPER_PAIRS",
    "TEST_SETS",
    "METRIC_COLUMNS",
    "ReproduceSettings",
    "training_settings",
    "epoch_schedule",
    "reproduce",
    "load_paper_table",
    "build_tables",
    "run_settings",
    "same_settings",
    "machine_info",
    "worker_pool",
    "require_executor",
    # the run's constants, kept importable from here (studies and tests read them)
    "VALIDATION_SETS",
    "EVALUATION_SETS",
    "SCALE_FIT_SET",
    "PHYSICS_METRICS",
    "SENSORS",
    "TRAINING_VELOCITIES",
    "EXECUTORS",
    "FAILED",
    "FULL_PROP_EPOCHS",
    "FULL_PROP_QUADRATURE",
    "FULL_PROP_FINETUNE_LEARNING_RATE",
    "REPRODUCE_QUADRATURE",
    "RUN_RECORD_SCHEMA",
    "EXPECTED_SECONDS",
    "quadrature_rule",
    "truth_model",
]


def _log(msg: str, stream=None) -> None:
    print(msg, file=stream or sys.stderr, flush=True)


def reproduce(
    out: str | Path,
    config: ReproduceSettings = ReproduceSettings(),
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
        _book(what, item, result, timings, results, figure_paths, log)
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


def _book(what: str, item, result, timings: dict, results: dict, figure_paths: dict, log) -> None:
    """Book one finished task: a system's figures, or one model's metrics and what it cost."""
    if what == "figures":
        made, seconds = result
        timings[f"figures/{item}"] = seconds
        if isinstance(made, str):
            log(f"[{item}] figures failed: {made}")
        else:
            figure_paths[item] = made
        return
    (system, kind, loss, seed), (metrics, dt, status) = item, result
    timings[f"{system}/{kind}_{loss}/seed{seed}"] = {"seconds": dt, "status": status}
    if status == "reused" and isinstance(metrics.get("_seconds"), dict):
        # what the model cost when it was trained (an earlier or interrupted invocation)
        timings[f"{system}/{kind}_{loss}/seed{seed}"]["original"] = metrics["_seconds"]
    results[(system, kind, loss, seed)] = metrics


__getattr__ = deprecated_names(__name__)
