"""The C a translation is written into: its values (:class:`_Var`, C arrays), and
:class:`CWriter`, which declares them, emits statements and loops, and copies values by index
runs. The primitives' translations (``ops_*``) are written on top of it."""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np
from jax.extend.core import Literal

from .c_syntax import _c_literal, _ctype


class Aval:
    def __init__(self, shape, dtype):
        self.shape, self.dtype = shape, dtype


# ---------------------------------------------------------------------------------------------
# Index bookkeeping: structural operations become copies by (arithmetic) index runs
# ---------------------------------------------------------------------------------------------


def _runs(sources: np.ndarray, indices: np.ndarray):
    """Split the output positions into runs (source, first index, first output, length, stride)
    whose source index is an arithmetic progression."""
    runs = []
    n = len(indices)
    start = 0
    while start < n:
        src, first = int(sources[start]), int(indices[start])
        end = start + 1
        stride = int(indices[end]) - first if end < n and sources[end] == src else 0
        while end < n and sources[end] == src and int(indices[end]) - int(indices[end - 1]) == stride:
            end += 1
        runs.append((src, first, start, end - start, stride))
        start = end
    return runs


def _progression(table: np.ndarray) -> tuple[int, int] | None:
    """(first, stride) when ``table`` is an arithmetic progression, else None."""
    table = np.asarray(table).ravel()
    if table.size <= 1:
        return (int(table[0]) if table.size else 0), 0
    d = np.diff(table)
    return (int(table[0]), int(d[0])) if np.all(d == d[0]) else None


def _linear_tables(shape: Sequence[int], dims: Sequence[int]) -> np.ndarray:
    """Flat offsets (row-major, in an array of ``shape``) of every multi-index over ``dims``,
    in row-major order of those dims."""
    strides = np.cumprod((tuple(shape[1:]) + (1,))[::-1])[::-1] if len(shape) else np.array([], int)
    offsets = np.zeros(1, dtype=np.int64)
    for d in dims:
        offsets = (offsets[:, None] + np.arange(shape[d])[None, :] * int(strides[d])).ravel()
    return offsets


class _Var:
    """A C array holding one jaxpr value: its C name, shape and dtype."""

    __slots__ = ("name", "shape", "dtype", "literal", "value")

    def __init__(self, name, shape, dtype, literal=None, value=None):
        self.name, self.shape, self.dtype, self.literal = name, tuple(shape), np.dtype(dtype), literal
        #: the value when known while translating (literals, constants, what follows from them)
        self.value = value

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    def at(self, index) -> str:
        """C expression of element ``index`` (an int or a C expression); a scalar broadcasts."""
        if self.literal is not None:
            return self.literal
        if self.size == 1:
            return f"{self.name}[0]"
        return f"{self.name}[{index}]"


