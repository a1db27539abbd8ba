"""PPO in one jit learns on the functional swing-up, and its policy runs on the Gymnasium env.

The learning test fails when learning is broken: a short run's deterministic policy must beat the
random policy's return by a margin. The margin was set from seeds 0-4 of this very configuration
(examples/ppo_swingup.py's settings, shortened), not from the seed the test runs.
"""

import gymnasium as gym
import jax
import numpy as np
import pytest

pytest.importorskip("gymnax")

import equinox as eqx

import furuta_gym  # noqa: F401  (registers the envs)
from furuta_gym.envs import functional
from furuta_gym.rl import GymnasiumPolicy, PPOSettings, episode_returns, train_ppo

SWINGUP = "furuta_gym/FurutaSwingUp-v0"
SHORT = PPOSettings(total_timesteps=196_608, num_envs=128, num_steps=128)
#: seeds 0-4 of SHORT, 32 evaluation episodes each: the random policy returns 14.6, the trained
#: deterministic policies 84-117 (5.8-8.0 times as much); the full example run returns 466
MARGIN = 4.0


def _random(obs, key):
    return jax.random.uniform(key, (1,), minval=-1.0, maxval=1.0)


@pytest.fixture(scope="module")
def trained():
    env, params = functional.make(SWINGUP)
    policy, metrics = eqx.filter_jit(lambda key: train_ppo(env, params, SHORT, key))(jax.random.PRNGKey(0))
    return env, params, policy, metrics


def test_a_short_ppo_run_beats_the_random_policy_by_a_margin(trained):
    env, params, policy, metrics = trained
    key = jax.random.PRNGKey(123)
    random_return = float(np.mean(episode_returns(env, params, _random, key, 32)))
    trained_return = float(np.mean(episode_returns(env, params, lambda obs, k: policy(obs), key, 32)))
    assert trained_return > MARGIN * random_return, (trained_return, random_return)
    assert np.all(np.isfinite(np.asarray(metrics["return"]))) and int(np.sum(metrics["episodes"])) > 0


def test_the_policy_runs_on_the_gymnasium_mujoco_env_through_the_adapter(trained):
    _, _, policy, _ = trained
    env = gym.make(SWINGUP)  # the MuJoCo ground truth
    act = GymnasiumPolicy(policy, env.action_space)
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        action = act(obs)
        assert action.dtype == env.action_space.dtype and env.action_space.contains(action)
        obs, reward, terminated, truncated, _ = env.step(action)
        assert 0.0 <= reward <= 1.0 and not terminated
    # the adapter returns the env's float32: equal to float32 precision on the action range [-1, 1]
    # (relative to a near-zero action alone, jit-vs-eager rounding of 2e-8 failed on a fresh clone)
    np.testing.assert_allclose(act(obs), np.asarray(policy(obs)), rtol=1e-6, atol=float(np.finfo(np.float32).eps))


def test_ppo_trains_on_a_gymnax_env_unchanged():
    gymnax = pytest.importorskip("gymnax")
    env, params = gymnax.make("Pendulum-v1")
    config = PPOSettings(total_timesteps=8192, num_envs=16, num_steps=64, num_minibatches=4)
    policy, metrics = eqx.filter_jit(lambda key: train_ppo(env, params, config, key))(jax.random.PRNGKey(0))
    obs, _ = env.reset(jax.random.PRNGKey(1), params)
    assert policy(obs).shape == (1,) and np.all(np.isfinite(np.asarray(metrics["return"])))
