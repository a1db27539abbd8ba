"""A closed jaxpr written out as the body of one C function, primitive by primitive.

:func:`translate` is the entry point: it returns the C source of ``fg_kernel(ins, outs)`` and the
primitives it translated. A form it does not know is a :class:`CKernelTranslationError` naming it.

Here is the jaxpr walk (shared subexpressions, values folded by JAX, index-linear primitives);
the parts it stands on: :mod:`.c_syntax` (C types, literals, elementwise templates),
:mod:`.primitive_params` (the parameters each primitive may carry), :mod:`.c_writer` (the C
function being written) and one ``ops_*`` module per family of primitives.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from .c_syntax import _BINARY, _PRELUDE, _UNARY, _c_literal, _ctype
from .c_writer import Aval, _Var
from .errors import CKernelError, CKernelTranslationError
from .ops_control_flow import ControlFlowOps
from .ops_elementwise import ElementwiseOps
from .ops_reductions import ReductionOps
from .ops_structural import StructuralOps
from .primitive_params import _check_params

__all__ = ["translate", "MAX_STACK_BYTES", "Aval"]

#: the most stack one kernel call may use for its intermediates
MAX_STACK_BYTES = 1 << 20

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


class _Translator(ControlFlowOps, ReductionOps, StructuralOps, ElementwiseOps):
    """A jaxpr walked equation by equation into C; ``op_<primitive>`` methods come from the mixins."""

    # -- the jaxpr walk -----------------------------------------------------------------------
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
