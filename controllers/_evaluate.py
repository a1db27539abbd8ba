"""Closed-loop evaluation of a controller on Gymnasium envs (any backend, any plant variant).

:func:`evaluate_on_env` runs one episode per initial state, all episodes in lock-step: one env per
start, and at every control period a single jitted, ``vmap``-ed call of the controller's pure
``step`` on the whole batch of observations (one JAX dispatch per period instead of one per env),
then each env's ``step``. Metrics use the env's true state (``info["state"]``) and the applied,
clipped voltage (``info["action"]``), so sensor options change what the controller sees, not
what is scored.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._base import AbstractController
from ._metrics import EpisodeMetrics, episode_metrics

__all__ = ["EpisodeRecord", "evaluate_on_env"]


@dataclasses.dataclass
class EpisodeRecord:
    """One evaluated episode: true states, applied voltages, controller modes and metrics."""

    x0: np.ndarray
    t: np.ndarray  # (T+1,) s
    xs: np.ndarray  # (T+1, 4) true states
    us: np.ndarray  # (T,) applied voltages
    modes: np.ndarray  # (T,) controller state (SwingUpLQR: 0 swing-up, 1 LQR), else zeros
    metrics: EpisodeMetrics


@eqx.filter_jit
def _batched_step(controller, states, obs):
    return jax.vmap(controller.step)(states, obs)


def evaluate_on_env(
    controller: AbstractController,
    make_env: Callable[[], Any],
    x0s: np.ndarray,
    seconds: float,
    seed: int = 0,
) -> list[EpisodeRecord]:
    """Run ``controller`` from every row of ``x0s`` (shape (N, 4)) for ``seconds`` on fresh envs
    from ``make_env()``; env ``i`` is reset with ``seed + i`` and ``options={"state": x0s[i]}``.
    An episode that terminates (divergence) stops there and is scored as diverged."""
    x0s = np.atleast_2d(np.asarray(x0s, dtype=float))
    if x0s.shape[1] != 4:
        raise ValueError(f"x0s must have shape (N, 4), got {x0s.shape}")
    n = x0s.shape[0]
    envs = [make_env() for _ in range(n)]
    try:
        dt = float(envs[0].unwrapped.dt)
        steps = int(round(seconds / dt))
        obs = np.empty((n, 4))
        xs = np.full((n, steps + 1, 4), np.nan)
        us = np.zeros((n, steps))
        modes = np.zeros((n, steps), dtype=int)
        live = np.ones(n, dtype=bool)
        ended = np.full(n, steps)
        for i, env in enumerate(envs):
            obs[i], info = env.reset(seed=seed + i, options={"state": x0s[i]})
            xs[i, 0] = info["state"]
        states = jax.vmap(lambda _: controller.init_state())(jnp.arange(n))
        for k in range(steps):
            actions, states = _batched_step(controller, states, jnp.asarray(obs))
            actions = np.asarray(actions, dtype=float)
            mode_k = np.asarray(states) if not isinstance(states, tuple) else np.zeros(n)
            for i in np.flatnonzero(live):
                o, _, terminated, truncated, info = envs[i].step(actions[i])
                obs[i] = o
                xs[i, k + 1] = info["state"]
                us[i, k] = float(np.asarray(info["action"]).reshape(-1)[0])
                modes[i, k] = int(mode_k[i])
                if terminated or info.get("diverged", False):
                    live[i] = False
                    ended[i] = k + 1
    finally:
        for env in envs:
            env.close()
    records = []
    for i in range(n):
        e = ended[i]
        x_i = xs[i, : e + 1]
        if e < steps:  # diverged: mark the trajectory as such for the metrics
            x_i = np.concatenate([x_i, np.full((1, 4), np.inf)])
        m = episode_metrics(x_i, us[i, :e], dt)
        records.append(EpisodeRecord(x0s[i], np.arange(e + 1) * dt, xs[i, : e + 1], us[i, :e], modes[i, :e], m))
    return records