class CWriter:
    """The C function being written: its lines, static tables and stack use. The translator
    (:class:`~.translate._Translator`) adds the jaxpr walk and one ``op_<primitive>`` method per
    translated primitive, from the ``ops_*`` mixins."""

    def __init__(self):
        self.lines: list[str] = []
        self.counter = 0
        self.static_arrays: list[str] = []
        self.indent = 1
        self.common: dict = {}
        self.stack_bytes = 0
        #: primitives translated to C (named when the kernel disagrees with XLA)
        self.primitives: set[str] = set()

    # -- emission helpers ---------------------------------------------------------------------
    def emit(self, line: str) -> None:
        self.lines.append("    " * self.indent + line)

    def fresh(self, aval) -> _Var:
        self.counter += 1
        var = _Var(f"v{self.counter}", aval.shape, aval.dtype)
        self.emit(f"{_ctype(var.dtype)} {var.name}[{max(var.size, 1)}];")
        self.stack_bytes += max(var.size, 1) * var.dtype.itemsize
        return var

    def alias(self, source: _Var, aval) -> _Var:
        """Same data, new shape (reshape, squeeze, expand_dims)."""
        if source.literal is not None:
            return _Var(source.name, aval.shape, aval.dtype, source.literal)
        self.counter += 1
        var = _Var(f"v{self.counter}", aval.shape, aval.dtype)
        self.emit(f"{_ctype(var.dtype)} *{var.name} = {source.name};")
        return var

    def table(self, values: np.ndarray) -> str:
        name = f"t{len(self.static_arrays)}"
        body = ", ".join(str(int(v)) for v in np.asarray(values).ravel())
        self.static_arrays.append(f"static const int {name}[{max(len(values), 1)}] = {{{body}}};")
        return name

    def loop(self, n: int, body: Callable[[str], str]) -> None:
        """``for i < n: body(i)``; unrolled when short."""
        if n <= 4:
            for i in range(n):
                self.emit(body(str(i)))
        else:
            self.counter += 1
            i = f"i{self.counter}"
            self.emit(f"for (int {i} = 0; {i} < {n}; ++{i}) {body(i)}")

    def copy_runs(self, out: _Var, inputs: Sequence[_Var], sources, indices, fill: _Var | None = None) -> None:
        """out[k] = inputs[sources[k]][indices[k]] (source -1: ``fill``), as runs of copies."""
        runs = _runs(np.asarray(sources), np.asarray(indices))
        if len(runs) > 32 and len(inputs) == 1 and fill is None:  # scattered: one table
            t = self.table(indices)
            self.loop(out.size, lambda i: f"{out.name}[{i}] = {inputs[0].at(f'{t}[{i}]')};")
            return
        for src, first, dst, length, stride in runs:
            source = fill if src < 0 else inputs[src]
            if length == 1:
                self.emit(f"{out.name}[{dst}] = {source.at(first)};")
            else:
                # loop calls the body at once; the defaults bind this run's values all the same
                self.loop(
                    length,
                    lambda i, dst=dst, source=source, first=first, stride=stride: (
                        f"{out.name}[{dst} + {i}] = {source.at(f'{first} + {stride} * {i}')};"
                    ),
                )

    # -- values of the jaxpr ------------------------------------------------------------------
    def read(self, env: dict, atom) -> _Var:

        if isinstance(atom, Literal):
            aval: Any = atom.aval  # a ShapedArray
            value = np.asarray(atom.val)
            value = value.astype(aval.dtype).reshape(aval.shape)
            if value.size != 1:
                return self.constant(value)
            return _Var("lit", aval.shape, aval.dtype, _c_literal(value.ravel()[0], aval.dtype), value=value)
        return env[atom]

    def constant(self, value) -> _Var:
        value = np.asarray(value)
        self.counter += 1
        name = f"c{self.counter}"
        body = ", ".join(_c_literal(v, value.dtype) for v in value.ravel()) or "0"
        self.static_arrays.append(f"static const {_ctype(value.dtype)} {name}[{max(value.size, 1)}] = {{{body}}};")
        return _Var(name, value.shape, value.dtype, value=value)

    # -- reading values by index ------------------------------------------------------------
    def broadcast_reader(self, x: _Var, shape) -> Callable[[str], str]:
        """Element i of ``x`` broadcast to ``shape`` (jaxpr elementwise operands may carry size-1
        dimensions against the result's)."""
        if x.size == 1 or tuple(x.shape) == tuple(shape):
            return x.at
        placed = (1,) * (len(shape) - len(x.shape)) + tuple(x.shape)
        table = np.broadcast_to(np.arange(x.size).reshape(placed), shape).ravel()
        prog = _progression(table)
        if prog is not None:
            return lambda i: x.at(f"{prog[0]} + {prog[1]} * {i}")
        name = self.table(table)
        return lambda i: x.at(f"{name}[{i}]")

    def _index_expr(self, offsets) -> Callable[[str], str]:
        """C expression of ``offsets[v]``: ``a + b * v`` for an arithmetic progression, else a table."""
        prog = _progression(offsets)
        if prog:
            return lambda v: f"{prog[0]} + {prog[1]} * {v}"
        name = self.table(offsets)
        return lambda v: f"{name}[{v}]"

    # -- copies -----------------------------------------------------------------------------
    def _copy_into(self, dst: _Var, src: _Var) -> None:
        self.loop(max(dst.size, 1), lambda i: f"{dst.name}[{i}] = {src.at(i)};")

    def _fresh_copies(self, values: Sequence[_Var]) -> list[_Var]:
        copies = []
        for value in values:
            copy = self.fresh(Aval(value.shape, value.dtype))
            self._copy_into(copy, value)
            copies.append(copy)
        return copies

    def closed(self, closed_jaxpr, args: Sequence[_Var]) -> list[_Var]:
        """The outputs of a closed jaxpr on ``args`` (the translator's jaxpr walk)."""
        raise NotImplementedError
