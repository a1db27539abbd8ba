""":class:`CKernel`: a JAX function traced once, translated to C, built, checked against XLA and
called on fixed numpy buffers."""

from __future__ import annotations

import ctypes
import warnings
from typing import Any, Callable, Sequence

import jax
import numpy as np

from . import cache
from .errors import CKernelError, CKernelWarning
from .translate import Aval, translate

__all__ = ["CKernel"]


#: random input sets compared with XLA after the example inputs
_VERIFY_TRIALS = 3

#: (rtol, atol relative to the output's scale) when comparing C with XLA, by float type
_TOLERANCES = {"float64": (1e-9, 1e-12), "float32": (1e-4, 1e-6)}


def _trial_input(example, aval, rng) -> np.ndarray:
    """The example input (rng None) or a random one near it: floats move by 5 % of their size,
    or by N(0, 0.5) where zero (states and inputs are zeros in the examples; angles and rates
    of order one are their typical range). Integers and booleans may be indices or loop
    counts: kept as given."""
    x = np.array(example, dtype=aval.dtype).reshape(aval.shape)
    if rng is None or not np.issubdtype(x.dtype, np.floating):
        return x
    scale = np.where(x == 0, 0.5, 0.05 * np.abs(x))
    noisy = x + rng.normal(size=x.shape) * np.nan_to_num(scale, nan=0.0, posinf=0.0)
    return np.array(noisy, dtype=x.dtype)  # a fresh C-contiguous array, 0-d kept 0-d


def _disagreement(got: np.ndarray, want: np.ndarray) -> str | None:
    """Why ``got`` (C) is not ``want`` (XLA), or None when they agree to round-off."""
    if got.shape != want.shape:
        return f"shape {got.shape} vs {want.shape}"
    if not np.issubdtype(want.dtype, np.inexact):
        bad = got != want
        return (
            None
            if not bad.any()
            else f"{int(bad.sum())} element(s) differ exactly, e.g. {got[bad][0]} vs {want[bad][0]}"
        )
    rtol, atol = _TOLERANCES.get(want.dtype.name, (1e-4, 1e-6))
    finite = np.abs(want[np.isfinite(want)])
    atol *= max(1.0, float(finite.max()) if finite.size else 1.0)  # cancellation scales with the output
    close = np.isclose(got, want, rtol=rtol, atol=atol, equal_nan=True)
    if close.all():
        return None
    k = np.flatnonzero(~close.ravel())[0]
    return f"{int((~close).sum())} element(s) differ, e.g. C {got.ravel()[k]!r} vs XLA {want.ravel()[k]!r}"


