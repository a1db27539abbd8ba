"""An opt-in for programs that step one model-backed env from Python.

A DeLaN-backed ``env.step`` is one small jitted JAX call (docs/batched.md, "Speed"). By default JAX hands every CPU computation to a worker thread and returns at once
(asynchronous dispatch), which pays off for large computations but costs a thread hand-off per
call here. :func:`inline_cpu_dispatch` makes JAX run CPU computations inline on the calling
thread (JAX's ``jax_cpu_enable_async_dispatch=False``). It is process-wide and must be chosen
before JAX creates its CPU backend, so furuta-gym never does it for you; bench/env_speed.py
measures what it buys (BENCHMARKS.md, "Single-env speed").
"""

from __future__ import annotations

import jax

__all__ = ["inline_cpu_dispatch"]


def inline_cpu_dispatch() -> None:
    """Run JAX CPU computations inline instead of dispatching them asynchronously.

    Call it at the start of a program, before any JAX computation (JAX reads the setting once,
    when it creates its CPU backend); afterwards it raises :class:`RuntimeError` rather than
    silently doing nothing. Affects every JAX computation of the process.
    """
    if not jax.config.read("jax_cpu_enable_async_dispatch"):
        return
    try:  # JAX has no public way to ask whether its backends exist yet
        from jax._src import xla_bridge  # noqa: PLC0415  JAX internals that may move: inside the try

        initialized = xla_bridge.backends_are_initialized()
    except (ImportError, AttributeError):  # moved in another JAX version: cannot tell, set it
        initialized = False
    if initialized:
        raise RuntimeError(
            "inline_cpu_dispatch() must be called before the first JAX computation: JAX has "
            "already created its CPU backend with asynchronous dispatch"
        )
    jax.config.update("jax_cpu_enable_async_dispatch", False)
