"""A closed jaxpr written out as the body of one C function, primitive by primitive.

:func:`translate` is the entry point: it returns the C source of ``fg_kernel(ins, outs)`` and the
primitives it translated. A form it does not know is a :class:`CKernelTranslationError` naming it.
"""

from __future__ import annotations

import contextlib
import math
from typing import Any, Callable, Sequence

import jax
import numpy as np
from jax.extend.core import Literal

from .errors import CKernelError, CKernelTranslationError

__all__ = ["translate", "MAX_STACK_BYTES"]


class Aval:
    def __init__(self, shape, dtype):
        self.shape, self.dtype = shape, dtype


#: the most stack one kernel call may use for its intermediates
MAX_STACK_BYTES = 1 << 20

# ---------------------------------------------------------------------------------------------
# C types and scalar formatting
# ---------------------------------------------------------------------------------------------

_C_TYPES = {
    "float64": "double",
    "float32": "float",
    "int64": "long long",
    "int32": "int",
    "int16": "short",
    "int8": "signed char",
    "uint64": "unsigned long long",
    "uint32": "unsigned int",
    "uint8": "unsigned char",
    "bool": "unsigned char",
}


def _ctype(dtype) -> str:
    name = np.dtype(dtype).name
    try:
        return _C_TYPES[name]
    except KeyError:
        raise CKernelTranslationError(f"dtype {name} has no C translation (known: {sorted(_C_TYPES)})") from None


def _c_literal(value, dtype) -> str:
    dtype = np.dtype(dtype)
    if dtype == np.bool_:
        return "1" if bool(value) else "0"
    if np.issubdtype(dtype, np.integer):
        value = int(value)
        if value == -(1 << 63):  # 9223372036854775808LL itself does not fit a long long
            return f"({_ctype(dtype)})(-9223372036854775807LL - 1)"
        return f"({_ctype(dtype)}){value}{'ULL' if value >= 1 << 63 else 'LL'}"
    v = float(value)
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
    # a hexadecimal literal is exact
    return f"({_ctype(dtype)}){v.hex()}"


_PRELUDE = r"""
#include <math.h>
#include <string.h>
/* max/min/sign as XLA computes them: a NaN operand gives NaN (C's fmax would drop it) */
static inline double fg_max(double a, double b) { return a != a ? a : (b != b ? b : (a > b ? a : b)); }
static inline double fg_min(double a, double b) { return a != a ? a : (b != b ? b : (a < b ? a : b)); }
/* sign(±0) is ±0 in XLA (the zero itself), as is a NaN */
static inline double fg_sign(double a) { return (a != a || a == 0) ? a : (a > 0 ? 1.0 : -1.0); }
static inline double fg_logistic(double a) { return 1.0 / (1.0 + exp(-a)); }
static inline double fg_rsqrt(double a) { return 1.0 / sqrt(a); }
static inline double fg_round_even(double a) { return nearbyint(a); }
static inline double fg_round_away(double a) { return round(a); }
"""

_UNARY = {
    "neg": "(-{0})",
    "exp": "exp({0})",
    "exp2": "exp2({0})",
    "expm1": "expm1({0})",
    "log": "log({0})",
    "log1p": "log1p({0})",
    "tanh": "tanh({0})",
    "sin": "sin({0})",
    "cos": "cos({0})",
    "tan": "tan({0})",
    "asin": "asin({0})",
    "acos": "acos({0})",
    "atan": "atan({0})",
    "sinh": "sinh({0})",
    "cosh": "cosh({0})",
    "asinh": "asinh({0})",
    "acosh": "acosh({0})",
    "atanh": "atanh({0})",
    "sqrt": "sqrt({0})",
    "rsqrt": "fg_rsqrt({0})",
    "cbrt": "cbrt({0})",
    "abs": "fabs({0})",
    "sign": "fg_sign({0})",
    "floor": "floor({0})",
    "ceil": "ceil({0})",
    "logistic": "fg_logistic({0})",
    "square": "(({0}) * ({0}))",
    "not": "(!{0})",
    "is_finite": "isfinite({0})",
    "erf": "erf({0})",
    "erfc": "erfc({0})",
    "lgamma": "lgamma({0})",
    "copy": "{0}",
    "stop_gradient": "{0}",
    "copy_p": "{0}",
    "real": "{0}",
}

_BINARY = {
    "add": "({0} + {1})",
    "add_any": "({0} + {1})",
    "sub": "({0} - {1})",
    "mul": "({0} * {1})",
    "div": "({0} / {1})",
    "rem": "fmod({0}, {1})",
    "pow": "pow({0}, {1})",
    "atan2": "atan2({0}, {1})",
    "max": "fg_max({0}, {1})",
    "min": "fg_min({0}, {1})",
    "nextafter": "nextafter({0}, {1})",
    "eq": "({0} == {1})",
    "ne": "({0} != {1})",
    "lt": "({0} < {1})",
    "le": "({0} <= {1})",
    "gt": "({0} > {1})",
    "ge": "({0} >= {1})",
    "and": "({0} && {1})",
    "or": "({0} || {1})",
    "xor": "(!!({0}) ^ !!({1}))",
}

