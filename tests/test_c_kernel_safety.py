"""The C step kernel must never be trusted blindly: each kernel is checked against XLA when it
is built, a cached library is loaded only when it is privately ours, primitives whose C
semantics would differ from XLA's are matched or refused, and a machine without a usable
compiler (or Windows) falls back to XLA cleanly."""

import os
import stat
import subprocess
import sys
import textwrap

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym  # noqa: F401  (registers the envs, enables float64)
from furuta_gym._ckernel import (
    CKernel,
    CKernelError,
    CKernelWarning,
    c_compiler,
    cache as kernel_cache,
    primitive_params,
    translate,
)
from furuta_gym.envs import _model_backend

pytestmark = pytest.mark.skipif(c_compiler() is None, reason="no C compiler on PATH")

NMSD_ID = "furuta_gym/NMSD-v0"
V = np.random.default_rng(0).normal(size=4)
as_root = pytest.mark.skipif(
    not hasattr(os, "getuid") or os.getuid() != 0, reason="simulating another user's file needs os.chown as root"
)


@pytest.fixture
def cache(monkeypatch, tmp_path):
    """A fresh cache root (and temporary dir) per test: nothing compiled or checked before."""
    monkeypatch.setenv("FURUTA_GYM_CACHE", str(tmp_path / "cache"))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(kernel_cache.tempfile, "tempdir", str(tmp_path / "tmp"))
    monkeypatch.setattr(kernel_cache, "_VERIFIED", set())
    monkeypatch.setattr(_model_backend, "_C_KERNEL_CACHE", {})
    return tmp_path / "cache" / "furuta_gym" / "c_kernels"


def _script(path, body):
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(0o755)
    return path


# ----------------------------------------------------------------- 1. checked against XLA


def test_a_kernel_that_disagrees_with_xla_is_refused_with_a_warning(cache, monkeypatch):
    monkeypatch.setitem(translate._UNARY, "sin", "cos({0})")  # a translation bug
    with pytest.warns(CKernelWarning, match=r"disagrees with XLA on output 0.*sin"):
        with pytest.raises(CKernelError, match="disagrees with XLA"):
            CKernel(lambda v: jnp.sin(v) * 2.0, V)
    assert not list(cache.glob("*.verified"))  # a refused kernel is never marked good


def test_a_model_whose_kernel_disagrees_steps_with_xla(cache, monkeypatch):
    original = CKernel._translate

    def off_by_a_little(self, closed):  # the generated C perturbed before it is compiled
        source = original(self, closed)
        cut = source.rindex("}")
        return source[:cut] + "    ((double *)outs[0])[0] += 1e-6;\n" + source[cut:]

    monkeypatch.setattr(CKernel, "_translate", off_by_a_little)
    with pytest.warns(CKernelWarning, match="period step of .*disagrees with XLA"):
        backend = gym.make(NMSD_ID, dynamics="analytic").unwrapped.backend
    assert backend.kernel == "xla" and "disagrees with XLA" in backend.kernel_fallback
    with pytest.raises(ValueError, match="kernel='c'.*disagrees with XLA"):
        gym.make(NMSD_ID, dynamics="analytic", kernel="c")


def test_a_good_kernel_is_checked_once_and_marked(cache, monkeypatch):
    calls = []
    original = CKernel._verify
    monkeypatch.setattr(CKernel, "_verify", lambda self, *a: calls.append(1) or original(self, *a))
    first = CKernel(lambda v: jnp.tanh(v) + 1.0, V)
    assert first.library_path.with_suffix(".verified").exists()
    monkeypatch.setattr(kernel_cache, "_VERIFIED", set())  # a new process: the marker on disk suffices
    CKernel(lambda v: jnp.tanh(v) + 1.0, V)
    assert len(calls) == 1


# ------------------------------------------------------------------------ 2. the disk cache


def test_the_cache_directory_is_private(cache):
    kernel = CKernel(lambda v: v * 3.0, V)
    assert kernel.library_path.parent == cache
    assert stat.S_IMODE(os.stat(cache).st_mode) == 0o700
    assert not stat.S_IMODE(os.stat(kernel.library_path).st_mode) & 0o022


@as_root
def test_a_library_planted_by_another_user_is_refused(cache):
    kernel = CKernel(lambda v: v * 5.0, V)
    os.chown(kernel.library_path, 12345, 12345)
    with pytest.warns(CKernelWarning, match="refusing to load .*owned by uid 12345"):
        with pytest.raises(CKernelError, match="refusing to load"):
            CKernel(lambda v: v * 5.0, V)


