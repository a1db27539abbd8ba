"""Tasks, separate from physics (dm_control style): reward and termination as pure functions.

A task scores a transition ``(x, u, x_next)`` and says whether ``x_next`` ends the episode. The
functions are written once against a tiny array namespace so the *same* code runs on

* NumPy arrays and JAX arrays (including tracers inside ``jit``/``vmap``/``lax.scan``), with any
  leading batch shape (components are read as ``x[..., i]``), and
* plain Python sequences of floats (the single env's fast path: ``math`` instead of array calls).

The signature matches :data:`furuta_gym.envs._jax_rollout.RewardFn` (``reward(x, u, x_next)``) and
``TerminatedFn`` (``terminated(x_next)``), so a batched env passes ``task.reward`` and
``task.terminated`` as they are. Tasks are frozen dataclasses: hashable, so their bound methods are
valid static arguments of ``jax.jit`` / ``eqx.filter_jit`` and equal tasks share a compilation.

Every reward is a product of smooth factors in [0, 1] built from :func:`tolerance` (dm_control's
``rewards.tolerance`` with a Gaussian or quadratic sigmoid), so the reward is in [0, 1] with 1 only
at the goal.
"""

from __future__ import annotations

import dataclasses
import math
import types
from typing import Any

import jax.numpy as jnp
import numpy as np

__all__ = [
    "tolerance",
    "FurutaSwingUp",
    "NMSDReach",
    "DEFAULT_STATE_BOUND",
    "is_diverged",
    "divergence_bounds",
    "wrap_angle",
]

#: A state component beyond this magnitude (rad, rad/s, m, m/s) is "absurd": the episode ends
#: with ``info["diverged"] = True``. No physical run of either system comes near it.
DEFAULT_STATE_BOUND = 1e4

# The float fast path: the few functions the tasks use, on Python floats.
_SCALAR = types.SimpleNamespace(
    cos=math.cos, exp=math.exp, abs=abs, maximum=max, zeros_like=lambda x: 0.0, isscalar=True
)


def _namespace(x):
    """``math``-like namespace for sequences of floats, NumPy for ndarrays, else jax.numpy."""
    if isinstance(x, (list, tuple)):
        return _SCALAR
    if isinstance(x, np.ndarray):
        return np

    return jnp


def _components(x, n: int):
    if isinstance(x, (list, tuple)):
        return tuple(x[:n])
    return tuple(x[..., i] for i in range(n))


_GAUSS_SCALE_01 = math.sqrt(-2.0 * math.log(0.1))  # Gaussian reaching 0.1 at the margin


def tolerance(x, *, half_width: float = 0.0, margin: float, sigmoid: str = "gaussian", xp=None):
    """1 for |x| ≤ half_width, decaying smoothly outside over ``margin``.

    ``"gaussian"``: exp(−½(d·s)²) with d = (|x| − half_width)/margin and s chosen so the value is
    0.1 at d = 1 (never 0). ``"quadratic"``: max(1 − d², 0), exactly 0 beyond the margin.
    """
    xp = _namespace(x) if xp is None else xp
    d = xp.maximum(xp.abs(x) - half_width, 0.0 * x) / margin
    if sigmoid == "gaussian":
        return xp.exp(-0.5 * (d * _GAUSS_SCALE_01) ** 2)
    if sigmoid == "quadratic":
        return xp.maximum(1.0 - d * d, 0.0 * d)
    raise ValueError(f"sigmoid must be 'gaussian' or 'quadratic', got {sigmoid!r}")


def _never(x_next):
    xp = _namespace(x_next)
    if xp is _SCALAR:
        return False
    return xp.zeros(x_next.shape[:-1], dtype=bool)


def wrap_angle(angle):
    """``angle`` wrapped to (−π, π] (floats, NumPy and JAX arrays)."""
    return math.pi - (math.pi - angle) % (2.0 * math.pi)


def divergence_bounds(state_bound: float, angular) -> tuple[float, ...]:
    """Per-component bound of a state (q, q̇) for :func:`is_diverged`: ``inf`` for angular
    positions (a rotor may turn forever: only a non-finite angle is a divergence), ``state_bound``
    for the velocities and the other positions. ``angular``: one bool per joint."""
    bound = float(state_bound)
    return tuple(math.inf if a else bound for a in angular) + (bound,) * len(angular)