_INT_BINARY = {"and": "({0} & {1})", "or": "({0} | {1})", "xor": "({0} ^ {1})", "not": "(~{0})"}


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


# ---------------------------------------------------------------------------------------------
# The translator
# ---------------------------------------------------------------------------------------------

#: primitives holding sub-programs: translated afresh each time (their insides are shared)
_CALLS = frozenset(
    {
        "scan",
        "while",
        "cond",
        "jit",
        "pjit",
        "closed_call",
        "custom_jvp_call",
        "custom_vjp_call",
        "custom_vjp_call_jaxpr",
    }
)


#: primitives linear in their data operands once their index operands are known:
#: name -> the index operands' positions (given the number of operands)
_LINEAR_WITH_INDICES = {
    "gather": lambda n: (1,),
    "scatter": lambda n: (1,),
    "scatter-add": lambda n: (1,),
    "scatter_add": lambda n: (1,),
    "dynamic_slice": lambda n: tuple(range(1, n)),
    "dynamic_update_slice": lambda n: tuple(range(2, n)),
}


def _any(value) -> bool:
    return True


def _is_none(value) -> bool:
    return value is None


def _is_false(value) -> bool:
    return value is False or value == 0


#: the parameters each translated primitive may carry, and which of their values the
#: translation implements; any other parameter or value is refused (XLA steps the model)
#: rather than silently ignored. A primitive not listed may carry no parameter at all.
_ACCURACY = {"accuracy": _is_none}  # None: the default (libm-accurate) implementation
_JAXPR_CALL = dict.fromkeys(
    (
        "jaxpr",
        "name",
        "in_shardings",
        "out_shardings",
        "in_layouts",
        "out_layouts",
        "donated_invars",
        "ctx_mesh",
        "keep_unused",
        "inline",
        "compiler_options_kvs",
    ),
    _any,
)
_CUSTOM_CALL = dict.fromkeys(
    (
        "call_jaxpr",
        "fun_jaxpr",
        "jvp_jaxpr_fun",
        "jvp_jaxpr_thunk",
        "fwd_jaxpr_thunk",
        "bwd",
        "num_consts",
        "out_trees",
        "symbolic_zeros",
    ),
    _any,
)
_REDUCE = {"axes": _any, "out_sharding": _is_none}
_PARAMS = {
    **{
        n: _ACCURACY
        for n in (
            "exp",
            "exp2",
            "expm1",
            "log",
            "log1p",
            "tanh",
            "sin",
            "cos",
            "tan",
            "sqrt",
            "rsqrt",
            "cbrt",
            "logistic",
        )
    },
    **{n: {"out_dtype": _is_none} for n in ("add", "sub", "mul", "div")},
    "integer_pow": {"y": _any},
    "convert_element_type": {"new_dtype": _any, "weak_type": _any, "sharding": _is_none},
    "round": {"rounding_method": _any},
    "reduce_precision": {"exponent_bits": _any, "mantissa_bits": _any},  # checked by the handler
    "reshape": {"new_sizes": _any, "dimensions": _is_none, "sharding": _is_none},
    "squeeze": {"dimensions": _any},
    "expand_dims": {"dimensions": _any},
    "slice": {"start_indices": _any, "limit_indices": _any, "strides": _any},
    "broadcast_in_dim": {"shape": _any, "broadcast_dimensions": _any, "sharding": _is_none},
    "transpose": {"permutation": _any},
    "rev": {"dimensions": _any},
    "concatenate": {"dimension": _any},
    "stack": {"axis": _any},
    "unstack": {"axis": _any},
    "split": {"sizes": _any, "axis": _any},
    "pad": {"padding_config": _any},
    **{n: _REDUCE for n in ("reduce_sum", "reduce_max", "reduce_min", "reduce_prod")},
    **{n: {"axis": _any, "reverse": _any} for n in ("cumsum", "cumprod", "cummax", "cummin")},
    # precision only selects among float32-on-accelerator algorithms; the CPU computes exactly
    "dot_general": {
        "dimension_numbers": _any,
        "precision": _any,
        "preferred_element_type": _any,
        "out_sharding": _is_none,
    },
    "pjit": _JAXPR_CALL,
    "jit": _JAXPR_CALL,
    "closed_call": {"call_jaxpr": _any},
    "custom_jvp_call": _CUSTOM_CALL,
    "custom_vjp_call": _CUSTOM_CALL,
    "custom_vjp_call_jaxpr": _CUSTOM_CALL,
    "scan": {
        "jaxpr": _any,
        "length": _any,
        "reverse": _any,
        "num_consts": _any,
        "num_carry": _any,
        "linear": _any,
        "unroll": _any,
        "_split_transpose": _is_false,
    },
    "while": {"cond_jaxpr": _any, "body_jaxpr": _any, "cond_nconsts": _any, "body_nconsts": _any},
    "cond": {"branches": _any, "linear": _any},
}