def test_a_group_writable_library_is_refused(cache):
    kernel = CKernel(lambda v: v * 7.0, V)
    os.chmod(kernel.library_path, 0o664)
    with pytest.warns(CKernelWarning, match="group- or world-writable"):
        with pytest.raises(CKernelError, match="refusing to load"):
            CKernel(lambda v: v * 7.0, V)


def test_a_symlinked_library_is_refused(cache, tmp_path):
    kernel = CKernel(lambda v: v * 9.0, V)
    target = tmp_path / "elsewhere.so"
    os.replace(kernel.library_path, target)
    os.symlink(target, kernel.library_path)
    with pytest.warns(CKernelWarning, match="symbolic link"), pytest.raises(CKernelError):
        CKernel(lambda v: v * 9.0, V)


@as_root
def test_a_cache_directory_owned_by_another_user_is_not_used(cache, tmp_path):
    cache.mkdir(parents=True)
    os.chown(cache, 12345, 12345)
    with pytest.warns(CKernelWarning, match="not using the C kernel cache"):
        kernel = CKernel(lambda v: v * 11.0, V)
    fallback = tmp_path / "tmp" / f"furuta_gym_c_kernels_{os.getuid()}"
    assert kernel.library_path.parent == fallback  # the per-user temporary cache instead
    os.chown(fallback, 12345, 12345)  # planted there too: a private directory of this process
    with pytest.warns(CKernelWarning):
        again = CKernel(lambda v: v * 13.0, V)
    assert again.library_path.parent not in (cache, fallback)
    assert stat.S_IMODE(os.stat(again.library_path.parent).st_mode) == 0o700
    np.testing.assert_array_equal(again(V), V * 13.0)


def test_eviction_keeps_the_newest_kernels(tmp_path):
    for k in range(6):
        for suffix in (".so", ".verified"):
            path = tmp_path / f"kernel_{k}{suffix}"
            path.touch()
            os.utime(path, (1000 + k, 1000 + k))
    kernel_cache._evict(tmp_path, keep=3)
    assert sorted(p.name for p in tmp_path.glob("*.so")) == ["kernel_3.so", "kernel_4.so", "kernel_5.so"]
    assert sorted(p.name for p in tmp_path.glob("*.verified")) == [
        "kernel_3.verified",
        "kernel_4.verified",
        "kernel_5.verified",
    ]


_WORKER = textwrap.dedent("""
    import numpy as np, jax.numpy as jnp
    import furuta_gym
    from furuta_gym._ckernel import CKernel
    v = np.arange(4.0)
    np.testing.assert_allclose(CKernel(lambda x: jnp.cos(x) * 17.0, v)(v), np.cos(v) * 17.0)
""")


def test_concurrent_processes_compile_a_kernel_once(tmp_path):
    log = tmp_path / "cc.log"
    # a slow compiler: both workers are waiting for the kernel at the same time
    wrapper = _script(tmp_path / "slow-cc", f'echo "$@" >> {log}\nsleep 1\nexec cc "$@"\n')
    env = dict(os.environ, CC=str(wrapper), FURUTA_GYM_CACHE=str(tmp_path / "cache"))
    workers = [
        subprocess.Popen([sys.executable, "-c", _WORKER], env=env, stderr=subprocess.PIPE, text=True) for _ in range(2)
    ]
    for w in workers:
        assert w.wait(timeout=300) == 0, w.stderr.read()
    compiles = [line for line in log.read_text().splitlines() if "kernel.c" in line]
    assert len(compiles) == 1


# ------------------------------------------------------------------------ 3. the primitives


def _same_as_jax(fn, *args):
    kernel = CKernel(fn, *args)
    got = jax.tree_util.tree_leaves(kernel(*args))
    want = jax.tree_util.tree_leaves(jax.jit(fn)(*args))
    for g, w in zip(got, want, strict=True):
        w = np.asarray(w)
        assert g.dtype == w.dtype and g.shape == w.shape
        np.testing.assert_array_equal(g, w)
        if g.dtype.kind == "f":  # equal compares -0.0 == 0.0: the sign bits too
            np.testing.assert_array_equal(np.signbit(g), np.signbit(w))
    return got


def test_sign_of_signed_zero_is_the_zero_as_in_xla(cache):
    (got,) = _same_as_jax(lambda v: jnp.sign(v), np.array([-0.0, 0.0, -2.0, 3.0, np.nan]))
    assert np.signbit(got[0]) and not np.signbit(got[1])


