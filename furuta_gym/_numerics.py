"""The same numbers on every x86-64 machine: what furuta-gym pins before JAX starts.

XLA compiles JAX code for the CPU it runs on, and three of its choices change the rounding of a
float64 computation, which training then amplifies (docs/conventions.md, "Same numbers on every
machine", has the measurements):

* the instruction set: with FMA (AVX2 and later) ``a * b + c`` is rounded once, without it twice,
  and wider vectors sum in another order. ``--xla_cpu_max_isa=AVX2`` caps the code generation at
  AVX2, so an AVX-512 machine computes what an AVX2 machine does;
* YNNPACK, the kernel library XLA hands reductions and dots to: it splits them over the CPU's
  threads and picks its kernels by the CPU at run time, neither of which the cap reaches (a tiny
  training gives other bits on one core than on two). ``--xla_cpu_experimental_ynn_fusion_type=``
  (empty) leaves them to XLA's own code, whose order depends on neither;
* the size of XLA's intra-op thread pool (by default the process's cores): Eigen, which runs
  XLA's dots, splits a long inner dimension into one partial sum per thread, so a dot's bits
  follow the core count. ``PJRT_NPROC=2`` fixes the pool at two threads on every machine (a
  one-core machine time-slices them; a larger one gives up its other cores to XLA).

The first two go into ``XLA_FLAGS`` when ``furuta_gym`` is imported (its first act), before the user's own
flags, never replacing one the user set: XLA stops reading ``XLA_FLAGS`` at the first word that
does not start with ``--`` and silently drops everything after it (a widespread recipe's
``intra_op_parallelism_threads=1`` is such a word), so a pin placed after one would not apply;
:func:`unread_xla_flags` names what XLA will not read and :class:`NumericsWarning` says so. XLA reads ``XLA_FLAGS`` once, when JAX creates its CPU
backend (the first computation), as it reads ``PJRT_NPROC``, so importing ``jax`` earlier is
fine but computing with it is not: then nothing is pinned, :class:`NumericsWarning` says so and :func:`numerics` reports it.
``OPENBLAS_CORETYPE=Haswell`` (on a CPU with AVX2 and FMA) does the same for the BLAS that NumPy
and JAX's LAPACK calls load, when they load after furuta_gym (always under the ``furuta-gym``
command), and ``OPENBLAS_NUM_THREADS=1`` for its threads: OpenBLAS splits a long dot product
(and what a least-squares solve builds on it) into one partial sum per core it may use, and caps
any count asked for at the cores the process may run on, so only one thread gives the same bits
on every machine (and under ``taskset``). ``FURUTA_GYM_NATIVE_ISA=1`` turns all of it off. The variables are set in
``os.environ``, so child processes inherit them.
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
import sys
import warnings
from typing import Mapping

__all__ = [
    "NumericsWarning",
    "numerics",
    "pinned_environment",
    "pin_numerics",
    "unread_xla_flags",
    "PINNED_ISA",
    "PINNED_THREADS",
    "PINNED_BLAS_THREADS",
    "OPT_OUT",
]

PINNED_ISA = "AVX2"
OPT_OUT = "FURUTA_GYM_NATIVE_ISA"
MAX_ISA = "--xla_cpu_max_isa"
YNN_FUSIONS = "--xla_cpu_experimental_ynn_fusion_type"
THREADS = "PJRT_NPROC"  # XLA's intra-op pool size; XLA also reads NPROC, after this one
PINNED_THREADS = 2
BLAS_CORE = "Haswell"  # OpenBLAS's AVX2 + FMA kernels (AMD Zen uses the same ones)
BLAS_THREADS = "OPENBLAS_NUM_THREADS"  # OpenBLAS reads it before GOTO_NUM_THREADS and OMP_NUM_THREADS
PINNED_BLAS_THREADS = 1
# an unknown flag in XLA_FLAGS aborts the process: the lowest supported jaxlib, 0.8.1, knows this one
_YNN_SINCE = (0, 8, 1)

_state: dict = {"pinned": {}, "not_applied": None, "blas_not_applied": None}


class NumericsWarning(UserWarning):
    """Emitted when furuta_gym cannot pin XLA's CPU numerics because JAX has already started."""


def _flag_set(flags: str, name: str) -> bool:
    return any(part == name or part.startswith(name + "=") for part in flags.split())


def unread_xla_flags(flags: str) -> list[str]:
    """The words of ``flags`` (an ``XLA_FLAGS`` value) that XLA will not read: from the first one
    that does not start with ``--`` to the end (XLA's parser stops there without a word)."""
    words = flags.split()
    for i, word in enumerate(words):
        if not word.startswith("--"):
            return words[i:]
    return []


def _version(text: str) -> tuple[int, ...]:
    out = []
    for part in text.split(".")[:3]:
        digits = "".join(c for c in part if c.isdigit())
        out.append(int(digits) if digits else 0)
    return tuple(out)