def _check_params(name: str, params: dict) -> None:
    allowed = _PARAMS.get(name, {})
    for key, value in params.items():
        accepts = allowed.get(key)
        if accepts is None or not accepts(value):
            raise CKernelTranslationError(
                f"the C kernel does not implement {name!r} with {key}={value!r}; use the XLA kernel for this model"
            )


def _extremum(which: str, dtype) -> tuple[str, str]:
    """(combine template, initial value) of a max/min reduction in ``dtype``: integers compare
    as integers (through a double, int64 above 2**53 would round), floats propagate NaN."""
    dtype = np.dtype(dtype)
    if np.issubdtype(dtype, np.floating):
        return (f"fg_{which}({{0}}, {{1}})", "-INFINITY" if which == "max" else "INFINITY")
    op = ">" if which == "max" else "<"
    if dtype == np.bool_:
        init = "0" if which == "max" else "1"
    else:
        info = np.iinfo(dtype)
        init = _c_literal(info.min if which == "max" else info.max, dtype)
    return f"({{0}} {op} {{1}} ? {{0}} : {{1}})", init


def _saturating_cast(value: str, dtype) -> str:
    """float → integer as XLA converts: NaN gives 0, out of range the nearest limit (C leaves
    both undefined). Bounds are powers of two, exact in either float type."""
    info = np.iinfo(dtype)
    upper = float(info.max) + 1.0  # 2**bits (unsigned) or 2**(bits-1): the first value too large
    return (
        f"({value} != {value} ? {_c_literal(0, dtype)} : {value} >= {upper.hex()} ? "
        f"{_c_literal(info.max, dtype)} : {value} < {float(info.min).hex()} ? {_c_literal(info.min, dtype)} "
        f": ({_ctype(dtype)}){value})"
    )


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