class CKernel:
    """``fn(*args)`` for arrays of fixed shapes and dtypes, run as one compiled C function.

    ``example_args`` fix the shapes and dtypes (a pytree of arrays; only the leaves' shapes and
    dtypes are used). :meth:`bind` returns a zero-argument callable over fixed numpy buffers:
    write inputs into ``inputs[k]``, call, read ``outputs[k]`` — the form with the least cost per
    call. An output buffer may also be an input buffer (an in-place update): the results are
    staged and written out after the last input is read.
    """

    def __init__(self, fn: Callable, *example_args: Any, name: str = "kernel"):
        cache.require_compiler()
        leaves, self.in_tree = jax.tree_util.tree_flatten(example_args)
        self.in_avals = [Aval(np.shape(x), x.dtype if hasattr(x, "dtype") else np.asarray(x).dtype) for x in leaves]

        def flat_fn(*flat):
            return fn(*jax.tree_util.tree_unflatten(self.in_tree, flat))

        self.name = name
        closed, out_shapes = jax.make_jaxpr(flat_fn, return_shape=True)(*leaves)  # one trace
        # the traced types, not the examples': without jax_enable_x64 a float64 example is float32
        self.in_avals = [Aval(v.aval.shape, v.aval.dtype) for v in closed.jaxpr.invars]
        self.out_avals = [Aval(v.aval.shape, v.aval.dtype) for v in closed.jaxpr.outvars]
        self.out_tree = jax.tree_util.tree_structure(out_shapes)
        self.source = self._translate(closed)
        self.library_path, library = cache.compile_and_load(self.source)
        self._function = library.fg_kernel
        self._function.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        self._function.restype = None
        self._library = library
        # checked once per library: when it is built, or loaded from a cache that never checked it
        if not cache.is_verified(self.library_path):
            self._verify(flat_fn, leaves)
            cache.mark_verified(self.library_path)

    def _verify(self, flat_fn, leaves) -> None:
        """Run the C function and XLA on the example inputs and a few random ones near them: a
        translation bug (or a primitive whose C semantics differ) must never silently change a
        model's dynamics, so a kernel that disagrees is refused and the caller takes XLA."""
        reference = jax.jit(flat_fn)
        rng = np.random.default_rng(0)
        for trial in range(1 + _VERIFY_TRIALS):
            inputs = [_trial_input(x, a, rng if trial else None) for x, a in zip(leaves, self.in_avals, strict=True)]
            _, got = self.new_buffers()
            self.bind(inputs, got)()
            want = [np.asarray(w) for w in jax.tree_util.tree_leaves(reference(*inputs))]
            for k, (g, w) in enumerate(zip(got, want, strict=True)):
                problem = _disagreement(g, w)
                if problem:
                    message = (
                        f"the C kernel {self.name!r} disagrees with XLA on output {k} "
                        f"({'example' if trial == 0 else 'random'} inputs, trial {trial}): "
                        f"{problem}; primitives translated: {', '.join(sorted(self.primitives))}. "
                        "Refusing it: XLA steps this model"
                    )
                    warnings.warn(message, CKernelWarning, stacklevel=3)
                    raise CKernelError(message)

    def _translate(self, closed) -> str:
        """The C source of the traced step (:func:`.translate.translate`)."""
        source, self.primitives = translate(closed)
        return source

    def new_buffers(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Fresh, zeroed input and output buffers with the kernel's shapes and dtypes."""
        ins = [np.zeros(a.shape, dtype=a.dtype) for a in self.in_avals]
        outs = [np.zeros(a.shape, dtype=a.dtype) for a in self.out_avals]
        return ins, outs

    def bind(self, inputs: Sequence[np.ndarray], outputs: Sequence[np.ndarray]) -> Callable[[], None]:
        """A zero-argument call reading ``inputs`` and writing ``outputs`` (fixed buffers)."""
        if len(inputs) != len(self.in_avals) or len(outputs) != len(self.out_avals):
            # C would read pointers past the arrays' ends for a missing buffer
            raise ValueError(
                f"{len(inputs)} input and {len(outputs)} output buffers; the kernel takes "
                f"{len(self.in_avals)} and {len(self.out_avals)}"
            )
        for k, (buf, aval) in enumerate(zip(inputs, self.in_avals, strict=True)):
            self._check(buf, aval, f"inputs[{k}]")
        for k, (buf, aval) in enumerate(zip(outputs, self.out_avals, strict=True)):
            self._check(buf, aval, f"outputs[{k}]")
        in_ptrs = (ctypes.c_void_p * max(len(inputs), 1))(*[b.ctypes.data for b in inputs])
        out_ptrs = (ctypes.c_void_p * max(len(outputs), 1))(*[b.ctypes.data for b in outputs])
        function = self._function
        keep = (list(inputs), list(outputs), in_ptrs, out_ptrs)  # the buffers must outlive the call

        def call(_keep=keep):
            function(in_ptrs, out_ptrs)

        return call

    @staticmethod
    def _check(buf, aval, what):
        if (
            not isinstance(buf, np.ndarray)
            or buf.shape != tuple(aval.shape)
            or buf.dtype != aval.dtype
            or not buf.flags.c_contiguous
        ):
            raise ValueError(
                f"{what}: expected a C-contiguous numpy array of shape {tuple(aval.shape)} "
                f"and dtype {aval.dtype}, got {getattr(buf, 'shape', type(buf))} "
                f"{getattr(buf, 'dtype', '')}"
            )

    def __call__(self, *args):
        """Convenience call (allocates; for tests and one-off use): same pytree as ``fn``."""
        leaves = jax.tree_util.tree_leaves(args)
        inputs = [
            np.ascontiguousarray(np.asarray(x, dtype=a.dtype).reshape(a.shape))
            for x, a in zip(leaves, self.in_avals, strict=True)
        ]
        _, outputs = self.new_buffers()
        self.bind(inputs, outputs)()
        return jax.tree_util.tree_unflatten(self.out_tree, outputs)
