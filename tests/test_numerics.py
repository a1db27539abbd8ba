"""The same bits on every x86-64 machine (issue 68): what furuta_gym pins before JAX starts, and a
CI-size training that gives identical parameters on emulated machines with the pin and different
ones without it (studies/cpu_numerics.py runs the full matrix; docs/conventions.md)."""

import importlib.util
import json
import os
import platform
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from furuta_gym._numerics import pinned_environment, unread_xla_flags

ROOT = Path(__file__).resolve().parents[1]
PIN = "--xla_cpu_max_isa=AVX2 --xla_cpu_experimental_ynn_fusion_type="
AVX2 = frozenset({"sse4_2", "avx", "avx2", "fma"})


def _study():
    spec = importlib.util.spec_from_file_location("cpu_numerics", ROOT / "studies" / "cpu_numerics.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_pin_extends_the_users_flags_and_never_replaces_them():
    env = dict(machine="x86_64", cpu_flags=AVX2, jaxlib_version="0.10.2")
    assert pinned_environment({}, **env) == {
        "XLA_FLAGS": PIN,
        "OPENBLAS_CORETYPE": "Haswell",
        "PJRT_NPROC": "2",
        "OPENBLAS_NUM_THREADS": "1",
    }
    # the user's flags stay, after the pin (XLA stops reading at a word that is not a -- flag:
    # one in the user's flags must not hide the pin); a cap or a YNN choice of the user's wins;
    # so does a BLAS core
    got = pinned_environment({"XLA_FLAGS": " --xla_dump_to=/tmp/x ", "OPENBLAS_CORETYPE": "Zen"}, **env)
    assert got == {"XLA_FLAGS": PIN + " --xla_dump_to=/tmp/x", "PJRT_NPROC": "2", "OPENBLAS_NUM_THREADS": "1"}
    # a thread count of the user's wins (XLA reads PJRT_NPROC, then NPROC; OpenBLAS its own
    # variable, then GOTO_NUM_THREADS, before OMP_NUM_THREADS, which other libraries read too)
    assert "PJRT_NPROC" not in pinned_environment({"NPROC": "8"}, **env)
    assert "PJRT_NPROC" not in pinned_environment({"PJRT_NPROC": "8"}, **env)
    for given in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS"):
        assert "OPENBLAS_NUM_THREADS" not in pinned_environment({given: "4"}, **env)
    assert pinned_environment({"OMP_NUM_THREADS": "4"}, **env)["OPENBLAS_NUM_THREADS"] == "1"
    got = pinned_environment({"XLA_FLAGS": "--xla_cpu_max_isa=AVX512"}, **env)
    assert got["XLA_FLAGS"] == "--xla_cpu_experimental_ynn_fusion_type= --xla_cpu_max_isa=AVX512"
    assert unread_xla_flags("--a=1 intra_op_parallelism_threads=1 --b=2") == ["intra_op_parallelism_threads=1", "--b=2"]
    assert unread_xla_flags(PIN) == []
    assert "XLA_FLAGS" not in pinned_environment({"XLA_FLAGS": PIN}, **env)
    # opted out, another architecture: nothing; no AVX2 / FMA, or flags unknown: no BLAS core type
    assert pinned_environment({"FURUTA_GYM_NATIVE_ISA": "1"}, **env) == {}
    assert pinned_environment({"FURUTA_GYM_NATIVE_ISA": "0"}, **env)["XLA_FLAGS"] == PIN
    assert pinned_environment({}, **{**env, "machine": "aarch64"}) == {}
    no_blas = {"XLA_FLAGS": PIN, "PJRT_NPROC": "2", "OPENBLAS_NUM_THREADS": "1"}  # a core type only
    assert pinned_environment({}, **{**env, "cpu_flags": frozenset({"sse4_2", "avx"})}) == no_blas
    assert pinned_environment({}, **{**env, "cpu_flags": None}) == no_blas
    # a jaxlib older than the supported ones may not know the YNN flag (an unknown flag aborts)
    assert pinned_environment({}, **{**env, "jaxlib_version": "0.7.2"})["XLA_FLAGS"] == "--xla_cpu_max_isa=AVX2"


def _blas_pinned_here() -> bool:
    from furuta_gym._numerics import _cpu_flags

    flags = _cpu_flags()
    return platform.machine().lower() in ("x86_64", "amd64") and flags is not None and {"avx2", "fma"} <= flags


def _run(code: str, **env) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter without the pinned variables (``env`` adds to them; a
    variable given as None is removed)."""
    environ = {
        k: v
        for k, v in os.environ.items()
        if k not in ("XLA_FLAGS", "FURUTA_GYM_NATIVE_ISA", "PJRT_NPROC", "OPENBLAS_NUM_THREADS")
    } | env
    environ = {k: v for k, v in environ.items() if v is not None}
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300, env=environ
    )


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="the pin is x86-64's")
def test_the_pin_reaches_xla_and_a_late_import_says_it_cannot():
    early = _run(
        """
        import jax, jax.numpy as jnp            # imported first is fine: XLA reads its flags later
        import furuta_gym, os
        jnp.ones(2) + 1
        print(os.environ["XLA_FLAGS"], "|", furuta_gym.numerics()["not_applied"])
        """,
        OPENBLAS_CORETYPE="Haswell",  # NumPy (which JAX imports) is not: its BLAS is pinned by hand here
        OPENBLAS_NUM_THREADS="1",
    )
    assert early.returncode == 0, early.stderr
    assert early.stdout.split("|")[0].strip() == PIN and early.stdout.split("|")[1].strip() == "None"
    assert "NumericsWarning" not in early.stderr
    late = _run("""
        import jax.numpy as jnp, os
        jnp.ones(2) + 1                         # JAX has started: too late for XLA_FLAGS
        import furuta_gym
        print(repr(os.environ.get("XLA_FLAGS")), "|", furuta_gym.numerics()["not_applied"])
    """)
    assert late.returncode == 0, late.stderr
    assert "NumericsWarning: JAX had already started" in late.stderr
    assert late.stdout.startswith("None |") and "not pinned" in late.stdout  # nothing claimed
    opted_out = _run("import furuta_gym, os; print(os.environ.get('XLA_FLAGS'))", FURUTA_GYM_NATIVE_ISA="1")
    assert opted_out.stdout.strip() == "None"


@pytest.mark.skipif(not _blas_pinned_here(), reason="OpenBLAS's core type is pinned on x86-64 with AVX2 and FMA")
def test_numpy_imported_first_keeps_its_own_blas_and_a_warning_says_so():
    """NumPy loads its OpenBLAS on import: imported before furuta_gym, its kernels are the CPU's
    own choice, and the warning says so; furuta_gym first, the pin applies."""
    code = """
        import os
        {first}
        print(os.environ.get("OPENBLAS_CORETYPE"), "|", furuta_gym.numerics()["blas_not_applied"])
    """
    late = _run(code.format(first="import numpy, furuta_gym"), OPENBLAS_CORETYPE=None)
    assert late.returncode == 0, late.stderr
    assert "NumericsWarning: NumPy was imported before furuta_gym" in late.stderr
    assert late.stdout.startswith("Haswell |") and "may differ between machines" in late.stdout
    early = _run(code.format(first="import furuta_gym, numpy"), OPENBLAS_CORETYPE=None)
    assert early.returncode == 0, early.stderr
    assert "NumericsWarning" not in early.stderr and early.stdout.split() == ["Haswell", "|", "None"]
    given = _run(code.format(first="import numpy, furuta_gym"), OPENBLAS_CORETYPE="Haswell", OPENBLAS_NUM_THREADS="1")
    assert "NumericsWarning" not in given.stderr and given.stdout.split()[-1] == "None"
    threads = _run(code.format(first="import numpy, furuta_gym"), OPENBLAS_CORETYPE="Haswell")
    assert "OPENBLAS_NUM_THREADS=1 yourself" in threads.stderr  # the core type given, not the threads


# A jitted float64 loop whose reductions YNNPACK splits by the core count when it is on, and a
# dot with a long inner dimension, which Eigen splits by XLA's thread count: their digests on one
# core and on two say whether the pin reached XLA.
PROBE = """
    import hashlib, os, warnings
    warnings.simplefilter("ignore")
    import furuta_gym, jax, jax.numpy as jnp, numpy as np
    x = jax.random.normal(jax.random.PRNGKey(1), (4096, 64))
    w = jax.random.normal(jax.random.PRNGKey(2), (64, 64)) * 0.1
    def body(c, _):
        c = jnp.tanh(c @ w) + 0.01 * jnp.sin(c)
        return c, jnp.sum(c**2)
    ys = jax.jit(lambda x: jax.lax.scan(body, x, None, length=100)[1])(x)
    dot = jax.jit(lambda a, b: a @ b)(x.T, jnp.cos(x))
    print(hashlib.sha1(np.asarray(ys).tobytes()).hexdigest(), hashlib.sha1(np.asarray(dot).tobytes()).hexdigest())
"""


@pytest.mark.skipif(
    sys.platform != "linux"
    or platform.machine().lower() not in ("x86_64", "amd64")
    or len(os.sched_getaffinity(0)) < 2,
    reason="needs Linux x86-64 with two cores (the probe runs on one core and on two)",
)
def test_the_pin_applies_behind_a_word_xla_stops_reading_at():
    """A widespread recipe's XLA_FLAGS ends in ``intra_op_parallelism_threads=1``, which is no XLA
    flag: XLA stops reading there. The pin, placed after it, was silently dropped (a Ray task and
    a local-pool process then trained different models); placed before, one core and two give
    the same bits, and the user is told which words XLA ignores."""
    user = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    digests = []
    for cores in ("0", "0,1"):
        code = f"import os; os.sched_setaffinity(0, {{{cores}}})\n" + textwrap.dedent(PROBE)
        done = _run(code, XLA_FLAGS=user, JAX_ENABLE_X64="1")
        assert done.returncode == 0, done.stderr[-2000:]
        digests.append(done.stdout.split()[-2:])
    assert digests[0] == digests[1]
    warned = _run("import furuta_gym", XLA_FLAGS=user)
    assert "XLA stops reading at 'intra_op_parallelism_threads=1'" in warned.stderr


@pytest.mark.skipif(
    sys.platform != "linux"
    or platform.machine().lower() not in ("x86_64", "amd64")
    or len(os.sched_getaffinity(0)) < 2,
    reason="emulating machines needs Linux x86-64 (CPU affinity, XLA's x86 caps) and two cores",
)
def test_training_gives_the_same_bits_on_an_emulated_avx2_machine_with_one_core(tmp_path):
    """This machine on all its cores with OpenBLAS's and NumPy's own kernel choice, against an AVX2
    machine with one core (XLA capped at AVX2, one core, OpenBLAS's Haswell kernels, NumPy without
    its AVX-512 loops): with the pinned default, the same parameters to the last bit. Without the
    pin the core count alone changes them (the next test holds the study's native rows to that),
    so a pin that stopped reaching XLA fails here."""
    study = _study()
    runs = [
        study.run_setting(True, cap=None, cores=None, blas=None, out=tmp_path / "here.npz"),
        study.run_setting(True, cap="AVX2", cores=1, blas="Haswell", out=tmp_path / "avx2.npz", numpy_avx512_off=True),
    ]
    assert all(sorted(r["numerics"]["xla_flags"].split()) == sorted(PIN.split()) for r in runs)
    assert study.digest(runs[0]["arrays"]) == study.digest(runs[1]["arrays"])


def test_the_study_shows_the_emulation_tells_machines_apart_without_the_pin():
    rows = json.loads((ROOT / "results" / "cpu_numerics" / "results.json").read_text())["rows"]
    pinned = {r["digest"] for r in rows if r["pinned"] and r["xla_cap"] != "AVX"}
    native = {r["digest"] for r in rows if not r["pinned"]}
    assert len(pinned) == 1  # every machine with AVX2 and FMA: one set of bits
    assert len(native) >= 2 and not native & pinned  # native: one core differs from two
    no_fma = [r for r in rows if r["pinned"] and r["xla_cap"] == "AVX"]
    assert no_fma and no_fma[0]["digest"] not in pinned  # the pin's limit, as documented


def test_cpu_numerics_docs_block_matches_its_results():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "cpu_numerics.py"), "--check"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_numerics_cost_benchmark_section_matches_its_results():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "numerics_cost.py"), "--check"],
        capture_output=True,
        text=True,
        cwd=ROOT / "bench",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


BLAS_PROBE = """
    import os
    os.sched_setaffinity(0, {{{cores}}})  # before OpenBLAS loads
    {first}
    import numpy as np
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal(2_000_000), rng.standard_normal(2_000_000)
    A, b = rng.standard_normal((4000, 60)), rng.standard_normal(4000)
    print(float(x @ y).hex(), np.linalg.lstsq(A, b, rcond=None)[0].tobytes().hex())
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two cores to compare with one")
def test_numpy_gives_the_same_bits_on_one_core_and_on_two():
    """OpenBLAS splits a long dot product (and a least-squares solve) into one partial sum per
    core it may use: a process on one core (or under ``taskset``) gave other bits than one on two.
    furuta_gym pins its threads at one; without the pin the two differ (this machine's OpenBLAS)."""

    def probe(cores: str, first: str, **env) -> str:
        out = _run(BLAS_PROBE.format(cores=cores, first=first), **env)
        assert out.returncode == 0, out.stderr
        return out.stdout

    pinned = [probe(c, "import furuta_gym") for c in ("0", "0, 1")]
    assert pinned[0] == pinned[1]
    native = [probe(c, "pass", OPENBLAS_CORETYPE="Haswell") for c in ("0", "0, 1")]
    assert native[0] != native[1] and native[0] == pinned[0]  # one thread is what one core gave