class _Translator:
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

    # -- the jaxpr walk -----------------------------------------------------------------------
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

    def jaxpr(self, jaxpr, consts: Sequence[_Var], args: Sequence[_Var]) -> list[_Var]:
        env = {}
        for v, c in zip(jaxpr.constvars, consts, strict=True):
            env[v] = c
        for v, a in zip(jaxpr.invars, args, strict=True):
            env[v] = a
        for eqn in jaxpr.eqns:
            ins = [self.read(env, a) for a in eqn.invars]
            outs = self.equation(eqn, ins)
            for v, o in zip(eqn.outvars, outs, strict=True):
                env[v] = o
        return [self.read(env, a) for a in jaxpr.outvars]

    def closed(self, closed_jaxpr, args: Sequence[_Var]) -> list[_Var]:
        consts = [self.constant(c) for c in closed_jaxpr.consts]
        return self.jaxpr(closed_jaxpr.jaxpr, consts, args)

    def equation(self, eqn, ins: list[_Var]) -> list[_Var]:
        name = eqn.primitive.name
        p = eqn.params
        avals = [v.aval for v in eqn.outvars]
        # common subexpressions: autodiff repeats work (the mass network runs for M, for its
        # derivative and again in every RK4 stage's pieces); XLA merges the copies, so must we
        key = None
        if name not in _CALLS:
            key = (name, tuple((x.name, x.literal, x.shape) for x in ins), repr(sorted(p.items())))
            if key in self.common:
                return self.common[key]
        if name not in _CALLS and all(x.value is not None for x in ins):
            outs = self._fold(eqn, ins)  # known at translation time: computed once, by JAX
        elif name in _LINEAR_WITH_INDICES:
            outs = [self._linear_map(eqn, ins)]
        else:
            outs = self._translate_equation(name, p, ins, avals, eqn)
        if key is not None:
            self.common[key] = outs
        return outs

    def _fold(self, eqn, ins) -> list[_Var]:
        results = eqn.primitive.bind(*(x.value for x in ins), **eqn.params)
        if not eqn.primitive.multiple_results:
            results = [results]
        return [self.constant(np.asarray(r)) for r in results]

    def _linear_map(self, eqn, ins) -> _Var:
        """gather / scatter / dynamic slices with indices known here: linear in the other
        operands, so the result is ``Σ_i J_i · x_i`` with JAX's own (0/1) Jacobians J_i,
        written out element by element."""
        index_args = _LINEAR_WITH_INDICES[eqn.primitive.name]
        known = {k: ins[k].value for k in index_args(len(ins))}
        missing = [k for k, v in known.items() if v is None]
        if missing:
            raise CKernelTranslationError(
                f"the C kernel translates {eqn.primitive.name!r} only with indices known before "
                f"the step runs (here they are computed in it); use the XLA kernel for this model"
            )
        linear = [k for k in range(len(ins)) if k not in known]
        aval = eqn.outvars[0].aval
        size = int(np.prod(aval.shape, dtype=np.int64))
        if size * sum(ins[k].size for k in linear) > 1 << 22:
            raise CKernelError(f"{eqn.primitive.name!r} on {aval.shape}: too large to write out")

        def apply(*operands):
            args = list(operands)
            for k, v in known.items():
                args.insert(k, v)
            return eqn.primitive.bind(*args, **eqn.params)

        zeros = [np.zeros(ins[k].shape, ins[k].dtype) for k in linear]
        jacobians = jax.jacfwd(apply, argnums=tuple(range(len(linear))))(*zeros)
        offset = np.asarray(apply(*zeros)).ravel()
        out = self.fresh(aval)
        rows = [np.asarray(j).reshape(size, -1) for j in jacobians]
        for o in range(size):
            terms = [] if offset[o] == 0 else [_c_literal(offset[o], aval.dtype)]
            for k, row in zip(linear, rows, strict=True):
                for j in np.flatnonzero(row[o]):
                    c = row[o, j]
                    terms.append(ins[k].at(int(j)) if c == 1 else f"{_c_literal(c, aval.dtype)} * {ins[k].at(int(j))}")
            self.emit(f"{out.name}[{o}] = {' + '.join(terms) or '0'};")
        return out

    def _translate_equation(self, name, p, ins, avals, eqn) -> list[_Var]:
        self.primitives.add(name)
        _check_params(name, p)
        handler = getattr(self, f"op_{name}", None)
        if handler is not None:
            return handler(ins, avals, **p)
        if name in _UNARY or name in _BINARY:
            return [self.elementwise(name, ins, avals[0])]
        raise CKernelTranslationError(
            f"the C kernel has no translation of the JAX primitive {name!r} "
            f"(used as {eqn}); use the XLA kernel for this model"
        )

    # -- elementwise --------------------------------------------------------------------------
    def elementwise(self, name: str, ins: list[_Var], aval) -> _Var:
        out = self.fresh(aval)
        integer = np.issubdtype(out.dtype, np.integer) or (
            name in _INT_BINARY and np.issubdtype(ins[0].dtype, np.integer)
        )
        if integer and name in _INT_BINARY:
            template = _INT_BINARY[name]
        elif name in _UNARY:
            template = _UNARY[name]
        else:
            template = _BINARY[name]
        if name == "nextafter" and out.dtype == np.float32:
            template = "nextafterf({0}, {1})"  # the float32 neighbour, not the double one rounded
        if name in ("max", "min") and integer:
            template = "({0} > {1} ? {0} : {1})" if name == "max" else "({0} < {1} ? {0} : {1})"
        if name in ("div", "rem") and integer:
            # C traps on a zero divisor where XLA returns a value: never risk the process
            raise CKernelTranslationError(
                f"integer {name} has no C translation (a zero divisor would trap); use the XLA kernel for this model"
            )
        operands = [self.broadcast_reader(x, out.shape) for x in ins]
        self.loop(out.size, lambda i: f"{out.name}[{i}] = {template.format(*(read(i) for read in operands))};")
        return out

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

    def op_integer_pow(self, ins, avals, y):
        out = self.fresh(avals[0])
        x = ins[0]

        def power(i):
            e = x.at(i)
            if y == 0:
                return "1.0"
            term = " * ".join([f"({e})"] * abs(int(y)))
            return f"(1.0 / ({term}))" if y < 0 else f"({term})"

        self.loop(out.size, lambda i: f"{out.name}[{i}] = {power(i)};")
        return [out]

    def op_convert_element_type(self, ins, avals, new_dtype, **_):
        out = self.fresh(avals[0])
        cast = _ctype(new_dtype)
        if np.dtype(new_dtype) == np.bool_:
            self.loop(out.size, lambda i: f"{out.name}[{i}] = ({ins[0].at(i)} != 0);")
        elif np.issubdtype(new_dtype, np.integer) and np.issubdtype(ins[0].dtype, np.floating):
            self.loop(out.size, lambda i: f"{out.name}[{i}] = {_saturating_cast(ins[0].at(i), new_dtype)};")
        else:
            self.loop(out.size, lambda i: f"{out.name}[{i}] = ({cast}){ins[0].at(i)};")
        return [out]

    def op_reduce_precision(self, ins, avals, exponent_bits, mantissa_bits):
        info = np.finfo(ins[0].dtype)
        if exponent_bits < info.nexp or mantissa_bits < info.nmant:
            # rounding to a narrower format (bfloat16-like) is not implemented bit-exactly
            raise CKernelTranslationError(
                f"the C kernel does not implement 'reduce_precision' to "
                f"{exponent_bits} exponent / {mantissa_bits} mantissa bits on "
                f"{ins[0].dtype}; use the XLA kernel for this model"
            )
        return [ins[0]]  # as wide as the type: exactly the identity

    def op_optimization_barrier(self, ins, avals):
        return list(ins)  # several operands, passed through (C has no reordering to prevent)

    def op_select_n(self, ins, avals):
        out = self.fresh(avals[0])
        which, *cases = [self.broadcast_reader(x, out.shape) for x in ins]

        def pick(i):
            if len(cases) == 2:
                return f"({which(i)} ? {cases[1](i)} : {cases[0](i)})"
            expr = cases[-1](i)
            for k in range(len(cases) - 2, -1, -1):
                expr = f"({which(i)} == {k} ? {cases[k](i)} : {expr})"
            return expr

        self.loop(out.size, lambda i: f"{out.name}[{i}] = {pick(i)};")
        return [out]

    def op_clamp(self, ins, avals):
        out = self.fresh(avals[0])
        lo, x, hi = [self.broadcast_reader(v, out.shape) for v in ins]
        upper, lower = _extremum("max", out.dtype)[0], _extremum("min", out.dtype)[0]
        self.loop(out.size, lambda i: f"{out.name}[{i}] = {lower.format(upper.format(x(i), lo(i)), hi(i))};")
        return [out]

    def op_round(self, ins, avals, rounding_method, **_):
        out = self.fresh(avals[0])
        f = "fg_round_even" if int(rounding_method) == 1 else "fg_round_away"
        self.loop(out.size, lambda i: f"{out.name}[{i}] = {f}({ins[0].at(i)});")
        return [out]

    # -- structural: aliases and index-run copies ---------------------------------------------
    def op_reshape(self, ins, avals, dimensions=None, **_):
        if dimensions is not None:
            raise CKernelTranslationError("reshape with 'dimensions' has no C translation")
        return [self.alias(ins[0], avals[0])]

    def op_squeeze(self, ins, avals, **_):
        return [self.alias(ins[0], avals[0])]

    def op_expand_dims(self, ins, avals, **_):
        return [self.alias(ins[0], avals[0])]

    def _gather_by_numpy(self, ins, aval, indexer, fill=None):
        """Copy ``out = indexer(arange inputs)``: numpy applies the structural op to index arrays
        (input k's flat index + its offset), which gives every output's source."""
        sizes = [max(x.size, 1) for x in ins]
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        labelled = [np.arange(offsets[k], offsets[k + 1]).reshape(x.shape) for k, x in enumerate(ins)]
        flat = np.asarray(indexer(*labelled)).ravel()
        sources = np.searchsorted(offsets, flat, side="right") - 1
        sources = np.where(flat < 0, -1, sources)
        indices = np.where(flat < 0, 0, flat - offsets[np.clip(sources, 0, None)])
        out = self.fresh(aval)
        self.copy_runs(out, ins, sources, indices, fill)
        return out

    def op_slice(self, ins, avals, start_indices, limit_indices, strides=None):
        strides = strides or (1,) * len(start_indices)
        sl = tuple(slice(a, b, s) for a, b, s in zip(start_indices, limit_indices, strides, strict=True))
        return [self._gather_by_numpy(ins, avals[0], lambda a: a[sl])]

    def op_broadcast_in_dim(self, ins, avals, shape, broadcast_dimensions, **_):
        def bcast(a):
            placed = [1] * len(shape)  # operand dim i sits at output dim broadcast_dimensions[i]
            for i, d in enumerate(broadcast_dimensions):
                placed[d] = a.shape[i]
            return np.broadcast_to(a.reshape(placed), shape)

        return [self._gather_by_numpy(ins[:1], avals[0], bcast)]

    def op_transpose(self, ins, avals, permutation):
        return [self._gather_by_numpy(ins, avals[0], lambda a: np.transpose(a, permutation))]

    def op_rev(self, ins, avals, dimensions):
        return [self._gather_by_numpy(ins, avals[0], lambda a: np.flip(a, dimensions))]

    def op_concatenate(self, ins, avals, dimension):
        return [self._gather_by_numpy(ins, avals[0], lambda *a: np.concatenate(a, axis=dimension))]

    def op_stack(self, ins, avals, axis):
        return [self._gather_by_numpy(ins, avals[0], lambda *a: np.stack(a, axis=axis))]

    def op_unstack(self, ins, avals, axis):
        return [
            self._gather_by_numpy(ins, aval, lambda a, k=k: np.take(a, k, axis=axis)) for k, aval in enumerate(avals)
        ]

    def op_split(self, ins, avals, sizes, axis):
        bounds = np.cumsum((0,) + tuple(sizes))
        return [
            self._gather_by_numpy(ins, aval, lambda a, k=k: np.take(a, np.arange(bounds[k], bounds[k + 1]), axis=axis))
            for k, aval in enumerate(avals)
        ]

    def op_pad(self, ins, avals, padding_config):
        operand, fill = ins

        def pad(a):
            if any(int(i) < 0 for _, _, i in padding_config):
                raise CKernelTranslationError("pad with negative interior padding has no C translation")
            shape = list(a.shape)
            for d, (lo, hi, interior) in enumerate(padding_config):
                lo, hi, interior = int(lo), int(hi), int(interior)
                n = shape[d]
                dilated = n + max(n - 1, 0) * interior
                full = np.full(a.shape[:d] + (dilated,) + a.shape[d + 1 :], -1, dtype=np.int64)
                idx = [slice(None)] * a.ndim
                idx[d] = slice(0, dilated, interior + 1)
                full[tuple(idx)] = a
                # negative lo/hi crop
                pads = [(0, 0)] * a.ndim
                pads[d] = (max(lo, 0), max(hi, 0))
                full = np.pad(full, pads, constant_values=-1)
                crop = [slice(None)] * a.ndim
                crop[d] = slice(max(-lo, 0), full.shape[d] - max(-hi, 0))
                a = full[tuple(crop)]
                shape[d] = a.shape[d]
            return a

        return [self._gather_by_numpy([operand], avals[0], pad, fill=fill)]

    # -- reductions and products --------------------------------------------------------------
    def _index_expr(self, offsets) -> Callable[[str], str]:
        """C expression of ``offsets[v]``: ``a + b * v`` for an arithmetic progression, else a table."""
        prog = _progression(offsets)
        if prog:
            return lambda v: f"{prog[0]} + {prog[1]} * {v}"
        name = self.table(offsets)
        return lambda v: f"{name}[{v}]"

    def _reduce(self, ins, avals, axes, combine: str, init: str):
        x = ins[0]
        out = self.fresh(avals[0])
        kept = [d for d in range(len(x.shape)) if d not in axes]
        outer = _linear_tables(x.shape, kept)
        inner = _linear_tables(x.shape, sorted(axes))
        o_expr, i_expr = self._index_expr(outer), self._index_expr(inner)
        self.counter += 1
        o, r = f"o{self.counter}", f"r{self.counter}"
        acc = f"{_ctype(out.dtype)} acc = {init};"
        step = combine.format("acc", x.at(f"{o_expr(o)} + {i_expr(r)}"))
        self.emit(
            f"for (int {o} = 0; {o} < {len(outer)}; ++{o}) {{ {acc} "
            f"for (int {r} = 0; {r} < {len(inner)}; ++{r}) acc = {step}; {out.name}[{o}] = acc; }}"
        )
        return [out]

    def op_reduce_sum(self, ins, avals, axes, **_):
        return self._reduce(ins, avals, axes, "({0} + {1})", "0")

    def op_reduce_max(self, ins, avals, axes, **_):
        return self._reduce(ins, avals, axes, *_extremum("max", avals[0].dtype))

    def op_reduce_min(self, ins, avals, axes, **_):
        return self._reduce(ins, avals, axes, *_extremum("min", avals[0].dtype))

    def op_reduce_prod(self, ins, avals, axes, **_):
        return self._reduce(ins, avals, axes, "({0} * {1})", "1")

    def _cumulative(self, ins, avals, axis, reverse, combine: str):
        x = ins[0]
        out = self.fresh(avals[0])
        outer = _linear_tables(x.shape, [d for d in range(len(x.shape)) if d != axis])
        stride = int(np.prod(x.shape[axis + 1 :], dtype=np.int64))
        n = x.shape[axis]
        self.counter += 1
        o, r = f"o{self.counter}", f"r{self.counter}"
        t = self.table(outer)
        position = f"{t}[{o}] + {stride} * ({n - 1} - {r})" if reverse else f"{t}[{o}] + {stride} * {r}"
        self.emit(
            f"for (int {o} = 0; {o} < {len(outer)}; ++{o}) for (int {r} = 0; {r} < {n}; ++{r}) "
            f"{out.name}[{position}] = {r} == 0 ? {x.at(position)} : "
            f"{combine.format(out.name + '[' + position + (' + ' if reverse else ' - ') + str(stride) + ']', x.at(position))};"
        )
        return [out]

    def op_cumsum(self, ins, avals, axis, reverse):
        return self._cumulative(ins, avals, axis, reverse, "({0} + {1})")

    def op_cumprod(self, ins, avals, axis, reverse):
        return self._cumulative(ins, avals, axis, reverse, "({0} * {1})")

    def op_cummax(self, ins, avals, axis, reverse):
        return self._cumulative(ins, avals, axis, reverse, _extremum("max", avals[0].dtype)[0])

    def op_cummin(self, ins, avals, axis, reverse):
        return self._cumulative(ins, avals, axis, reverse, _extremum("min", avals[0].dtype)[0])

    def op_dot_general(self, ins, avals, dimension_numbers, preferred_element_type=None, **_):
        (lc, rc), (lb, rb) = dimension_numbers
        lhs, rhs = ins
        if any(x.dtype != np.dtype(avals[0].dtype) for x in ins):
            # mixed types accumulate in a wider type in XLA; C would multiply in the narrow one
            raise CKernelTranslationError(
                f"the C kernel does not implement 'dot_general' of {lhs.dtype} x {rhs.dtype} "
                f"into {avals[0].dtype}; use the XLA kernel for this model"
            )
        out = self.fresh(avals[0])
        lfree = [d for d in range(len(lhs.shape)) if d not in lc and d not in lb]
        rfree = [d for d in range(len(rhs.shape)) if d not in rc and d not in rb]
        groups = {
            "lb": _linear_tables(lhs.shape, lb),
            "li": _linear_tables(lhs.shape, lfree),
            "lk": _linear_tables(lhs.shape, lc),
            "rb": _linear_tables(rhs.shape, rb),
            "rj": _linear_tables(rhs.shape, rfree),
            "rk": _linear_tables(rhs.shape, rc),
        }
        exprs = {}
        for key, t in groups.items():
            exprs[key] = self._index_expr(t)
        nb, ni, nj, nk = len(groups["lb"]), len(groups["li"]), len(groups["rj"]), len(groups["lk"])
        self.counter += 1
        b, i, j, k = (f"{c}{self.counter}" for c in "bijk")
        a_index = f"{exprs['lb'](b)} + {exprs['li'](i)} + {exprs['lk'](k)}"
        b_index = f"{exprs['rb'](b)} + {exprs['rj'](j)} + {exprs['rk'](k)}"
        o_index = f"({b} * {ni} + {i}) * {nj} + {j}"
        product = f"{lhs.at(a_index)} * {rhs.at(b_index)}"
        rj = _progression(groups["rj"])
        if nj > 1 and rj is not None and rj[1] == 1:
            # rows of rhs are contiguous along j: k outside, j innermost (independent outputs,
            # unit stride: the compiler vectorises it; each output still sums in k order)
            self.emit(f"for (int {b} = 0; {b} < {nb}; ++{b}) for (int {i} = 0; {i} < {ni}; ++{i}) {{")
            self.emit(f"    for (int {j} = 0; {j} < {nj}; ++{j}) {out.name}[{o_index}] = 0;")
            self.emit(
                f"    for (int {k} = 0; {k} < {nk}; ++{k}) for (int {j} = 0; {j} < {nj}; ++{j}) "
                f"{out.name}[{o_index}] += {product};"
            )
            self.emit("}")
        else:
            # a dot product per output; the reduction may be reassociated into SIMD lanes (the
            # result changes in the last bits, as XLA's own blocked sums do)
            self.emit(
                f"for (int {b} = 0; {b} < {nb}; ++{b}) for (int {i} = 0; {i} < {ni}; ++{i}) "
                f"for (int {j} = 0; {j} < {nj}; ++{j}) {{ {_ctype(out.dtype)} acc = 0;"
            )
            self.emit(
                f'    _Pragma("omp simd reduction(+:acc)") for (int {k} = 0; {k} < {nk}; ++{k}) acc += {product};'
            )
            self.emit(f"    {out.name}[{o_index}] = acc; }}")
        return [out]

    # -- calls and control flow ---------------------------------------------------------------
    def op_pjit(self, ins, avals, jaxpr, **_):
        return self.closed(jaxpr, ins)

    op_jit = op_pjit

    def op_closed_call(self, ins, avals, call_jaxpr, **_):
        return self.closed(call_jaxpr, ins)

    def op_custom_jvp_call(self, ins, avals, call_jaxpr, num_consts=0, **_):
        return self.closed(call_jaxpr, ins)

    def op_custom_vjp_call(self, ins, avals, call_jaxpr=None, fun_jaxpr=None, **_):
        return self.closed(call_jaxpr if call_jaxpr is not None else fun_jaxpr, ins)

    op_custom_vjp_call_jaxpr = op_custom_vjp_call

    def _copy_into(self, dst: _Var, src: _Var) -> None:
        self.loop(max(dst.size, 1), lambda i: f"{dst.name}[{i}] = {src.at(i)};")

    def _fresh_copies(self, values: Sequence[_Var]) -> list[_Var]:
        copies = []
        for value in values:
            copy = self.fresh(Aval(value.shape, value.dtype))
            self._copy_into(copy, value)
            copies.append(copy)
        return copies

    def _update_carry(self, carry: Sequence[_Var], new: Sequence[_Var]) -> None:
        """carry ← new, reading every new value before overwriting any (they may alias)."""
        for dst, src in zip(carry, self._fresh_copies(new), strict=True):
            self._copy_into(dst, src)

    @contextlib.contextmanager
    def _block(self, opening: str):
        """A C block: values made inside die with it, so they leave the shared-value table too."""
        self.emit(opening)
        self.indent += 1
        outer_common = dict(self.common)
        yield
        self.common = outer_common
        self.indent -= 1
        self.emit("}")

    def op_scan(self, ins, avals, jaxpr, length, reverse, num_consts, num_carry, **_):
        consts, init, xs = ins[:num_consts], ins[num_consts : num_consts + num_carry], ins[num_consts + num_carry :]
        carry = self._fresh_copies(init)
        ys = [self.fresh(aval) for aval in avals[num_carry:]]
        self.counter += 1
        it = f"it{self.counter}"
        index = f"({length - 1} - {it})" if reverse else it
        with self._block(f"for (int {it} = 0; {it} < {length}; ++{it}) {{"):
            self._scan_body(jaxpr, consts, carry, xs, ys, index, num_consts, num_carry)
        return carry + ys

    def _scan_body(self, jaxpr, consts, carry, xs, ys, index, num_consts, num_carry):
        x_slices = []
        for x, var in zip(xs, jaxpr.jaxpr.invars[num_consts + num_carry :], strict=True):
            self.counter += 1
            size = max(int(np.prod(var.aval.shape, dtype=np.int64)), 1)
            name = f"v{self.counter}"
            self.emit(f"{_ctype(x.dtype)} *{name} = {x.name} + {index} * {size};")
            x_slices.append(_Var(name, var.aval.shape, var.aval.dtype))
        outs = self.closed(jaxpr, list(consts) + carry + x_slices)
        self._update_carry(carry, outs[:num_carry])
        for dst, src in zip(ys, outs[num_carry:], strict=True):
            size = max(src.size, 1)
            self.loop(size, lambda i, d=dst, s=src, n=size: f"{d.name}[{index} * {n} + {i}] = {s.at(i)};")

    def op_while(self, ins, avals, cond_jaxpr, body_jaxpr, cond_nconsts, body_nconsts, **_):
        cconsts, bconsts, init = (
            ins[:cond_nconsts],
            ins[cond_nconsts : cond_nconsts + body_nconsts],
            ins[cond_nconsts + body_nconsts :],
        )
        carry = self._fresh_copies(init)
        with self._block("for (;;) {"):
            (go,) = self.closed(cond_jaxpr, list(cconsts) + carry)
            self.emit(f"if (!{go.at(0)}) break;")
            self._update_carry(carry, self.closed(body_jaxpr, list(bconsts) + carry))
        return carry

    def op_cond(self, ins, avals, branches, **_):
        index, operands = ins[0], ins[1:]
        outs = [self.fresh(aval) for aval in avals]
        for k, branch in enumerate(branches):
            keyword = "if" if k == 0 else "else if"
            test = f"({index.at(0)} <= {k})" if k < len(branches) - 1 else None
            with self._block(f"{keyword} {test} {{" if test else "else {"):
                for dst, src in zip(outs, self.closed(branch, operands), strict=True):
                    self._copy_into(dst, src)
        return outs


