"""Pickling an env: rebuilt from its settings objects, then its episode and its memory restored
(state, step count, random generator, task, and what the sensors and the actuator remember)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["episode_state", "restore_episode"]


def episode_state(env) -> dict[str, Any]:
    """What :func:`restore_episode` needs to continue ``env``'s episode in a rebuilt env."""
    actuator, lagged = env._actuator, getattr(env.backend, "lagged_input", None)
    if actuator is not None and actuator.lag is not None:
        lagged = actuator.lag.state.copy()
    return {
        "kwargs": env._init_kwargs,
        "x": env._x,
        "steps": env._steps,
        "diverged": env._diverged,
        "parameters": env.backend.parameters,
        "np_random": env._np_random,
        "task": env.task,
        "u": env._u,
        "last_obs": env._last_obs,
        "buffer": list(actuator.buffer) if env._has_delay else None,
        "lag": lagged,
        "filter_z": None if env._observer.filter is None else np.array(env._observer.filter._z),
    }


def restore_episode(env, state: dict[str, Any]) -> None:
    """Rebuild ``env`` from ``state["kwargs"]`` and continue the episode of :func:`episode_state`."""
    env.__init__(**state["kwargs"])
    env.task = state["task"]
    if state["parameters"] != env.backend.parameters:
        env.backend.set_parameters(state["parameters"])
        env._on_parameters(env.physical_parameters())
    env._reset_episode(state["x"])  # (may draw sensor noise: restore the RNG after it)
    env._np_random = state["np_random"]
    env._steps, env._diverged, env._u = state["steps"], state["diverged"], state["u"]
    env._last_obs = state["last_obs"]
    if state["buffer"] is not None:
        env._actuator.buffer.extend(state["buffer"])
    if state["lag"] is not None:
        if env._actuator is not None and env._actuator.lag is not None:
            env._actuator.lag.state = np.array(state["lag"], dtype=np.float64)
        elif getattr(env.backend, "lagged_input", None) is not None:
            env.backend.lagged_input = state["lag"]
    if state["filter_z"] is not None:
        env._observer.filter._z = np.array(state["filter_z"])
