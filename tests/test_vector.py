"""Batched model-backed env and the pure-JAX rollout (issue 4, item 3).

Compiles are the cost here, so every jitted object is built once per module and reused.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym.envs._jax_rollout import controlled_step, rollout
from furuta_gym.lagrangian import AbstractLagrangianSystem, SystemSpec
from furuta_gym.models import NMSD, Furuta, NMSDParameters
from furuta_gym.simulate import rollout_zoh

DT = 0.002


def lqr_like(obs):
    """A jittable memoryless feedback that saturates the 5 V limit at times (clipping matters)."""
    return jnp.array([8.0 * jnp.sin(obs[1]) - 0.2 * obs[2] + 0.5 * obs[3]])


class CountingPolicy:
    """A stateful policy: the action ramps with the number of steps taken (tests the carry)."""

    def __call__(self, count, obs):
        return jnp.array([0.01 * count]), count + 1


class BlowUp(AbstractLagrangianSystem):
    """A "learned model" gone wrong: a softening cubic spring that explodes in finite time.

    Starting at rest at p = 0 it stays exactly there; anywhere else beyond ~1 m it reaches inf/NaN
    within a fraction of a second, the way an over-fitted network can.
    """

    spec: ClassVar[SystemSpec] = NMSD().spec

    def mass_matrix(self, q):
        return jnp.eye(1)

    def potential(self, q):
        return -25.0 * q[0] ** 4

    def nonconservative_force(self, q, qd):
        return jnp.zeros(1)

    def input_force(self, q, qd, u):
        return u[:1]


@pytest.fixture(scope="module")
def furuta_rollout():
    x0s = jnp.array(
        [[0.0, 0.05, 0.0, 0.0], [0.3, 3.0, -1.0, 0.5], [-0.2, 2.9, 2.0, -3.0]]
    )
    return x0s, rollout(Furuta(), lqr_like, x0s, 400, dt=DT, substeps=2, action_limit=5.0)


def test_rollout_replays_as_open_loop_zoh(furuta_rollout):
    """The scan/vmap rollout is the policy in closed loop with the env's clipping and ZOH RK4."""
    x0s, out = furuta_rollout
    assert out.states.shape == (3, 401, 4) and out.actions.shape == (3, 400, 1)
    # the policy saw the state of its own step and its action was clipped to ±5 V
    policy_u = jax.vmap(jax.vmap(lqr_like))(out.states[:, :-1])
    np.testing.assert_allclose(out.actions, jnp.clip(policy_u, -5.0, 5.0), rtol=0, atol=1e-12)
    assert np.max(np.abs(policy_u)) > 5.0  # clipping was exercised
    for k in range(3):
        xs = rollout_zoh(Furuta(), x0s[k], out.actions[k], DT, 2)
        np.testing.assert_allclose(out.states[k], xs, rtol=0, atol=1e-12)
    assert not out.done.any() and not out.diverged.any()


def test_rollout_single_state_and_stateful_policy():
    x0 = jnp.array([0.1, 0.0])
    out = rollout(NMSD(), CountingPolicy(), x0, 50, dt=0.01, policy_state=jnp.array(0.0))
    assert out.states.shape == (51, 2)
    np.testing.assert_allclose(out.actions[:, 0], 0.01 * np.arange(50), atol=1e-15)
    np.testing.assert_allclose(out.states, rollout_zoh(NMSD(), x0, out.actions, 0.01, 1), atol=1e-12)


def test_diverging_copy_is_frozen_flagged_and_isolated():
    """One copy of a blown-up model diverges; no NaN leaks and the other copies are untouched."""
    x0s = jnp.array([[0.0, 0.0], [2.0, 0.0], [0.0, 0.0]])
    zero = lambda obs: jnp.zeros(1)  # noqa: E731
    out = jax.tree_util.tree_map(np.asarray, rollout(BlowUp(), zero, x0s, 200, dt=0.01))
    assert np.all(np.isfinite(out.states)) and np.all(np.isfinite(out.rewards))
    assert out.diverged[1].sum() == 1 and not out.diverged[[0, 2]].any()
    t_div = int(np.argmax(out.diverged[1]))
    assert out.terminated[1, t_div] and out.done[1, t_div:].all() and not out.done[1, :t_div].any()
    # frozen at the last good state, which was already large (it was blowing up)
    assert np.all(out.states[1, t_div + 1 :] == out.states[1, t_div])
    assert abs(out.states[1, t_div, 0]) > 2.0
    np.testing.assert_array_equal(out.states[[0, 2]], 0.0)
    # the step function alone, on a NaN action, also freezes instead of propagating it
    step = controlled_step(NMSD(), jnp.array([0.1, 0.0]), jnp.array([jnp.nan]), dt=0.01)
    assert bool(step.diverged) and np.all(np.isfinite(step.state))