@pytest.mark.parametrize("dtype", ["int64", "int32", "int8", "uint8", "uint32"])
def test_float_to_integer_saturates_and_nan_is_zero_as_in_xla(cache, dtype):
    values = np.array(
        [
            np.nan,
            np.inf,
            -np.inf,
            1e300,
            -1e300,
            2.0**63,
            -(2.0**63),
            2.0**31,
            -(2.0**31) - 0.5,
            255.9,
            256.0,
            -1.0,
            -0.5,
            3.7,
            -3.7,
        ]
    )
    with np.errstate(over="ignore"):  # 1e300 as float32 is inf: meant
        narrow = values.astype(np.float32)
    _same_as_jax(lambda v, w: (v.astype(dtype), w.astype(dtype)), values, narrow)


def test_int64_extrema_above_two_to_the_53_are_exact(cache):
    x = np.array([2**60 + 1, 2**60 + 3, 2**60 + 2, -(2**62) - 1], dtype=np.int64)
    _same_as_jax(
        lambda a: (
            jnp.max(a),
            jnp.min(a),
            jax.lax.cummax(a),
            jax.lax.cummin(a),
            jnp.clip(a, 2**60 + 2, 2**60 + 2 + 2**10),
        ),
        x,
    )


def test_float32_nextafter_is_the_float32_neighbour(cache):
    a = np.array([1.0, 0.0, -0.0, 1e30, -1.5, 3.0], dtype=np.float32)
    b = np.array([2.0, 1.0, -1.0, np.inf, -2.0, 3.0], dtype=np.float32)
    _same_as_jax(jnp.nextafter, a, b)
    _same_as_jax(jnp.nextafter, a.astype(np.float64), b.astype(np.float64))


def test_reduce_precision_is_refused_unless_it_is_the_identity(cache):
    with pytest.raises(CKernelError, match="'reduce_precision' to 8 exponent / 7 mantissa"):
        CKernel(lambda v: jax.lax.reduce_precision(v * 2.0, exponent_bits=8, mantissa_bits=7), V)
    _same_as_jax(lambda v: jax.lax.reduce_precision(v * 2.0, exponent_bits=11, mantissa_bits=52), V)


def test_a_parameter_value_the_translation_lacks_is_refused(cache, monkeypatch):
    monkeypatch.setitem(primitive_params._PARAMS, "tanh", {})  # as if 'accuracy' were a new parameter
    with pytest.raises(CKernelError, match=r"does not implement 'tanh' with accuracy=None"):
        CKernel(lambda v: jnp.tanh(v), V)
    with pytest.raises(CKernelError, match=r"does not implement 'reshape' with dimensions"):
        CKernel(lambda w: jax.lax.reshape(w, (4, 2), dimensions=(1, 0)), np.ones((2, 4)))


def test_optimization_barrier_passes_every_operand(cache):
    _same_as_jax(lambda v, w: jax.lax.optimization_barrier((v * 2.0, w + 1.0)), V, V[::-1].copy())


# ----------------------------------------------------------------------- 4. portability


def test_cc_is_a_command_line(cache, tmp_path, monkeypatch):
    launcher = _script(tmp_path / "ccache", f'echo "$@" >> {tmp_path / "launched"}\nexec "$@"\n')
    monkeypatch.setenv("CC", f"{launcher} cc")
    assert c_compiler() is not None and c_compiler().endswith("ccache cc")
    np.testing.assert_allclose(CKernel(lambda v: v * 19.0, V)(V), V * 19.0)
    assert "kernel.c" in (tmp_path / "launched").read_text()
    monkeypatch.setenv("CC", "'unbalanced")
    assert c_compiler() is None


def test_a_stub_compiler_falls_back_to_xla(cache, tmp_path, monkeypatch):
    stub = _script(tmp_path / "cc", 'echo "xcrun: error: invalid active developer path" >&2\nexit 1\n')
    monkeypatch.setenv("CC", str(stub))
    with pytest.raises(CKernelError, match="not a working C compiler"):
        CKernel(lambda v: v * 23.0, V)
    backend = gym.make(NMSD_ID, dynamics="analytic").unwrapped.backend
    assert backend.kernel == "xla" and "not a working C compiler" in backend.kernel_fallback


def test_windows_falls_back_to_xla_without_getuid(cache, monkeypatch):
    monkeypatch.setattr(os, "name", "nt")
    monkeypatch.delattr(os, "getuid", raising=False)
    with pytest.raises(CKernelError, match="POSIX systems only"):
        CKernel(lambda v: v * 29.0, V)
    backend = gym.make(NMSD_ID, dynamics="analytic").unwrapped.backend
    assert backend.kernel == "xla" and "POSIX" in backend.kernel_fallback
