"""One model of a reproduction run: train it (or resume, or reuse a finished one whose recorded
settings are this run's) and score it on the run's sets; part of :mod:`.reproduce`."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import jax

from ..models import make_model, model_kind
from ._reproduce_data import _training_data, _worker_inputs
from ._reproduce_settings import EVALUATION_SETS, FAILED, METRIC_COLUMNS, ReproduceSettings, training_settings
from .checkpoint import load_model, read_header
from .metrics import evaluate_model, metrics_to_json
from .train import MODEL_FILE, STATE_FILE, TrainSettings, train

#: The form of a run record (``reproduce_config.json``); a record without the key is form 1.
#: A training setting added later whose default does what runs did before it needs nothing (the
#: record lacks it and compares as that default); a change that older records cannot be compared
#: with bumps this, and runs of another form are then trained again, never guessed equal.
RUN_RECORD_SCHEMA = 1


def run_settings(system: str, kind: str, loss: str, seed: int, config: ReproduceSettings) -> dict:
    """What a run directory's ``reproduce_config.json`` records for this run — its training
    settings (the progress bar aside) and architecture — in JSON's own form (lists, not tuples),
    so it compares with a saved record as it is."""
    train = training_settings(system, config, seed, loss, kind).to_json()
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
    defaults = json.loads(json.dumps(TrainSettings().to_json()))
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


def _check_saved_settings(run_dir: Path, cfg_json: dict) -> None:
    """Refuse a run folder whose recorded settings (``reproduce_config.json``) are not these."""
    cfg_path, model_path = run_dir / "reproduce_config.json", run_dir / MODEL_FILE
    if not cfg_path.exists():
        return
    saved = json.loads(cfg_path.read_text())
    if "model_hparams" not in saved and model_path.exists():
        # a record from before the architecture was recorded: the checkpoint's header knows it
        saved["model_hparams"] = json.loads(json.dumps(read_header(model_path).get("hparams", {}), default=str))
    if not same_settings(saved, cfg_json):
        raise ValueError(f"{run_dir}: holds a run with other settings ({cfg_path}); choose another --out")


def _failed_metrics(system: str, config: ReproduceSettings, error: str) -> dict[str, Any]:
    """A failed model's metrics: recorded, never hidden, every cell of it reads "fail" in the tables."""
    metrics: dict[str, Any] = {
        label: {m: FAILED for m in METRIC_COLUMNS[system]} for label in EVALUATION_SETS[config.split][system]
    }
    metrics["_error"] = error
    return metrics


def _run_one(system, kind, loss, seed, data, run_dir: Path, config: ReproduceSettings, truth):
    """Train (or resume / reuse) one model and evaluate it; returns its metrics dict."""
    metrics_path = run_dir / "metrics.json"
    model_path = run_dir / MODEL_FILE
    tcfg = training_settings(system, config, seed, loss, kind)
    cfg_json = run_settings(system, kind, loss, seed, config)
    cfg_path = run_dir / "reproduce_config.json"
    _check_saved_settings(run_dir, cfg_json)
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
            metrics = _failed_metrics(system, config, error)
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


def _run_task(system, kind, loss, seed, out, config, data=None, truth=None):
    """One model of the run (also the body of a worker process): ``(metrics, seconds, status)``."""
    if data is None:  # in a worker process
        data, truth = _worker_inputs(system, out, config)
    run_dir = out / "runs" / system / f"{kind}_{loss}" / f"seed{seed}"
    t0 = time.perf_counter()
    metrics, _, status = _run_one(system, kind, loss, seed, data, run_dir, config, truth)
    return metrics, round(time.perf_counter() - t0, 1), status
