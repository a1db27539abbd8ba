"""The translation of calls and control flow (jit, custom derivatives, scan, while, cond):
sub-jaxprs translated inline, loops and branches as C blocks."""

from __future__ import annotations

import contextlib
from typing import Sequence

import numpy as np

from .c_syntax import _ctype
from .c_writer import CWriter, _Var


class ControlFlowOps(CWriter):
    """Calls inlined; ``scan`` / ``while`` as C loops, ``cond`` as an if-chain."""

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
