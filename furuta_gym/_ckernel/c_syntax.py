"""What C the translation writes for a value or an operation: C types, exact literals, the
prelude of helper functions, and the C expression of each elementwise primitive."""

from __future__ import annotations

import math

import numpy as np

from .errors import CKernelTranslationError

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