def is_diverged(x, state_bound: Any = DEFAULT_STATE_BOUND):
    """True when a state (float sequence or array, last axis = state) is non-finite or absurd.

    ``state_bound``: one magnitude for every component, or one per component (see
    :func:`divergence_bounds`, which leaves the angles unbounded)."""
    xp = _namespace(x)
    if xp is _SCALAR:
        bounds = state_bound if np.ndim(state_bound) else [state_bound] * len(x)
        return not all(math.isfinite(v) and abs(v) <= b for v, b in zip(x, bounds, strict=True))
    bound = xp.asarray(state_bound)
    return xp.logical_not(xp.all(xp.isfinite(x), axis=-1)) | xp.any(xp.abs(x) > bound, axis=-1)


@dataclasses.dataclass(frozen=True)
class FurutaSwingUp:
    """Swing the pendulum up and balance it, rotor near its start, little effort, little motion.

    reward = upright × centred × small_control × small_velocity, each in [0, 1]:

    * upright = (1 − cos β)/2: 0 hanging, 1 upright;
    * centred = (1 + tolerance(wrap(α), margin=``alpha_margin``))/2 ∈ [0.5, 1], on α wrapped to
      (−π, π] (2π-periodic: a rotor one turn away is as centred as at 0);
    * small_control = (4 + tolerance(u/max_voltage, margin=1, quadratic))/5 ∈ [0.8, 1];
    * small_velocity = (1 + tolerance(β̇, margin=``velocity_margin``))/2 ∈ [0.5, 1].

    Never terminates by itself (the episode ends on time or on divergence).
    """

    max_voltage: float = 5.0
    alpha_margin: float = math.pi / 2
    velocity_margin: float = 5.0
    state_bound: float = DEFAULT_STATE_BOUND

    def reward(self, x, u, x_next):
        """Reward of the transition to ``x_next`` = (α, β, α̇, β̇) under voltage ``u``."""
        xp = _namespace(x_next)
        alpha, beta, _, beta_dot = _components(x_next, 4)
        (volts,) = _components(u, 1)
        upright = 0.5 * (1.0 - xp.cos(beta))
        centred = 0.5 * (1.0 + tolerance(wrap_angle(alpha), margin=self.alpha_margin, xp=xp))
        small_control = 0.2 * (4.0 + tolerance(volts / self.max_voltage, margin=1.0, sigmoid="quadratic", xp=xp))
        small_velocity = 0.5 * (1.0 + tolerance(beta_dot, margin=self.velocity_margin, xp=xp))
        return upright * centred * small_control * small_velocity

    def terminated(self, x_next):
        """The task never ends an episode by itself."""
        return _never(x_next)


@dataclasses.dataclass(frozen=True)
class NMSDReach:
    """Drive the mass to ``target`` and hold it there with little force and little motion.

    reward = at_target × small_control × small_velocity, each in [0, 1]:

    * at_target = tolerance(p − target, half_width=``tolerance_width``, margin=``target_margin``);
    * small_control = (4 + tolerance(u/max_force, margin=1, quadratic))/5 ∈ [0.8, 1];
    * small_velocity = (1 + tolerance(ṗ, margin=``velocity_margin``))/2 ∈ [0.5, 1].

    Never terminates by itself.
    """

    target: float = 0.5
    max_force: float = 20.0
    tolerance_width: float = 0.02
    target_margin: float = 0.5
    velocity_margin: float = 1.0
    state_bound: float = DEFAULT_STATE_BOUND

    def reward(self, x, u, x_next):
        """Reward of the transition to ``x_next`` = (p, ṗ) under force ``u``."""
        xp = _namespace(x_next)
        p, p_dot = _components(x_next, 2)
        (force,) = _components(u, 1)
        at_target = tolerance(p - self.target, half_width=self.tolerance_width, margin=self.target_margin, xp=xp)
        small_control = 0.2 * (4.0 + tolerance(force / self.max_force, margin=1.0, sigmoid="quadratic", xp=xp))
        small_velocity = 0.5 * (1.0 + tolerance(p_dot, margin=self.velocity_margin, xp=xp))
        return at_target * small_control * small_velocity

    def terminated(self, x_next):
        """The task never ends an episode by itself."""
        return _never(x_next)
