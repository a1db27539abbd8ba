"""The translation of elementwise primitives: one C expression per output element."""

from __future__ import annotations

import numpy as np

from .c_syntax import _BINARY, _INT_BINARY, _UNARY, _ctype, _extremum, _saturating_cast
from .c_writer import CWriter, _Var
from .errors import CKernelTranslationError


class ElementwiseOps(CWriter):
    """Arithmetic, comparisons, casts, selects and rounding, element by element."""

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