def pinned_environment(
    environ: Mapping[str, str], *, machine: str, cpu_flags: frozenset[str] | None, jaxlib_version: str | None
) -> dict[str, str]:
    """The variables (name → value) furuta_gym sets in an environment ``environ`` on a CPU of
    architecture ``machine`` (``platform.machine()``) with ``cpu_flags`` (``None``: unknown)
    and jaxlib ``jaxlib_version``; nothing the user set is replaced."""
    if environ.get(OPT_OUT, "").strip().lower() not in ("", "0", "false", "no", "off"):
        return {}
    if machine.lower() not in ("x86_64", "amd64", "x64"):
        return {}  # the ISA names are x86-64's; other machines are not pinned
    out = {}
    flags = environ.get("XLA_FLAGS", "")
    added = []
    if not _flag_set(flags, MAX_ISA):
        added.append(f"{MAX_ISA}={PINNED_ISA}")
    if jaxlib_version is not None and _version(jaxlib_version) >= _YNN_SINCE and not _flag_set(flags, YNN_FUSIONS):
        added.append(f"{YNN_FUSIONS}=")
    if added:  # first: a word XLA stops at in the user's flags must not swallow the pin
        out["XLA_FLAGS"] = " ".join([*added, flags.strip()]).strip()
    if THREADS not in environ and "NPROC" not in environ:
        out[THREADS] = str(PINNED_THREADS)
    # a core type the CPU lacks would crash OpenBLAS: only where AVX2 and FMA are known present
    if "OPENBLAS_CORETYPE" not in environ and cpu_flags is not None and {"avx2", "fma"} <= cpu_flags:
        out["OPENBLAS_CORETYPE"] = BLAS_CORE
    if BLAS_THREADS not in environ and "GOTO_NUM_THREADS" not in environ:
        out[BLAS_THREADS] = str(PINNED_BLAS_THREADS)
    return out


def _cpu_flags() -> frozenset[str] | None:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return None


def _jaxlib_version() -> str | None:
    try:
        return importlib.metadata.version("jaxlib")
    except importlib.metadata.PackageNotFoundError:
        return None


def _jax_started() -> bool:
    if "jax" not in sys.modules:
        return False
    try:  # JAX has no public way to ask whether its backends exist yet
        from jax._src import xla_bridge  # noqa: PLC0415  JAX internals that may move: inside the try

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # moved in another JAX version: assume it started
        return True


def pin_numerics() -> dict[str, str]:
    """Set the pinned variables in ``os.environ`` (what :func:`pinned_environment` gives), once,
    at import; returns what it set. If JAX has already computed, the XLA flags cannot apply to
    this process: they are left unset and a :class:`NumericsWarning` says so."""
    wanted = pinned_environment(
        os.environ, machine=platform.machine(), cpu_flags=_cpu_flags(), jaxlib_version=_jaxlib_version()
    )
    if {"XLA_FLAGS", THREADS} & wanted.keys() and _jax_started():
        wanted.pop("XLA_FLAGS", None)
        wanted.pop(THREADS, None)
        _state["not_applied"] = (
            "JAX had already started when furuta_gym was imported: XLA's CPU code generation is not "
            f"pinned in this process (results may differ between machines). Import furuta_gym before "
            f"the first JAX computation, or set XLA_FLAGS='{MAX_ISA}={PINNED_ISA} {YNN_FUSIONS}=' and "
            f"{THREADS}={PINNED_THREADS} yourself; {OPT_OUT}=1 silences this."
        )
        warnings.warn(_state["not_applied"], NumericsWarning, stacklevel=2)
    blas = {"OPENBLAS_CORETYPE", BLAS_THREADS} & wanted.keys()
    if blas and "numpy" in sys.modules:  # NumPy loads its OpenBLAS on import
        _state["blas_not_applied"] = (
            "NumPy was imported before furuta_gym: its OpenBLAS has chosen its kernels and threads for this "
            "CPU, so NumPy's and SciPy's results may differ between machines (child processes get the pin). "
            f"Import furuta_gym before NumPy, or set {' and '.join(f'{k}={wanted[k]}' for k in sorted(blas))} "
            f"yourself; {OPT_OUT}=1 silences this."
        )
        warnings.warn(_state["blas_not_applied"], NumericsWarning, stacklevel=2)
    unread = unread_xla_flags(wanted.get("XLA_FLAGS", os.environ.get("XLA_FLAGS", "")))
    if unread:
        warnings.warn(
            f"XLA_FLAGS: XLA stops reading at {unread[0]!r} (not a '--' flag) and ignores it and what "
            f"follows ({' '.join(unread)})" + ("; furuta_gym's pin comes before it" if "XLA_FLAGS" in wanted else ""),
            NumericsWarning,
            stacklevel=2,
        )
    os.environ.update(wanted)
    _state["pinned"] = dict(wanted)
    return dict(wanted)


def numerics() -> dict:
    """What furuta_gym pinned in this process: ``{"pinned": {variable: value set}, "xla_flags":
    XLA_FLAGS as given, "xla_flags_unread": its words XLA will not read, "pjrt_nproc": XLA's thread
    pool size if set, "openblas_coretype": ..., "openblas_num_threads": ...,
    "not_applied": why the XLA pin did not apply, or None, "blas_not_applied": why OpenBLAS's
    pin did not apply in this process (NumPy imported first), or None}``."""
    flags = os.environ.get("XLA_FLAGS", "")
    return {
        "pinned": dict(_state["pinned"]),
        "xla_flags": flags,
        "xla_flags_unread": unread_xla_flags(flags),
        "pjrt_nproc": os.environ.get(THREADS),
        "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE"),
        "openblas_num_threads": os.environ.get(BLAS_THREADS),
        "not_applied": _state["not_applied"],
        "blas_not_applied": _state["blas_not_applied"],
    }


pin_numerics()  # on import: furuta_gym imports this module before anything that loads JAX or BLAS
