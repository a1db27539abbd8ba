"""Test-wide setup: float64 switched on explicitly (as the README tells users), headless GL, and
one JAX compilation cache per test session."""

import atexit
import os
import shutil
import tempfile

os.environ.setdefault("MUJOCO_GL", "egl")
# the training commands turn on a persistent compilation cache in ~/.cache: tests stay hermetic
os.environ.setdefault("FURUTA_GYM_COMPILATION_CACHE", "0")
# ... but the session compiles the same steps in many tests, xdist workers and CLI subprocesses:
# one temporary cache, made by the first process (workers and subprocesses inherit it), removed
# when that process ends. The traced-step cache stays off, so tests take the users' default path.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ and os.environ.get("FURUTA_GYM_TEST_JAX_CACHE", "1") != "0":
    _session_cache = tempfile.mkdtemp(prefix="furuta_gym_tests_jax_")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _session_cache
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    os.environ.setdefault("FURUTA_GYM_STEP_CACHE", "0")
    atexit.register(shutil.rmtree, _session_cache, ignore_errors=True)

import furuta_gym  # noqa: E402  first: it pins NumPy's BLAS before JAX loads NumPy

# isort: split
import jax  # noqa: E402
import pytest  # noqa: E402

if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update(
        "jax_persistent_cache_min_compile_time_secs",
        float(os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "1.0")),
    )

furuta_gym.enable_x64()


@pytest.fixture
def no_persistent_cache():
    """For tests that count compilations: a hit in the session's cache skips the compile event."""
    before = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    yield
    jax.config.update("jax_enable_compilation_cache", before)
