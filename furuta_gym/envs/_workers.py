"""Worker processes for the batched env: each steps a contiguous slice of the copies.

Why processes: one XLA:CPU execution of a batched small-network step keeps one core busy and
spends the others spinning; threads in one process share XLA's intra-op pool and reach little
more. A worker whose XLA pool has one thread keeps one core busy, so K workers on K cores add up
(docs/batched.md "Speed" has the measurements). The price: start-up (a worker imports JAX and
compiles its step) and a socket round trip per step, so this pays for thousands of copies, not tens.

Workers are fresh interpreters (``python -m furuta_gym.envs._workers``) that connect back over a
local socket, not ``multiprocessing`` children: those re-import the user's main script, which then
needs an ``if __name__ == "__main__"`` guard (and JAX is not fork-safe). The model and task travel
pickled, so a model class must be importable by name. Data travel through two shared-memory
blocks (inputs: state and action; outputs: the packed step's columns, see
:func:`furuta_gym.envs._batched_step.unpack_outputs`); the connections carry only "step" / "task"
messages.
"""

from __future__ import annotations

import os
import pickle
import secrets
import subprocess
import sys
import threading
import traceback
import weakref
from multiprocessing import resource_tracker, shared_memory
from multiprocessing.connection import Client, Listener

import jax
import numpy as np

from .._x64 import enable_x64
from ._batched_step import packed_output_width, step_function, unpack_outputs
from ._jax_rollout import chunk_bounds

__all__ = ["ProcessChunks"]


_ADDRESS_VARIABLE = "FURUTA_GYM_VECTOR_WORKER_ADDRESS"
_KEY_VARIABLE = "FURUTA_GYM_VECTOR_WORKER_KEY"


def _connect_and_serve() -> None:
    """Entry point of a worker interpreter: connect to the env, receive its set-up, serve."""
    conn = Client(os.environ[_ADDRESS_VARIABLE], authkey=bytes.fromhex(os.environ[_KEY_VARIABLE]))
    _worker_main(conn, *conn.recv())


def _worker_main(conn, names, num_envs, n_state, n_input, lo, hi, core, payload, path) -> None:
    inputs = outputs = shm_in = shm_out = None
    try:
        # the env's import path first, so a model class importable there is importable here
        sys.path[:] = list(path) + [p for p in sys.path if p not in path]

        enable_x64()  # the env's own process already runs in float64 (and warned if it switched)
        _start_backend(core)
        settings = _rebuilt_settings(payload)
        shm_in, shm_out = (_attach(name) for name in names)
        inputs = np.ndarray((num_envs, n_state + n_input), dtype=np.float64, buffer=shm_in.buf)
        outputs = np.ndarray((num_envs, packed_output_width(n_state, n_input)), dtype=np.float64, buffer=shm_out.buf)
        step, args = step_function(**settings, packed=True)

        def run():
            outputs[lo:hi] = np.asarray(step(*args, inputs[lo:hi]))

        run()  # compile before reporting ready
        conn.send(("ready", None))
        while True:
            message = conn.recv()
            if message is None:
                break
            if message[0] == "task":
                settings["task"] = message[1]
                step, args = step_function(**settings, packed=True)
            else:
                run()
            conn.send(("ok", None))
    except (EOFError, KeyboardInterrupt):
        pass
    except BaseException as exc:
        try:  # the reason first, the traceback after it for whoever debugs
            conn.send(("error", f"{type(exc).__name__}: {exc}\n\n{traceback.format_exc()}"))
        except Exception:
            pass
    finally:
        inputs = outputs = None  # drop the views before their buffers close
        for block in (shm_in, shm_out):
            if block is not None:
                block.close()


def _start_backend(core: int | None) -> None:
    """Start JAX's backend on ``core`` alone, then run as a batch-class process."""
    if core is not None and hasattr(os, "sched_setaffinity"):
        # XLA:CPU sizes its thread pool from the cores this process may use when its backend
        # starts: one core gives one thread, none left spinning against the other workers.
        # Then the scheduler may place the worker anywhere again: kept pinned, a worker woken
        # on the env's own core waited for the env to yield it, and the workers ran in turn.
        allowed = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {core})
        jax.devices()
        os.sched_setaffinity(0, allowed)
    if hasattr(os, "SCHED_BATCH"):
        # a batch-class worker does not pre-empt the env's process when woken, so the env
        # sends every worker its step at once (without it, some steps waited a worker's turn)
        try:
            os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
        except OSError:
            pass


def _rebuilt_settings(payload: bytes) -> dict:
    """The env's step settings (model, task, ...), unpickled in this worker."""
    try:
        return pickle.loads(payload)
    except Exception as exc:
        raise RuntimeError(
            "the model or task could not be rebuilt in a worker process: its class must be "
            "importable by name (defined in a module on the import path, not in __main__, a "
            f"notebook or a function): {type(exc).__name__}: {exc}"
        ) from exc


def _attach(name: str) -> shared_memory.SharedMemory:
    """Attach to the env's block without handing it to this interpreter's resource tracker, which
    would otherwise unlink it (with a "leaked" warning) when the worker exits: the env owns it."""
    block = shared_memory.SharedMemory(name=name)
    try:
        # the tracker's key is CPython's private _name, which typeshed does not declare
        resource_tracker.unregister(getattr(block, "_name"), "shared_memory")  # noqa: B009
    except Exception:  # the tracker's layout is CPython's; without it only a warning is at stake
        pass
    return block


