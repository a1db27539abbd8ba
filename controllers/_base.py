"""The controller protocol: a pure, jittable law plus a stateful Gymnasium-policy face.

A controller is an Equinox module (a pytree holding the design model and the gains) with

* ``init_state()`` → the controller's internal state (a pytree; ``()`` for memoryless laws),
* ``step(state, obs) -> (action, state)`` — pure and jittable, usable inside ``jax.lax.scan``
  and ``jax.vmap`` (a batched JAX env) and differentiable where the law is.

and, for plain Gymnasium loops, it is itself a policy: ``controller.reset()`` then
``action = controller(obs)`` returns an ``np.ndarray`` of shape ``(1,)`` (the motor voltage),
running the same jitted ``step`` and keeping the state on the Python side. Observations are
``(α, β, α̇, β̇)`` as the env returns them (β = 0 hanging, π upright; any unwrapped β works).
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = ["AbstractController", "wrap_angle"]


def wrap_angle(angle):
    """Angle wrapped to [−π, π)."""
    return jnp.mod(angle + jnp.pi, 2.0 * jnp.pi) - jnp.pi


class _Runtime:
    """Python-side state of a controller used as a policy (never part of the pytree)."""

    def __init__(self, controller: "AbstractController"):
        # a lambda, not the bound method: Equinox modules holding arrays are not hashable
        self.step = jax.jit(lambda state, obs: controller.step(state, obs))
        self.state = None


class AbstractController(eqx.Module):
    """Base of every controller: pure ``step(state, obs)``; callable as a Gymnasium policy."""

    @abc.abstractmethod
    def step(self, state: Any, obs: Float[Array, " 4"]) -> tuple[Float[Array, " 1"], Any]:
        """One control period: the voltage action (shape (1,)) and the next internal state."""

    def init_state(self) -> Any:
        """Internal state at the start of an episode (``()`` for a memoryless law)."""
        return ()

    def action(self, obs: Float[Array, " 4"]) -> Float[Array, " 1"]:
        """The action from the initial internal state: a memoryless ``obs -> action`` function."""
        return self.step(self.init_state(), obs)[0]

    # -- the stateful policy face (Python side) --------------------------------------------
    def _runtime(self) -> _Runtime:
        # plain object attribute access: Equinox's own __getattribute__ is slow on this per-step path
        rt = object.__getattribute__(self, "__dict__").get("_policy_runtime")
        if rt is None:
            rt = _Runtime(self)
            # Equinox modules are frozen; this attribute is deliberately not a pytree field, so
            # jit/vmap/tree_map never see it and copies start with a fresh policy state.
            object.__setattr__(self, "_policy_runtime", rt)
        return rt

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode (clears the switching mode, the first-push flag, ...)."""
        self._runtime().state = self.init_state()

    def __call__(self, obs) -> np.ndarray:
        """Gymnasium policy: observation (α, β, α̇, β̇) → voltage action, ``np.ndarray`` (1,)."""
        obs_arr = np.asarray(obs, dtype=np.float64)
        if obs_arr.shape != (4,):
            raise ValueError(
                f"obs must be the Furuta observation (alpha, beta, alpha_dot, beta_dot) of shape "
                f"(4,), got shape {obs_arr.shape}"
            )
        rt = object.__getattribute__(self, "__dict__").get("_policy_runtime") or self._runtime()
        if rt.state is None:
            rt.state = self.init_state()
        action, rt.state = rt.step(rt.state, obs_arr)  # NumPy in: no extra device_put call
        return np.asarray(action, dtype=np.float64).reshape(1)

    @property
    def policy_state(self) -> Any:
        """The internal state the Python policy currently holds (e.g. the switching mode)."""
        return self._runtime().state
