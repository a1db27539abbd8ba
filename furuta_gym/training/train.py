"""Training learned Lagrangian models with the paper's curriculum (Laiche et al. 2026, appendix A.2).

:func:`train` runs stages of epochs over trajectory windows — 2-step predictions first, then the
long horizon (1 s Furuta, 2 s N-MSD) — with optax Adam + weight decay (``adamw``), minibatches of
trajectory windows, a tqdm bar showing the loss terms, a resumable training state written
atomically after every finished epoch (so a kill loses no finished epoch; the epochs of an
L_Iτ-alone stage run in compiled blocks of about :data:`BLOCK_SECONDS`, and the state is
written after each block), model snapshots every
``checkpoint_every`` epochs and a NaN guard (a step whose loss or gradient is not finite is
skipped and counted; a NaN model is never saved).

Losses (``loss=``): ``"traj"`` L_traj; ``"aph"`` ‖F_a‖² + λ·L_traj with APHYNITY's dual ascent on λ;
``"prop"`` L_Iτ + λ·L_traj (the paper's proposed loss); ``"itau"`` L_Iτ alone (cheap: no ODE
solve; the training-stage horizon is then irrelevant). L_Iτ is computed on all integral windows
at every step (it is cheap), L_traj on a minibatch of windows.

**Overall scale.** On free (u = 0) data the dynamics, and hence every loss, are invariant to
multiplying the learned Lagrangian and τ_NC by one constant: the scale is unidentifiable. Pass
one forced trajectory (``forced_trajs``) and the scale is fitted after training by least squares
(:func:`fit_scale`; the integral residual Z̄ − s·Ā is linear in s), as the paper does.

The parts: :mod:`._train_settings` (:class:`TrainSettings`), :mod:`._train_step` (the optimiser
step of a loss, compiled) and :mod:`._scale_fit` (:func:`fit_scale`); here are the stages, the
epochs and blocks, and the run directory a run writes and resumes from.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import signal
import time
import warnings
from pathlib import Path
from typing import Any, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from .._deprecated import deprecated_names
from .._x64 import ensure_x64
from ..data import Trajectory
from ..models import make_model
from ..systems import get_spec
from . import checkpoint as ckpt
from ._itau_block import CAPACITY as BLOCK_CAPACITY, ItauBlock
from ._scale_fit import ScaleFit, ScaleFitWarning, fit_scale
from ._train_settings import AUGMENTATION_WEIGHT, TrainSettings
from ._train_step import _all_finite, _build_optimizer, _make_step, _step_function, training_step
from .consistency import check_potential_shape, warn_data_coverage, warn_potential_shape
from .free_dynamics import has_free_motion, warn_free_dynamics
from .loss_kinds import INTEGRAL_ONLY, LOSS_KINDS, TRAJECTORY_TERM, loss_kind
from .losses import Windows, make_windows, resolve_normalization

__all__ = [
    "TrainSettings",
    "train",
    "training_step",
    "fit_scale",
    "data_hash",
    "LOSSES",
    "ScaleFit",
    "ScaleFitWarning",
    "AUGMENTATION_WEIGHT",
]

#: the built-in losses' names (:data:`.loss_kinds.LOSS_KINDS`: what each is made of)
LOSSES = tuple(LOSS_KINDS)
#: wall time aimed at per block of L_Iτ-alone epochs (between two writes of the training state)
BLOCK_SECONDS = 2.0
STATE_FILE = "train_state.eqx"
HISTORY_FILE = "history.jsonl"
MODEL_FILE = "model.eqx"
#: the physical check of the trained model's free motion (:mod:`.free_dynamics`), beside the model
FREE_DYNAMICS_FILE = "free_dynamics.json"


#: TrainSettings fields a resumed run may change: how long it runs and what it prints or saves.
#: Anything else (a step size, λ, μ, the quadrature, ...) would continue one run under another's
#: name.
RESUMABLE_CHANGES = frozenset({"epochs", "progress", "checkpoint_every"})


def _check_resumable_config(state_path, saved: dict | None, current: dict) -> None:
    """Refuse to resume a run whose saved training settings differ from ``current`` in a field
    outside :data:`RESUMABLE_CHANGES` (one error naming every such field). A field the saved
    state lacks was added later and is not compared."""
    if saved is None:
        return
    current = json.loads(json.dumps(current))  # tuples as the saved JSON holds them: lists
    differ = sorted(k for k in current.keys() & saved.keys() if k not in RESUMABLE_CHANGES and saved[k] != current[k])
    if differ:
        detail = "; ".join(f"{k}: saved {saved[k]!r}, now {current[k]!r}" for k in differ)
        raise ValueError(
            f"{state_path}: cannot resume with other training settings ({detail}); "
            "train into another output directory, or resume with the saved settings"
        )


def data_hash(trajs: Sequence[Trajectory]) -> str:
    """SHA-256 over the trajectories' arrays (t, q, u, q̇): identifies the training data."""
    h = hashlib.sha256()
    for tr in trajs:
        for a in (tr.t, tr.q, tr.u, tr.qd):
            if a is not None:
                h.update(np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes())
    return h.hexdigest()


