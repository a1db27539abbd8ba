"""The translation of reductions, cumulative scans and dot products: loops over index tables."""

from __future__ import annotations

import numpy as np

from .c_syntax import _ctype, _extremum
from .c_writer import CWriter, _linear_tables, _progression
from .errors import CKernelTranslationError


class ReductionOps(CWriter):
    """Sums, products and extrema over axes, their cumulative forms, and ``dot_general``."""

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