def _accept_workers(listener, processes, count: int) -> list:
    """Accept ``count`` connections, failing fast when a worker exits before it connects."""
    accepted: list = []

    def accept():
        try:
            for _ in range(count):
                accepted.append(listener.accept())
        except OSError:  # the listener was closed because a worker died
            pass

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    while thread.is_alive():
        thread.join(0.05)
        dead = [p for p in processes if p.poll() is not None]
        if dead and thread.is_alive():
            listener.close()
            thread.join()
            for conn in accepted:
                conn.close()
            raise RuntimeError(
                f"a batched env worker process exited with code {dead[0].returncode} before it "
                "started (its error is printed above)"
            )
    return accepted


def _shutdown(processes, connections, blocks) -> None:
    for conn in connections:
        try:
            conn.send(None)
        except Exception:
            pass
    for p in processes:
        # a worker tears down its interpreter and JAX on the way out: seconds on a loaded machine,
        # so it is killed only when it is plainly stuck
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    for conn in connections:
        conn.close()
    for block in blocks:
        block.close()
        try:
            block.unlink()
        except FileNotFoundError:
            pass


class ProcessChunks:
    """Step ``num_envs`` copies as ``workers`` processes, each owning a contiguous slice.

    ``settings`` are the keyword arguments of :func:`furuta_gym.envs._batched_step.step_function`
    (model, energy model, task, integration settings); they are pickled to the workers, which
    build and compile the same jitted step (each worker's XLA thread pool is sized for one core,
    see ``_worker_main``). :meth:`close` (or garbage collection, or interpreter exit)
    stops the workers and frees the shared memory.
    """

    def __init__(self, num_envs: int, workers: int, n_state: int, n_input: int, settings: dict):
        self.num_envs, self.workers = int(num_envs), int(workers)
        self.n_state, self.n_input = int(n_state), int(n_input)
        width_in, width_out = n_state + n_input, packed_output_width(n_state, n_input)
        try:
            payload = pickle.dumps(settings)
        except Exception as exc:
            raise ValueError(
                f"workers={workers}: the model or task cannot be sent to worker processes (it must "
                f"pickle; a class defined inside a function does not): {type(exc).__name__}: {exc}"
            ) from exc
        blocks = [
            shared_memory.SharedMemory(create=True, size=8 * num_envs * width_in),
            shared_memory.SharedMemory(create=True, size=8 * num_envs * width_out),
        ]
        self._inputs = np.ndarray((num_envs, width_in), dtype=np.float64, buffer=blocks[0].buf)
        self._outputs = np.ndarray((num_envs, width_out), dtype=np.float64, buffer=blocks[1].buf)
        self._inputs[:] = 0.0
        bounds = chunk_bounds(num_envs, workers)
        cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
        key = secrets.token_bytes(32)
        self._connections, self._processes = [], []
        with Listener(family="AF_UNIX", authkey=key) as listener:
            environment = {**os.environ, _ADDRESS_VARIABLE: listener.address, _KEY_VARIABLE: key.hex()}
            for _ in range(workers):
                self._processes.append(
                    subprocess.Popen([sys.executable, "-m", __name__], env=environment, stdin=subprocess.DEVNULL)
                )
            try:
                connections = _accept_workers(listener, self._processes, workers)
            except BaseException:
                _shutdown(self._processes, [], blocks)
                raise
            for i, conn in enumerate(connections):  # slices go out in the order workers connect
                core = cores[i % len(cores)] if cores else None
                conn.send(
                    (
                        [b.name for b in blocks],
                        num_envs,
                        n_state,
                        n_input,
                        int(bounds[i]),
                        int(bounds[i + 1]),
                        core,
                        payload,
                        list(sys.path),
                    )
                )
                self._connections.append(conn)
        # the finalizer holds no reference to self: it runs at close(), collection or exit
        self._finalizer = weakref.finalize(self, _shutdown, self._processes, self._connections, blocks)
        self._collect("start")

    def _collect(self, what: str) -> None:
        errors = []
        for i, conn in enumerate(self._connections):
            try:
                status, detail = conn.recv()
            except EOFError:
                status, detail = "error", "the worker process exited"
            if status == "error":
                errors.append(f"worker {i}: {detail}")
        if errors:
            self.close()
            raise RuntimeError(f"batched env worker process(es) failed at {what}:\n" + "\n".join(errors))

    def step(self, xs: np.ndarray, us: np.ndarray) -> tuple[np.ndarray, ...]:
        """The jitted step's outputs for every copy (x_next, obs, u, reward, terminated,
        diverged, energy), as NumPy arrays owned by the caller."""
        if not self._finalizer.alive:
            raise RuntimeError("the batched env's worker processes are closed")
        self._inputs[:, : self.n_state] = xs
        self._inputs[:, self.n_state :] = us
        try:
            for conn in self._connections:
                conn.send(("step",))
            self._collect("step")
        except BaseException:  # e.g. Ctrl-C between send and reply: the workers are out of step
            self.close()
            raise
        return unpack_outputs(self._outputs, self.n_state, self.n_input)

    def set_task(self, task) -> None:
        for conn in self._connections:
            conn.send(("task", task))
        self._collect("task change")

    def close(self) -> None:
        self._finalizer()


if __name__ == "__main__":
    _connect_and_serve()
