"""How furuta-gym switches on JAX's float64 mode.

The choice (documented in the README under "Float64"): importing furuta_gym never touches JAX's
global configuration. The physics, the losses and the fits need float64 (the integral residual
subtracts momenta that agree to 1e-7 relative; float32 would drown it), so every entry point that
builds JAX physics — constructing a model, a model-backed env, training, diagnosis, controller
design — calls :func:`ensure_x64`. If the user has not already enabled float64 (``JAX_ENABLE_X64=1``
or ``jax.config.update("jax_enable_x64", True)``), it switches it on *once*, at that moment, and
says so with a :class:`Float64Warning`. Users who want float32 elsewhere in their program can keep
their JAX code and ours apart, or silence the warning by enabling float64 themselves first.
"""

from __future__ import annotations

import warnings

import jax

__all__ = ["Float64Warning", "enable_x64", "ensure_x64"]


class Float64Warning(UserWarning):
    """Emitted once when furuta_gym switches JAX's global float64 flag on at first use."""


def enable_x64() -> None:
    """Switch on JAX float64 explicitly (silently). Call before creating any JAX arrays."""
    jax.config.update("jax_enable_x64", True)


def ensure_x64() -> None:
    """Make sure JAX computes in float64; switch it on with a one-time warning if it was off."""
    if jax.config.read("jax_enable_x64"):
        return
    warnings.warn(
        "furuta_gym switched on JAX's float64 mode (jax_enable_x64) because its physics runs in "
        "float64. Set JAX_ENABLE_X64=1 or call furuta_gym.enable_x64() before using JAX to "
        "make this explicit and silence this warning.",
        Float64Warning,
        stacklevel=3,
    )
    enable_x64()