def translate(closed) -> tuple[str, set[str]]:
    """The C source of ``void fg_kernel(void *const *ins, void *const *outs)`` computing the closed
    jaxpr ``closed`` (inputs and outputs as flat buffers, in order), and the primitives it uses.

    A form the translation does not know is a :class:`CKernelTranslationError`, whatever JAX
    changed under it; a step too large for the stack is a :class:`CKernelError`.
    """
    try:
        return _translate(closed)
    except CKernelError:
        raise
    except Exception as exc:  # jaxpr internals this translation does not know (a newer JAX)
        raise CKernelTranslationError(
            f"the C kernel cannot translate this jaxpr ({type(exc).__name__}: {exc}); use the XLA kernel"
        ) from exc


def _translate(closed) -> tuple[str, set[str]]:
    t = _Translator()
    args = []
    for k, aval in enumerate(closed.jaxpr.invars):
        a = aval.aval
        args.append(_Var(f"in{k}", a.shape, a.dtype))
        t.emit(f"{_ctype(a.dtype)} *in{k} = ({_ctype(a.dtype)} *)ins[{k}];")
    # staged in fresh copies: an output buffer may be an input buffer
    results = t._fresh_copies(t.closed(closed, args))
    if t.stack_bytes > MAX_STACK_BYTES:
        # every intermediate lives on the calling thread's stack (reentrant, no allocation);
        # a thread's stack may be as small as 2 MiB. Models this large are compute-bound,
        # where XLA's fixed cost per call matters little.
        raise CKernelError(
            f"the step needs {t.stack_bytes / 2**20:.1f} MiB of intermediates (limit "
            f"{MAX_STACK_BYTES / 2**20:.0f} MiB on the stack); use the XLA kernel for this model"
        )
    for k, (res, var) in enumerate(zip(results, closed.jaxpr.outvars, strict=True)):
        ct = _ctype(var.aval.dtype)
        t.emit(f"{{ {ct} *o = ({ct} *)outs[{k}];")
        t.indent += 1
        t._copy_into(_Var("o", var.aval.shape, var.aval.dtype), res)
        t.indent -= 1
        t.emit("}")
    staged = "\n".join(t.lines)
    source = (
        _PRELUDE
        + "\n".join(t.static_arrays)
        + "\n"
        + "void fg_kernel(void *const *ins, void *const *outs) {\n"
        + staged
        + "\n}\n"
    )
    return source, t.primitives
