"""The parameters each translated JAX primitive may carry, and which of their values the
translation implements: any other is refused (XLA steps the model) rather than ignored."""

from __future__ import annotations

from .errors import CKernelTranslationError


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