def _horizon_samples(h, dt: float) -> int:
    if isinstance(h, bool):
        raise ValueError(f"horizon must be an int (samples) or float (seconds), got {h!r}")
    if isinstance(h, (int, np.integer)):
        steps = int(h)
    else:
        steps = int(round(float(h) / dt))
    if steps < 1:
        raise ValueError(f"horizon {h!r} is shorter than one sample (dt = {dt})")
    return steps


def _read_history(path: Path, epochs: int) -> list[dict]:
    """The first ``epochs`` records of a run's history.jsonl (later lines belong to an epoch whose
    state was never saved: the run was killed in between)."""
    if not path.exists():
        return []
    lines = [l for l in path.read_text().splitlines() if l.strip()]
    records = [json.loads(l) for l in lines]
    records = [r for r in records if r["epoch"] <= epochs]
    # keep the last record of each epoch (a killed run may have written an epoch twice)
    by_epoch = {r["epoch"]: r for r in records}
    history = [by_epoch[e] for e in sorted(by_epoch)]
    path.write_text("".join(json.dumps(r, default=float) + "\n" for r in history))
    return history


class _StopRequested(Exception):
    pass


class _Stages:
    """What each training stage uses: its loss (a stage without a horizon is L_Iτ alone: no ODE
    solve, an epoch costs milliseconds), its trajectory windows and its compiled step, each
    built once when first needed."""

    def __init__(self, config, loss, trajs, dt, shortest, int_windows, make_step, step_function):
        self.config, self.trajs, self.dt, self.shortest = config, trajs, dt, shortest
        self.int_windows, self._loss, self._make_step = int_windows, loss, make_step
        self._step_function = step_function
        self.bounds = np.cumsum(config.epochs)
        step = config.lambda_step
        self.lam_step = step if step is not None else loss_kind(loss).dual_ascent_step
        self._windows: dict[int, Windows] = {}
        self._steps: dict[str, Any] = {}
        self._block: ItauBlock | None = None
        self.block_epochs = 8  # the next block's length; set from the last block's time
        self.blocks_run = 0

    def of_epoch(self, epoch: int) -> int:
        return int(np.searchsorted(self.bounds, epoch, side="right"))

    def loss(self, stage: int) -> str:
        return INTEGRAL_ONLY.name if self.config.horizons[stage] is None else self._loss

    def windows(self, stage: int) -> Windows:
        if stage not in self._windows:
            h = min(_horizon_samples(self.config.horizons[stage], self.dt), self.shortest - 1)
            self._windows[stage] = make_windows(self.trajs, h + 1, stride=1)
        return self._windows[stage]

    def step(self, stage: int):
        name = self.loss(stage)
        if name not in self._steps:
            self._steps[name] = self._make_step(name)
        return self._steps[name]

    def in_blocks(self, stage: int) -> bool:
        """Whether the stage's epochs run as compiled blocks: L_Iτ alone on all windows per step."""
        ib = self.config.integral_batch_size
        alone = not loss_kind(self.loss(stage)).uses_trajectory
        return alone and (ib is None or ib >= self.int_windows.n_windows)

    def block(self) -> ItauBlock:
        if self._block is None:
            self._block = ItauBlock(
                self._step_function(INTEGRAL_ONLY.name), self.int_windows, self.config.seed, self.config.keep_best_itau
            )
        return self._block

    def block_length(self, epoch: int, stage: int) -> int:
        """Epochs of the block starting at ``epoch``: up to the stage's end or the next snapshot."""
        end = int(self.bounds[stage])
        if self.config.checkpoint_every:
            end = min(end, (epoch // self.config.checkpoint_every + 1) * self.config.checkpoint_every)
        return max(1, min(end - epoch, self.block_epochs, BLOCK_CAPACITY))


def _run_epoch(stages: _Stages, run: _RunState, epoch: int) -> tuple[dict, dict]:
    """One epoch's steps; returns its history record and its mean loss terms."""
    config = stages.config
    t0 = time.perf_counter()
    stage = stages.of_epoch(epoch)
    solves = loss_kind(stages.loss(stage)).uses_trajectory
    traj_batches, int_batches = _epoch_batches(
        np.random.default_rng([config.seed, epoch]),
        stages.windows(stage) if solves else None,
        stages.int_windows,
        config,
    )
    means, skipped = _run_steps(stages.step(stage), run, traj_batches, int_batches, config.epoch_learning_rate(epoch))
    if stages.lam_step and TRAJECTORY_TERM in means:
        run.lam = run.lam + stages.lam_step * means[TRAJECTORY_TERM]
    record = {
        "epoch": epoch + 1,
        "stage": stage,
        "horizon": stages.windows(stage).length - 1 if solves else None,
        **means,
        "lambda": run.lam,
        "steps": len(traj_batches),
        "skipped": skipped,
        "seconds": time.perf_counter() - t0,
    }
    return record, means


def _run_block(stages: _Stages, run: _RunState, epoch: int) -> list[tuple[dict, dict]]:
    """A block of full-batch L_Iτ-alone epochs in one compiled loop (:mod:`._itau_block`);
    returns each epoch's history record and loss terms, as :func:`_run_epoch` does."""
    config, stage, block = stages.config, stages.of_epoch(epoch), stages.block()
    n = stages.block_length(epoch, stage)
    best = run.best if run.best is not None and run.best["stage"] == stage else None
    t0 = time.perf_counter()
    result = block(
        run.params,
        run.opt_state,
        run.lam,
        epoch,
        [config.epoch_learning_rate(e) for e in range(epoch, epoch + n)],
        best=None if best is None else (best["total"], best["after"], best["params"]),
    )
    seconds = time.perf_counter() - t0
    run.params, run.opt_state = result.params, result.opt_state
    if config.keep_best_itau and result.best_after >= 0:
        # "after": how many epochs (counted over all stages) had run on these parameters
        run.best = {
            "stage": stage,
            "after": result.best_after,
            "total": result.best_total,
            "params": result.best_params,
        }
    if stages.blocks_run:  # the first block's time is mostly its compiling
        stages.block_epochs = int(np.clip(BLOCK_SECONDS / max(seconds / n, 1e-9), 1, BLOCK_CAPACITY))
    stages.blocks_run += 1
    done = []
    for i in range(n):
        ok = bool(result.ok[i])
        means = {k: float(v[i]) for k, v in result.terms.items()} if ok else {}
        record = {"epoch": epoch + i + 1, "stage": stage, "horizon": None, **means, "lambda": run.lam}
        record |= {"steps": 1, "skipped": int(not ok), "seconds": seconds / n}
        done.append((record, means))
    if config.keep_best_itau and epoch + n == stages.bounds[stage]:
        done[-1][0].update(_hand_over_best(run, stage, block, epoch + n - 1))
    return done


def train(
    model_kind: str,
    system: str,
    loss: str,
    train_trajs: Sequence[Trajectory],
    config: TrainSettings | None = None,
    out_dir: str | Path | None = None,
    resume: bool = False,
    *,
    forced_trajs: Sequence[Trajectory] | None = None,
    hparams: dict[str, Any] | None = None,
    model=None,
) -> tuple[Any, list[dict]]:
    """Train a learned model; returns ``(model, history)``.

    ``model_kind`` "dln" | "aph" | "adln"; ``system`` "furuta" | "nmsd"; ``loss`` "traj" | "aph" |
    "prop" | "itau"; ``train_trajs`` :class:`~furuta_gym.data.Trajectory` list with velocities;
    ``config`` a :class:`TrainSettings` (default :meth:`TrainSettings.for_system`). ``hparams``
    override the model's defaults (``make_model``); ``model`` starts from a given model instead.

    With ``out_dir``: writes ``train_state.eqx`` (resumable, after every epoch or block of epochs),
    ``model_epoch<N>.eqx`` every ``checkpoint_every`` epochs, ``model.eqx`` (final, loadable with
    :func:`furuta_gym.training.checkpoint.load_model`), ``history.jsonl`` (one line per epoch) and ``history.json``. An ``out_dir`` that
    already holds a run is refused unless ``resume=True``, which continues it (same model,
    optimiser state, λ, epoch counter; the data and the training settings must match, except
    the epochs, the progress bar and the snapshot cadence: :data:`RESUMABLE_CHANGES`). ``forced_trajs``: fit the
    overall scale on them after training (see the module docstring). ``history`` has one dict per
    epoch: epoch, stage, horizon, mean loss terms, λ, skipped steps, seconds.
    """
    ensure_x64()
    spec = get_spec(system)
    config = config or TrainSettings.for_system(spec.name)
    trajs = list(train_trajs)
    model = _prepared_model(spec, model_kind, loss, trajs, config, hparams, model)
    augmentation_weight = _augmentation_weight(config, spec, model, model_kind)
    dt = float(np.median([tr.dt for tr in trajs]))
    shortest = min(len(tr) for tr in trajs)
    dhash = data_hash(trajs)
    int_windows, normalization = _integral_windows(trajs, config, loss, shortest)
    optimizer, trainable, params = _build_optimizer(model, config)
    _, static = eqx.partition(model, trainable)
    run = _RunState(params=params, opt_state=optimizer.init(params), lam=float(config.lambda_traj))
    out = Path(out_dir) if out_dir is not None else None
    run_info = {
        "model_kind": model_kind,
        "system": spec.name,
        "loss": loss,
        "data_hash": dhash,
        "config": config.to_json(),
    }
    if out is not None:
        static = _open_run_dir(out, resume, model, trainable, run, run_info, static)
    stages = _Stages(
        config,
        loss,
        trajs,
        dt,
        shortest,
        int_windows,
        lambda name: _make_step(static, optimizer, name, config, normalization, augmentation_weight),
        lambda name: _step_function(static, optimizer, name, config, normalization, augmentation_weight),
    )
    _run_epochs(stages, run, out, static, run_info, loss, f"{model_kind}/{loss}")
    return _finish(eqx.combine(run.params, static), run.history, config, loss, dhash, trajs, forced_trajs, out)


def _run_epochs(stages: "_Stages", run: "_RunState", out: Path | None, static, run_info: dict, loss: str, label: str):
    """Run ``stages`` from ``run.start_epoch`` to the last epoch, saving and showing each epoch
    (or block of epochs); a polite stop (SIGINT/SIGTERM) ends it after the epoch it is in."""
    config = stages.config
    with _polite_stop(out, run) as stop, _progress_bar(config, run.start_epoch, label) as bar:
        epoch = run.start_epoch
        while epoch < config.total_epochs:
            in_blocks = stages.in_blocks(stages.of_epoch(epoch))
            done = _run_block(stages, run, epoch) if in_blocks else [_run_epoch(stages, run, epoch)]
            run.history.extend(record for record, _ in done)
            _save_epochs(out, [record for record, _ in done], run, static, run_info, config, loss)
            for record, means in done:
                _show_epoch(bar, means, loss, run.lam, record["skipped"], record["epoch"] - 1, record["steps"])
            epoch += len(done)
            if stop["flag"]:
                raise _StopRequested


@dataclasses.dataclass
class _RunState:
    """What a training run changes from epoch to epoch (and a resumed run restores)."""

    params: Any
    opt_state: Any
    lam: float
    start_epoch: int = 0
    history: list = dataclasses.field(default_factory=list)
    # the lowest-loss iterate of the running full-batch L_Iτ stage (keep_best_itau):
    # {"stage", "after" (epochs run before it, counted over all stages), "total", "params"}
    best: dict | None = None


def _prepared_model(spec, model_kind: str, loss: str, trajs, config: TrainSettings, hparams, model):
    """The model to train (a new one unless given), after checking it fits the data and the loss."""
    if loss not in LOSS_KINDS:
        raise ValueError(f"loss must be one of {tuple(LOSS_KINDS)}, got {loss!r}")
    kind = loss_kind(loss)
    if not trajs:
        raise ValueError("train_trajs is empty")
    for tr in trajs:
        if np.asarray(tr.q).ndim != 2 or np.asarray(tr.q).shape[1] != spec.n_dof:
            raise ValueError(
                f"trajectory {tr.name!r} has q of shape {np.asarray(tr.q).shape}; a {spec.name} "
                f"trajectory has {spec.n_dof} joint(s)"
            )
    if model is None:
        model = make_model(spec.name, model_kind, jax.random.PRNGKey(config.seed), **(hparams or {}))
    elif model.kind != model_kind or model.spec.name != spec.name:
        raise ValueError(f"model is a {model.spec.name} {model.kind}; asked for {spec.name} {model_kind}")
    if any(h is None for h in config.horizons) and not kind.uses_integral:
        with_integral = tuple(k.name for k in LOSS_KINDS.values() if k.uses_integral)
        raise ValueError(
            f"horizons {config.horizons}: a stage without a horizon (None) trains on L_Iτ alone, "
            f"which only the {' and '.join(map(repr, with_integral))} losses contain, not {loss!r}"
        )
    if kind.penalises_augmentation and not model.has_augmentation:
        raise ValueError(f"loss {loss!r} needs a model with a data-driven force F_a (aph or adln), not {model_kind!r}")
    return model


def _augmentation_weight(config: TrainSettings, spec, model, model_kind: str) -> float:
    """μ of the minimum-norm term: the config's, or the recipe's for models with F_a."""
    if config.augmentation_weight is None:
        return AUGMENTATION_WEIGHT.get((spec.name, model.kind), 0.0) if model.has_augmentation else 0.0
    if config.augmentation_weight and not model.has_augmentation:
        raise ValueError(
            f"augmentation_weight={config.augmentation_weight!r} weighs a data-driven force F_a, which a "
            f"{model_kind!r} model does not have (only aph and adln do); leave it None or 0"
        )
    return float(config.augmentation_weight)


def _integral_windows(trajs, config: TrainSettings, loss: str, shortest: int):
    """L_Iτ's windows (made once; None without L_Iτ) and the resolved normalisation."""
    if not loss_kind(loss).uses_integral:
        return None, config.normalize
    w = min(config.integral_window, shortest)
    if config.quadrature == "simpson" and w % 2 == 0:
        w -= 1  # Simpson pairs intervals: an odd number of samples uses them all
    int_windows = make_windows(trajs, w, stride=w - 1, cover_end=True)
    normalization = resolve_normalization(int_windows) if config.normalize == "auto" else config.normalize
    return int_windows, normalization


def _open_run_dir(out: Path, resume: bool, model, trainable, run: _RunState, run_info: dict, static):
    """Refuse a directory holding a run unless resuming; on resume, restore ``run`` from its
    training state (same model, data and settings). Returns the model's static part."""
    state_path = out / STATE_FILE
    if state_path.exists() and not resume:
        raise FileExistsError(
            f"{out}: holds a training run already ({STATE_FILE}); resume it (resume=True / "
            "--resume) or choose another output directory"
        )
    if resume and state_path.exists():
        m0, run.opt_state, header, best_model = ckpt.load_training_state(
            state_path, model, run.opt_state, with_best=True
        )
        st = header["state"]
        for key in ("model_kind", "system", "loss", "data_hash"):
            if st["run"][key] != run_info[key]:
                raise ValueError(
                    f"{state_path}: cannot resume: the saved run has {key}={st['run'][key]!r}, "
                    f"this one {run_info[key]!r}"
                )
        _check_resumable_config(state_path, st["run"].get("config"), run_info["config"])
        run.params, static = eqx.partition(m0, trainable)
        run.start_epoch = int(st["epoch"])
        run.lam = float(st["lambda"])
        if best_model is not None:
            run.best = {**st["best_itau"], "params": eqx.partition(best_model, trainable)[0]}
        run.history = _read_history(out / HISTORY_FILE, run.start_epoch)
    out.mkdir(parents=True, exist_ok=True)
    return static


def _epoch_batches(rng, traj_windows: Windows | None, int_windows: Windows | None, config: TrainSettings):
    """One epoch's minibatches: trajectory windows (None in an L_Iτ-alone stage) in a random
    order, each paired with L_Iτ windows (all of them, or random batches; None without L_Iτ)."""
    traj_batches: list[Windows | None] = [None]
    if traj_windows is not None:
        nw = traj_windows.n_windows
        bs = nw if config.batch_size is None else min(config.batch_size, nw)
        perm = rng.permutation(nw)
        traj_batches = [traj_windows.take(perm[k * bs : (k + 1) * bs]) for k in range(nw // bs)]
    int_batches: list[Windows | None] = [None] * len(traj_batches)
    if int_windows is not None:
        ni = int_windows.n_windows
        ib = ni if config.integral_batch_size is None else min(config.integral_batch_size, ni)
        if ib == ni and traj_windows is not None:
            int_batches = [int_windows] * len(traj_batches)
        else:
            n_steps = len(traj_batches) if traj_windows is not None else max(1, ni // ib)
            perm = np.concatenate([rng.permutation(ni) for _ in range(math.ceil(n_steps * ib / ni) + 1)])
            int_batches = [int_windows.take(perm[k * ib : (k + 1) * ib]) for k in range(n_steps)]
            if traj_windows is None:
                traj_batches = [None] * n_steps
    return traj_batches, int_batches


def _run_steps(step, run: _RunState, traj_batches, int_batches, learning_rate: float):
    """The epoch's optimiser steps (a step with a non-finite loss or gradient is skipped);
    returns the mean loss terms of the steps taken and how many were skipped."""
    sums: dict[str, float] = {}
    skipped = 0
    for tb, ib_ in zip(traj_batches, int_batches, strict=True):
        run.params, run.opt_state, terms, ok = step(
            run.params, run.opt_state, tb, ib_, jnp.asarray(run.lam), jnp.asarray(learning_rate)
        )
        if bool(ok):
            for k, v in terms.items():
                sums[k] = sums.get(k, 0.0) + float(v)
        else:
            skipped += 1
    n_ok = len(traj_batches) - skipped
    return ({k: v / n_ok for k, v in sums.items()} if n_ok else {}), skipped


def _hand_over_best(run: _RunState, stage: int, block: ItauBlock, last_epoch: int) -> dict:
    """keep_best_itau at a full-batch L_Iτ stage's end: the stage hands on whichever iterate had
    the lowest loss; returns the history fields of that hand-over (or {})."""
    best = run.best
    if best is None or best["stage"] != stage:
        return {}
    # its last step's result is evaluated too: an epoch at rate 0 is just the loss (the block's
    # other outputs are dropped), on the last epoch's window order
    final = block(run.params, run.opt_state, run.lam, last_epoch, [0.0])
    if bool(final.ok[0]) and float(final.terms["total"][0]) < best["total"]:
        best = {"stage": stage, "after": last_epoch + 1, "total": float(final.terms["total"][0]), "params": run.params}
    run.params = best["params"]
    run.best = None  # handed on: later epochs' training states need not carry it
    return {"best_after_epoch": best["after"], "best_total": best["total"]}


def _save_epochs(
    out: Path | None, records: list[dict], run: _RunState, static, run_info: dict, config: TrainSettings, loss: str
) -> None:
    """The epochs' history lines, the resumable state after the last of them and (every
    ``checkpoint_every``; a block ends at one) a snapshot."""
    if out is None:
        return
    model_now = eqx.combine(run.params, static)
    record = records[-1]
    epoch = record["epoch"]
    snapshot = bool(config.checkpoint_every and epoch % config.checkpoint_every == 0)
    if snapshot:  # cheap (two second derivatives of V): the shape's course through training
        record["potential_shape"] = check_potential_shape(model_now)
    # the history is appended line by line (the state file stays small); written before the
    # state so a resumed run always finds every finished epoch's line
    with (out / HISTORY_FILE).open("a") as fh:
        fh.write("".join(json.dumps(r, default=float) + "\n" for r in records))
    meta = {"data_hash": run_info["data_hash"], "epoch": epoch, "loss": loss}
    extra = {"epoch": epoch, "lambda": run.lam, "run": run_info, "seed": config.seed, "meta": meta}
    best_model = None
    if run.best is not None:
        extra["best_itau"] = {k: v for k, v in run.best.items() if k != "params"}
        best_model = eqx.combine(run.best["params"], static)
    ckpt.save_training_state(out / STATE_FILE, model_now, run.opt_state, extra, best_model=best_model)
    if snapshot:
        ckpt.save_model(
            out / f"model_epoch{epoch:06d}.eqx",
            model_now,
            {**meta, "potential_shape": record["potential_shape"]},
            overwrite=True,
        )


def _show_epoch(bar, means: dict, loss: str, lam: float, skipped: int, epoch: int, steps: int) -> None:
    if bar is not None:
        post: dict[str, Any] = {k: f"{v:.3g}" for k, v in means.items() if k != "total"}
        if loss_kind(loss).weighs_trajectory_by_lambda:
            post["λ"] = f"{lam:.3g}"
        if skipped:
            post["skipped"] = skipped
        bar.set_postfix(post, refresh=False)
        bar.update(1)
    if skipped:
        warnings.warn(
            f"epoch {epoch + 1}: skipped {skipped} of {steps} step(s) with a non-finite loss or gradient (NaN guard)",
            RuntimeWarning,
            stacklevel=3,
        )


@contextlib.contextmanager
def _polite_stop(out: Path | None, run: _RunState):
    """A polite kill (Ctrl-C / SIGTERM) finishes the running epoch (or block) and saves; SIGKILL
    loses at most the unfinished one because the state is written after each."""
    stop = {"flag": False}
    old_handler = None
    if out is not None:
        try:
            old_handler = signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__("flag", True))
        except ValueError:  # not in the main thread
            old_handler = None
    try:
        yield stop
    except (KeyboardInterrupt, _StopRequested):
        raise KeyboardInterrupt(
            f"training stopped after epoch {len(run.history)}; resume with resume=True / --resume"
            + (f" from {out}" if out is not None else "")
        ) from None
    finally:
        if old_handler is not None:
            signal.signal(signal.SIGTERM, old_handler)


@contextlib.contextmanager
def _progress_bar(config: TrainSettings, start_epoch: int, desc: str):
    bar = None
    if config.progress and config.total_epochs > start_epoch:
        bar = tqdm(total=config.total_epochs, initial=start_epoch, desc=desc, unit="ep")
    try:
        yield bar
    finally:
        if bar is not None:
            bar.close()


def _finish(model, history: list, config: TrainSettings, loss: str, dhash: str, trajs, forced_trajs, out):
    """The trained model (with its overall scale fitted on ``forced_trajs``), saved with its
    history when there is an ``out`` directory; returns ``(model, history)``."""
    meta = {
        "data_hash": dhash,
        "epoch": len(history),
        "loss": loss,
        "config": config.to_json(),
        "final": history[-1] if history else None,
    }
    if forced_trajs:
        meta["forced_data_hash"] = data_hash(forced_trajs)
        try:
            model, fit = fit_scale(model, forced_trajs, rule=config.quadrature, span=config.integral_span)
            meta["scale_fit"] = fit.to_json()
        except ValueError as exc:  # the trained model is kept, unscaled, and the reason said
            meta["scale_fit"] = {"error": str(exc)}
            warnings.warn(f"{exc}; the model is saved without a scale fit", ScaleFitWarning, stacklevel=3)
    elif not any(np.any(np.asarray(tr.u) != 0) for tr in trajs):
        meta["scale_fit"] = None
        meta["scale_note"] = "trained on free data only: the overall scale of L and τ_NC is unidentified"
    # after the scale fit, which multiplies V too; one warning if the shape is not physical
    meta["potential_shape"] = warn_potential_shape(model, stacklevel=3)
    meta["data_coverage"] = warn_data_coverage(trajs, model.spec, stacklevel=3)
    if has_free_motion(trajs):
        meta["free_dynamics"] = warn_free_dynamics(model, trajs, stacklevel=3)
    if history:
        history[-1]["potential_shape"] = meta["potential_shape"]
    if out is not None:
        if bool(_all_finite(model)):
            ckpt.save_model(out / MODEL_FILE, model, meta, overwrite=True)
        (out / "history.json").write_text(json.dumps({"meta": meta, "history": history}, indent=1, default=float))
        if "free_dynamics" in meta:
            (out / FREE_DYNAMICS_FILE).write_text(json.dumps(meta["free_dynamics"], indent=1, default=float) + "\n")
    return model, history


__getattr__ = deprecated_names(__name__)
