"""Where furuta-gym keeps its caches on disk: one root for all of them.

``$FURUTA_GYM_CACHE`` if set, else ``$XDG_CACHE_HOME``, else ``~/.cache``; then ``furuta_gym/``.
Below it: ``c_kernels/`` (compiled C steps, :mod:`furuta_gym._ckernel`) and ``jax/`` (JAX's
persistent compilation cache, which the ``train`` and ``reproduce`` commands turn on;
``$JAX_COMPILATION_CACHE_DIR`` moves that one alone). Pointing ``XDG_CACHE_HOME`` at an empty
folder therefore gives a cold start for everything.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """The folder under which every furuta-gym cache lives (not created here)."""
    base = os.environ.get("FURUTA_GYM_CACHE") or os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "furuta_gym"
