"""Where a reproduction run's models train: in this process, a local pool of processes or Ray
tasks on a cluster (:mod:`._ray_sweep`), behind one interface; each system's figures made as
soon as its last model is done. Part of :mod:`.reproduce`."""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import dataclasses
import multiprocessing as mp
import time
from pathlib import Path
from typing import Any, Iterator

from . import _ray_sweep, _reproduce_figures
from ._labels import LOSS_LABELS, MODEL_LABELS
from ._reproduce_data import _worker_inputs
from ._reproduce_one_model import _run_task
from ._reproduce_settings import ReproduceSettings

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


def _longest_first(tasks, config: ReproduceSettings) -> list:
    """``tasks`` in the order a pool should start them: longest expected first (ties: as given)."""
    table = EXPECTED_SECONDS["quick" if config.quick else "full"]
    return sorted(tasks, key=lambda t: -table.get(t[:3], 0))


def _figures_task(system: str, out: Path, config: ReproduceSettings, data=None, truth=None):
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


def _run_all(tasks, out: Path, config: ReproduceSettings, loaded: dict, log) -> Iterator[tuple[str, Any, Any]]:
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


def _run_in_process(tasks, out: Path, config: ReproduceSettings, loaded: dict, report):
    """:func:`_run_all` one model after the other in this process, on the data it has loaded."""
    for task in tasks:
        system, kind, loss, seed = task
        result = _run_task(system, kind, loss, seed, out, config, loaded[system]["data"], loaded[system]["truth"])
        report(task, result)
        yield "model", task, result
    if config.figures:
        for system in dict.fromkeys(t[0] for t in tasks):
            yield "figures", system, _figures_task(system, out, config, loaded[system]["data"], loaded[system]["truth"])


def require_executor(config: ReproduceSettings) -> None:
    """Raise the ImportError :func:`worker_pool` would, before any work: ``executor="ray"`` without
    Ray installed (one line naming the ``[cluster]`` extra)."""
    if config.executor == "ray":
        _ray_sweep._import_ray()


@contextlib.contextmanager
def worker_pool(config: ReproduceSettings) -> Iterator[Any]:
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


def _drain(executor, tasks, out: Path, config: ReproduceSettings, report):
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
