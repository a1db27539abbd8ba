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

from furuta_gym._numerics import pinned_environment

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
    assert pinned_environment({}, **env) == {"XLA_FLAGS": PIN, "OPENBLAS_CORETYPE": "Haswell"}
    # the user's flags stay, first; a cap or a YNN choice of the user's wins; so does a BLAS core
    got = pinned_environment({"XLA_FLAGS": " --xla_dump_to=/tmp/x ", "OPENBLAS_CORETYPE": "Zen"}, **env)
    assert got == {"XLA_FLAGS": "--xla_dump_to=/tmp/x " + PIN}
    got = pinned_environment({"XLA_FLAGS": "--xla_cpu_max_isa=AVX512"}, **env)
    assert got["XLA_FLAGS"] == "--xla_cpu_max_isa=AVX512 --xla_cpu_experimental_ynn_fusion_type="
    assert "XLA_FLAGS" not in pinned_environment({"XLA_FLAGS": PIN}, **env)
    # opted out, another architecture: nothing; no AVX2 / FMA, or flags unknown: no BLAS core type
    assert pinned_environment({"FURUTA_GYM_NATIVE_ISA": "1"}, **env) == {}
    assert pinned_environment({"FURUTA_GYM_NATIVE_ISA": "0"}, **env)["XLA_FLAGS"] == PIN
    assert pinned_environment({}, **{**env, "machine": "aarch64"}) == {}
    assert pinned_environment({}, **{**env, "cpu_flags": frozenset({"sse4_2", "avx"})}) == {"XLA_FLAGS": PIN}
    assert pinned_environment({}, **{**env, "cpu_flags": None}) == {"XLA_FLAGS": PIN}
    # a jaxlib older than the supported ones may not know the YNN flag (an unknown flag aborts)
    assert pinned_environment({}, **{**env, "jaxlib_version": "0.7.2"})["XLA_FLAGS"] == "--xla_cpu_max_isa=AVX2"


def _run(code: str, **env) -> subprocess.CompletedProcess:
    environ = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "FURUTA_GYM_NATIVE_ISA")} | env
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300, env=environ
    )


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="the pin is x86-64's")
def test_the_pin_reaches_xla_and_a_late_import_says_it_cannot():
    early = _run("""
        import jax, jax.numpy as jnp            # imported first is fine: XLA reads its flags later
        import furuta_gym, os
        jnp.ones(2) + 1
        print(os.environ["XLA_FLAGS"], "|", furuta_gym.numerics()["not_applied"])
    """)
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
    assert all(r["numerics"]["xla_flags"] == PIN for r in runs)
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
