"""A disk cache of traced training steps (``jax.export``), so a warm first call skips Python tracing.

JAX's persistent compilation cache stores compiled executables, but each new process still
*traces* the step in Python before it can look one up; for the trajectory loss (a differentiated
diffrax solve) tracing alone takes seconds (BENCHMARKS.md, "Loss cost"). This module serialises
the traced and lowered step with :mod:`jax.export` and, in a later process, deserialises it
instead of tracing: the lowering of the stored StableHLO module is then cheap and its compiled
executable comes from JAX's persistent cache.

**When it is active.** Only when the user has opted in to JAX's persistent compilation cache
(``JAX_COMPILATION_CACHE_DIR`` or ``jax.config.update("jax_compilation_cache_dir", ...)``); the
steps are then stored beside it, in ``<that dir>/furuta_gym_steps/``. ``FURUTA_GYM_STEP_CACHE=0``
turns it off. It also needs the ``flatbuffers`` package (jax's serialisation format); without it,
or if anything about exporting or loading fails, the live jitted step is used — the cache can
only save time, never change a result.

**What a stored step is keyed by** — everything the traced computation depends on: the loss
settings and training configuration given by the caller, the structure and static fields of
every argument (model, optimiser state, batches) with their shapes and dtypes, the values of
the non-trained arrays baked into the step, the source code of furuta_gym and of every loaded
module outside installed packages (a user's own model class), the versions of jax, jaxlib, equinox, diffrax and optax, the backend, and the x64 and
``EQX_ON_ERROR`` settings. The optimiser is trusted to be the one the caller says (the key
includes the caller's description of it): :func:`furuta_gym.training.train._make_step` only
uses this cache for optimisers built by its own ``_build_optimizer``.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import json
import os
import sys
import sysconfig
import tempfile
import warnings
from pathlib import Path
from typing import Any, Callable

import jax
import jax.core
import numpy as np
from jax import export

from .._versions import installed_versions

__all__ = ["step_cache_dir", "ExportedStep"]

_SUBDIR = "furuta_gym_steps"
_FORMAT = 1  # bump when the stored layout below changes


def step_cache_dir() -> Path | None:
    """Where exported steps go: beside JAX's persistent cache if the user enabled it, else None."""
    if os.environ.get("FURUTA_GYM_STEP_CACHE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    base = getattr(jax.config, "jax_compilation_cache_dir", None)
    if not base:
        return None
    try:
        import flatbuffers  # noqa: F401, PLC0415  (jax.export's serialisation needs it)
    except ImportError:
        return None
    return Path(base) / _SUBDIR


_SOURCE_DIGEST: str | None = None


def _local_sources() -> list[Path]:
    """Every .py file of furuta_gym (imported or not) and every loaded module that is not part of
    an installed distribution or the standard library (e.g. a user's own model class)."""
    installed = {Path(sysconfig.get_paths()[k]).resolve() for k in ("stdlib", "platstdlib", "purelib", "platlib")}
    files: set[Path] = set()
    # the whole package whatever was imported, so every process computes the same digest; the
    # folders mapped into it by pyproject's package-dir are found through their specs
    folders = list(importlib.import_module("furuta_gym").__path__)
    for sub in ("models", "controllers", "assets"):
        try:
            spec = importlib.util.find_spec(f"furuta_gym.{sub}")
        except (ImportError, ValueError):
            spec = None
        folders += list(spec.submodule_search_locations or []) if spec is not None else []
    for folder in folders:
        files.update(Path(folder).resolve().rglob("*.py"))
    prefixes = tuple(str(root) for root in installed)
    for module in list(sys.modules.values()):
        path = getattr(module, "__file__", None)
        if path and path.endswith(".py") and not path.startswith(prefixes):
            path = Path(path).resolve()
            if not any(path.is_relative_to(root) for root in installed):
                files.add(path)
    return sorted(files)


def _source_digest() -> str:
    """Hash of the local source code (a code edit invalidates every stored step)."""
    global _SOURCE_DIGEST
    if _SOURCE_DIGEST is None:
        h = hashlib.sha256()
        for path in _local_sources():
            h.update(str(path).encode())
            try:
                h.update(path.read_bytes())
            except OSError:
                h.update(b"<unreadable>")
        _SOURCE_DIGEST = h.hexdigest()
    return _SOURCE_DIGEST


def _versions() -> dict[str, str]:
    return installed_versions(("jax", "jaxlib", "equinox", "diffrax", "optax"), missing="?")


def array_digest(tree: Any) -> str:
    """Hash of the structure (incl. static fields) and array values of ``tree``."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    h = hashlib.sha256(str(treedef).encode())
    for leaf in leaves:
        if isinstance(leaf, (jax.Array, np.ndarray, np.generic)):
            a = np.asarray(leaf)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(np.ascontiguousarray(a).tobytes())
        else:
            h.update(repr(leaf).encode())
    return h.hexdigest()


def _is_array(x) -> bool:
    return isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer)


class ExportedStep:
    """Wraps a jitted training step ``(params, opt_state, *rest) -> (params, opt_state, terms, ok)``.

    Called like the step. Per distinct argument signature it loads the exported step from
    ``cache_dir`` or exports and stores it, then runs the deserialised computation under
    ``jax.jit``. ``terms`` must be a dict of arrays; ``params``/``opt_state`` come back with the
    structure they went in with. Falls back to ``step`` for anything it cannot handle.
    ``compiler_options`` (XLA's, as for ``jax.jit``) compile the deserialised computation; JAX
    refuses them on a jit nested in another, so a ``step`` compiled with them is exported through
    ``export_step``, the same step jitted without them. Options that change results must enter
    ``key`` too.
    """

    def __init__(
        self,
        step: Callable,
        key: dict[str, Any],
        cache_dir: Path,
        compiler_options: dict[str, Any] | None = None,
        export_step: Callable | None = None,
    ):
        self._step = step
        self._key = key
        self._dir = Path(cache_dir)
        self._compiler_options = compiler_options
        self._export_step = step if export_step is None else export_step
        self._calls: dict[Any, Callable | None] = {}

    def __call__(self, *args):
        leaves, treedef = jax.tree_util.tree_flatten(args)
        if not all(_is_array(leaf) for leaf in leaves):
            return self._step(*args)
        sig = (treedef, tuple((leaf.shape, leaf.dtype, leaf.aval.weak_type) for leaf in leaves))
        if sig not in self._calls:
            self._calls[sig] = self._load_or_export(args, leaves, treedef, sig)
        call = self._calls[sig]
        if call is None:
            return self._step(*args)
        return call(args, leaves)

    # -- internals -----------------------------------------------------------------------------

    def _digest(self, treedef, sig) -> str:
        payload = {
            "format": _FORMAT,
            "key": self._key,
            "treedef": str(treedef),
            "avals": [[list(s), str(d), bool(w)] for s, d, w in sig[1]],
            "source": _source_digest(),
            "versions": _versions(),
            "backend": jax.default_backend(),
            # flags with a context manager refuse config.read(); config.values holds their current value
            "x64": bool(jax.config.values["jax_enable_x64"]),
            "matmul_precision": str(jax.config.values["jax_default_matmul_precision"]),
            "eqx_on_error": os.environ.get("EQX_ON_ERROR", ""),
        }
        return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:32]

    def _load_or_export(self, args, leaves, treedef, sig):

        params_def = jax.tree_util.tree_structure(args[0])
        opt_def = jax.tree_util.tree_structure(args[1])
        n_params, n_opt = params_def.num_leaves, opt_def.num_leaves
        path = self._dir / f"step-{self._digest(treedef, sig)}.jaxexport"
        exp, terms = None, None
        try:
            if path.exists():
                blob = path.read_bytes()
                header_len = int.from_bytes(blob[:4], "little")
                terms = json.loads(blob[4 : 4 + header_len])["terms"]
                exp = export.deserialize(bytearray(blob[4 + header_len :]))
        except Exception as e:  # a damaged or foreign file: export afresh and overwrite it
            warnings.warn(f"ignoring unreadable cached training step {path}: {e}", stacklevel=3)
            exp = None
        if exp is None:
            try:
                exp, terms = self._export(treedef, leaves, n_params, n_opt, params_def, opt_def)
                header = json.dumps({"terms": terms}).encode()
                self._write(path, len(header).to_bytes(4, "little") + header + bytes(exp.serialize()))
            except Exception as e:
                warnings.warn(
                    f"training step not exported ({type(e).__name__}: {e}); using the jitted step", stacklevel=3
                )
                return None

        run = jax.jit(exp.call, compiler_options=self._compiler_options)
        assert terms is not None  # read or exported with exp

        def call(args, leaves):
            # The deserialised computation returns arrays committed to their device, while a
            # run's first params / opt_state and every batch arrive uncommitted. jit keys its
            # compilation on that too, so the first and second calls each compiled the whole step
            # (once per training run). Committing every argument
            # where it already lives makes all calls alike: one compilation, same results.
            leaves = [leaf if leaf.committed else jax.device_put(leaf, next(iter(leaf.devices()))) for leaf in leaves]
            out = run(*leaves)
            params = jax.tree_util.tree_unflatten(params_def, out[:n_params])
            opt_state = jax.tree_util.tree_unflatten(opt_def, out[n_params : n_params + n_opt])
            values = out[n_params + n_opt : -1]
            return params, opt_state, dict(zip(terms, values, strict=True)), out[-1]

        return call

    def _export(self, treedef, leaves, n_params, n_opt, params_def, opt_def):

        terms_keys: list[str] = []
        step = self._export_step

        def flat_step(*flat):
            params, opt_state, terms, ok = step(*jax.tree_util.tree_unflatten(treedef, flat))
            # the stored computation returns leaves only; the caller rebuilds the trees
            if jax.tree_util.tree_structure(params) != params_def or jax.tree_util.tree_structure(opt_state) != opt_def:
                raise ValueError("the step changed the structure of params or opt_state")
            terms_keys[:] = list(terms)  # the live step's order, so histories read the same
            return (
                *jax.tree_util.tree_leaves(params),
                *jax.tree_util.tree_leaves(opt_state),
                *[terms[k] for k in terms_keys],
                ok,
            )

        specs = [jax.ShapeDtypeStruct(leaf.shape, leaf.dtype, weak_type=leaf.aval.weak_type) for leaf in leaves]
        exp = export.export(jax.jit(flat_step))(*specs)
        return exp, list(terms_keys)

    def _write(self, path: Path, data: bytes) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.chmod(tmp, 0o644)  # like JAX's own cache entries (mkstemp makes it owner-only)
            os.replace(tmp, path)  # atomic: a concurrent reader sees the old file or the new one
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


_KNOWN_OPTIMIZERS: dict[int, tuple[Callable, str]] = {}


def register_optimizer(optimizer, description: str) -> None:
    """Record that ``optimizer`` (an optax transformation) is fully described by ``description``.

    Only steps built with a registered optimiser are exported: the description enters the key, as
    an optimiser's hyper-parameters are closed over and invisible from outside.
    """
    if len(_KNOWN_OPTIMIZERS) > 64:  # a long-lived process building many runs: forget the oldest
        _KNOWN_OPTIMIZERS.pop(next(iter(_KNOWN_OPTIMIZERS)))
    _KNOWN_OPTIMIZERS[id(optimizer.update)] = (optimizer.update, description)


def optimizer_description(optimizer) -> str | None:
    """The registered description of ``optimizer``, or None if it was not registered."""
    entry = _KNOWN_OPTIMIZERS.get(id(getattr(optimizer, "update", None)))
    if entry is None or entry[0] is not optimizer.update:
        return None
    return entry[1]
