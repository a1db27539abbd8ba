"""The persistent JAX compilation cache the training commands turn on.

A training step with the trajectory loss takes long to compile; a persistent cache pays that
once per machine instead of once per run (and, with it, :mod:`furuta_gym.training._step_cache`
stores the traced steps too, so a warm first call skips tracing as well). The library itself never writes
caches; the ``train`` and ``reproduce`` commands do, in ``jax/`` under the cache root of
:func:`furuta_gym._paths.cache_root` (``~/.cache/furuta_gym`` unless ``FURUTA_GYM_CACHE`` or
``XDG_CACHE_HOME`` move it) — or wherever ``JAX_COMPILATION_CACHE_DIR`` points. Set
``FURUTA_GYM_COMPILATION_CACHE=0`` to turn it off.
"""

from __future__ import annotations

import os
from pathlib import Path

from .._paths import cache_root


def enable_compilation_cache() -> Path | None:
    """Turn JAX's persistent compilation cache on for this process and its children; returns
    the folder (``None`` when turned off or unavailable)."""
    if os.environ.get("FURUTA_GYM_COMPILATION_CACHE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    import jax

    cache = Path(os.environ.get("JAX_COMPILATION_CACHE_DIR") or cache_root() / "jax").expanduser()
    try:
        cache.mkdir(parents=True, exist_ok=True)
        # the environment too: worker processes (reproduce --jobs) start a fresh JAX that reads it
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(cache)
        os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1.0")
        jax.config.update("jax_compilation_cache_dir", str(cache))
        jax.config.update(
            "jax_persistent_cache_min_compile_time_secs",
            float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
        )
    except (OSError, AttributeError, ValueError):
        return None
    return cache
