"""The reproduction's models as Ray tasks (``furuta-gym reproduce --executor ray``).

Each model × seed is one Ray task asking for ``cpus_per_task`` CPUs, named after its run folder
(``nmsd/dln_prop/seed0``: the Ray dashboard and the worker's process title say which model it
trains). A task is the very function a local worker process runs, so finding and reusing a
finished run, refusing one trained with other settings and resuming an unfinished one are the
same as with the local pool: its run folder's recorded settings and training state decide.

A worker lost mid-run (killed, out of memory, its node gone) is retried up to
:data:`MAX_RETRIES` times by Ray; training writes its state after every epoch (or block of
L_Iτ-alone epochs), so the retry resumes from the last one saved instead of starting over. An exception raised by the
model's own code is not retried: it would fail the same way again.

On a cluster of several machines, ``out`` must be a folder every node sees at the same path
(a shared file system): the tasks read the datasets and write the run folders there.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

__all__ = ["MAX_RETRIES", "RayExecutor", "absolute", "ray_executor", "worker_env"]

#: Times Ray starts a task again after its worker died (a system failure, not an exception).
MAX_RETRIES = 3
# Only small values travel through Ray (arguments, metrics dicts): the datasets are read from
# ``out`` by each task. A local instance needs no object store sized for arrays.
_LOCAL_OBJECT_STORE_BYTES = 128 * 2**20
# Forwarded to the workers when set here: where the compilation caches live and whether they
# are on, headless rendering for the figures.
_FORWARDED_ENV = (
    "JAX_COMPILATION_CACHE_DIR",
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
    "FURUTA_GYM_CACHE",
    "FURUTA_GYM_COMPILATION_CACHE",
    "FURUTA_GYM_STEP_CACHE",
    "MUJOCO_GL",
)
_THREAD_FLAG = "--xla_cpu_multi_thread_eigen"
# not an XLA flag (a TensorFlow option in a widespread recipe): XLA stops reading XLA_FLAGS at it
_NOT_A_FLAG = "intra_op_parallelism_threads"


def _import_ray():
    try:
        import ray  # noqa: PLC0415  the optional [cluster] extra
    except ImportError as exc:
        raise ImportError("--executor ray needs Ray: pip install 'furuta-gym[cluster]'") from exc
    return ray


def worker_env(cpus: int, environ=None) -> dict[str, str]:
    """Environment variables of a task asking for ``cpus`` CPUs.

    Several tasks share a node: a one-CPU task runs XLA's Eigen kernels on one thread and every
    task's OpenMP / BLAS pools get its CPUs, instead of every core of the node each, and on an
    accelerator no task reserves most of its memory at start-up. The node's own XLA flags are
    kept, after the thread setting (XLA stops reading at the first word that is not a ``--``
    flag), except ``intra_op_parallelism_threads``: not an XLA flag, and it would hide the flags
    after it, the numerics pin among them."""
    environ = os.environ if environ is None else environ
    kept = [f for f in environ.get("XLA_FLAGS", "").split() if not f.startswith((_THREAD_FLAG, _NOT_A_FLAG))]
    multi = "true" if cpus > 1 else "false"
    flags = [f"{_THREAD_FLAG}={multi}", *kept]
    env = {
        "XLA_FLAGS": " ".join(flags),
        "XLA_PYTHON_CLIENT_PREALLOCATE": "false",
        **{name: str(cpus) for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")},
    }
    env.update({name: environ[name] for name in _FORWARDED_ENV if name in environ})
    return env


class RayExecutor:
    """Submits functions as Ray tasks and collects them: the interface of the reproduction's
    local process pool (``submit`` → handle, ``first_done`` → finished handles, ``result``,
    ``folder``: a run folder as the workers see it)."""

    def __init__(self, ray, cpus_per_task: int):
        self._ray = ray
        self._options = dict(
            num_cpus=cpus_per_task,
            max_retries=MAX_RETRIES,
            retry_exceptions=False,
            runtime_env={"env_vars": worker_env(cpus_per_task)},
        )
        self._remote = {}

    def submit(self, fn, args, name: str):
        if fn not in self._remote:
            self._remote[fn] = self._ray.remote(fn)
        return self._remote[fn].options(name=name, **self._options).remote(*args)

    def first_done(self, handles) -> list:
        done, _ = self._ray.wait(list(handles), num_returns=1)
        return done

    def result(self, handle):
        return self._ray.get(handle)

    def folder(self, out: Path) -> Path:
        return absolute(out)


@contextlib.contextmanager
def ray_executor(address: str | None, jobs: int, cpus_per_task: int):
    """A :class:`RayExecutor` on the Ray instance this process is connected to, else on the one
    at ``address``, else on a new local one running ``jobs`` tasks at once (closed on exit)."""
    ray = _import_ray()
    started = False
    if not ray.is_initialized():
        if address is None:
            ray.init(
                num_cpus=jobs * cpus_per_task, include_dashboard=False, object_store_memory=_LOCAL_OBJECT_STORE_BYTES
            )
        else:
            ray.init(address=address)
        started = True
    try:
        yield RayExecutor(ray, cpus_per_task)
    finally:
        if started:
            ray.shutdown()


def absolute(out: Path) -> Path:
    """``out`` as the workers must see it: their working folder is not the driver's."""
    return Path(out).resolve()
