"""The functional (gymnax) env is the Gymnasium env as pure JAX functions: the same state and
action give the same observation, reward and termination; quantisation, measurement noise and
domain randomisation come through its params; autoreset and truncation follow gymnax."""

import dataclasses
from pathlib import Path

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

pytest.importorskip("gymnax")

import furuta_gym  # noqa: F401  (registers the envs)
from furuta_gym.envs import EnvArgumentError, Plant, Sensors, Spaces, functional

SWINGUP = "furuta_gym/FurutaSwingUp-v0"
DELAN = Path(__file__).resolve().parents[1] / "results/reproduce/runs/furuta/dln_prop/seed0/model.eqx"


def _states_and_actions(count: int, seed: int = 0):
    """Hanging, mid-swing and near-upright states; actions inside and beyond [−1, 1]."""
    rng = np.random.default_rng(seed)
    xs = np.column_stack(
        [
            rng.uniform(-4, 4, count),
            rng.uniform(-np.pi, 2 * np.pi, count),
            rng.uniform(-8, 8, count),
            rng.uniform(-12, 12, count),
        ]
    )
    return xs, rng.uniform(-1.5, 1.5, (count, 1)).astype(np.float32)


def _assert_parity(env, params, gym_env, xs, actions, obs_atol=1e-6):
    step = jax.jit(env.step_env)
    key = jax.random.PRNGKey(0)
    for x, a in zip(xs, actions, strict=True):
        state = env.state_at(x, params)
        obs, new, reward, terminated, info = step(key, state, a, params)
        gym_env.reset(options={"state": x})
        gym_obs, gym_reward, gym_terminated, _, gym_info = gym_env.step(a)
        np.testing.assert_allclose(np.asarray(new.x), gym_info["state"], rtol=1e-11, atol=1e-11)
        assert obs.dtype == gym_obs.dtype and obs.shape == gym_obs.shape
        np.testing.assert_allclose(np.asarray(obs), gym_obs, rtol=0, atol=obs_atol)
        assert float(reward) == pytest.approx(gym_reward, rel=1e-10, abs=1e-12)
        assert bool(terminated) == gym_terminated and bool(info["diverged"]) == gym_info["diverged"]
        assert float(info["action"]) == pytest.approx(gym_info["action"], rel=1e-6)


def test_same_state_and_action_give_the_gymnasium_presets_observation_reward_and_termination():
    env, params = functional.make(SWINGUP, dynamics="analytic")
    gym_env = gym.make(SWINGUP, dynamics="analytic")
    _assert_parity(env, params, gym_env, *_states_and_actions(40))


def test_the_preset_spaces_and_horizon_are_the_gymnasium_envs():
    env, params = functional.make(SWINGUP)
    gym_env = gym.make(SWINGUP)
    obs_space, action_space = env.observation_space(params), env.action_space(params)
    assert obs_space.shape == gym_env.observation_space.shape == (6,)
    np.testing.assert_array_equal(np.asarray(obs_space.high), gym_env.observation_space.high)
    assert (action_space.low, action_space.high, action_space.shape) == (-1.0, 1.0, (1,))
    assert int(params.max_steps_in_episode) == gym_env.spec.max_episode_steps == 500


@pytest.mark.parametrize("plant", ["coulomb", "cable_spring"])
def test_plant_variants_match_the_gymnasium_env_with_the_same_plant(plant):
    env, params = functional.make(SWINGUP, plant=plant)
    _assert_parity(env, params, gym.make(SWINGUP, dynamics="analytic", plant=plant), *_states_and_actions(10, 1))


def test_a_learned_checkpoint_backend_matches_the_gymnasium_env_on_it():
    env, params = functional.make(SWINGUP, dynamics=str(DELAN))
    assert params.spreads is None  # a learned model has no physical parameters to randomise
    _assert_parity(env, params, gym.make(SWINGUP, dynamics=str(DELAN)), *_states_and_actions(5, 2))


@pytest.mark.parametrize("plant", [None, "coulomb"])
def test_the_analytic_model_steps_with_its_trig_shared(plant):
    """The step integrates the analytic Furuta as FurutaSharedTrig (the parity tests above check
    its numbers): compiled and vmapped, one sin β per RK4 stage plus the observation's sin α and
    sin β, where Furuta's own graph has XLA:CPU evaluate each in several kernels."""
    env, params = functional.make(SWINGUP, **({} if plant is None else {"plant": plant}))
    states = jax.vmap(lambda x: env.state_at(x, params))(jnp.zeros((8, 4)))
    step = jax.jit(jax.vmap(env.step_env, in_axes=(None, 0, 0, None)))
    text = step.lower(jax.random.PRNGKey(0), states, jnp.zeros((8, 1)), params).compile().as_text()
    if jax.default_backend() == "cpu":
        assert text.count(" sine(") <= 4 + 2


def test_nmsd_with_a_fixed_target_matches_its_gymnasium_env():
    env, params = functional.make("furuta_gym/NMSD-v0")
    gym_env = gym.make("furuta_gym/NMSD-v0", dynamics="analytic")
    rng = np.random.default_rng(3)
    xs, us = rng.uniform(-0.5, 0.5, (5, 2)), rng.uniform(-30, 30, (5, 1))
    _assert_parity(env, params, gym_env, xs, us)


def test_encoder_quantisation_matches_the_gymnasium_env_and_is_a_param():
    sensors = Sensors(encoder_counts=64)  # coarse, so a step visibly moves the observation
    env, params = functional.make(SWINGUP, sensors=sensors)
    step = 2 * np.pi / 64
    np.testing.assert_allclose(np.asarray(params.quantization), [step, step])
    _assert_parity(env, params, gym.make(SWINGUP, dynamics="analytic", sensors=sensors), *_states_and_actions(10, 4))

    # one compiled observation, two encoders: vmapped over params
    state = env.state_at([0.3, 2.0, 0.1, -0.2], params)
    both = jax.tree_util.tree_map(
        lambda *a: jnp.stack(a), params, dataclasses.replace(params, quantization=jnp.zeros(2))
    )
    obs = jax.vmap(lambda p: env.get_obs(state, p))(both)
    alpha_q, beta_q = np.round(0.3 / step) * step, np.round(2.0 / step) * step
    np.testing.assert_allclose(
        np.asarray(obs[0, :4]),
        np.float32([np.cos(alpha_q), np.sin(alpha_q), np.cos(beta_q), np.sin(beta_q)]),
        atol=1e-7,
    )
    np.testing.assert_allclose(
        np.asarray(obs[1, :4]), np.float32([np.cos(0.3), np.sin(0.3), np.cos(2.0), np.sin(2.0)]), atol=1e-7
    )


def test_measurement_noise_is_drawn_from_the_step_key_with_the_params_std():
    env, params = functional.make(
        SWINGUP, spaces=Spaces(observation="raw"), sensors=Sensors(measurement_noise=[0.0, 0.0, 0.5, 0.0])
    )
    state = env.state_at(np.zeros(4), params)
    keys = jax.random.split(jax.random.PRNGKey(1), 4000)
    obs = jax.vmap(lambda k: env.get_obs(state, params, k))(keys)
    assert np.all(np.asarray(obs[:, [0, 1, 3]]) == 0.0)
    assert np.std(np.asarray(obs[:, 2])) == pytest.approx(0.5, rel=0.05)
    assert functional.make(SWINGUP)[1].measurement_noise is None  # no noise: nothing drawn


def test_domain_randomisation_draws_physical_parameters_per_reset_and_steps_with_them():
    env, params = functional.make(SWINGUP, plant=Plant(randomize=0.2))
    nominal = env.plant(params).params
    states = jax.vmap(lambda k: env.reset(k, params)[1])(jax.random.split(jax.random.PRNGKey(0), 256))
    ratio = np.asarray(states.physical.Lp) / float(nominal.Lp)
    assert 0.8 <= ratio.min() < 0.85 and 1.15 < ratio.max() <= 1.2  # uniform in ±20 %
    assert np.all(np.asarray(states.physical.g) == float(nominal.g))  # g is left out by default
    # a step uses the episode's parameters: the Gymnasium env set to them agrees
    drawn = jax.tree_util.tree_map(lambda a: a[7], states.physical)
    state = dataclasses.replace(env.state_at([0.0, 3.0, 0.0, 0.5], params), physical=drawn)
    _, new, reward, _, _ = env.step_env(jax.random.PRNGKey(0), state, np.array([0.4], np.float32), params)
    gym_env = gym.make(SWINGUP, dynamics="analytic").unwrapped
    gym_env.backend.set_parameters({k: float(getattr(drawn, k)) for k in gym_env.physical_parameters()})
    gym_env.reset(options={"state": np.asarray(state.x)})
    _, gym_reward, _, _, info = gym_env.step(np.array([0.4], np.float32))
    np.testing.assert_allclose(np.asarray(new.x), info["state"], rtol=1e-11, atol=1e-11)
    # spreads are params: zero spreads give the nominal plant
    still = dataclasses.replace(params, spreads=jax.tree_util.tree_map(jnp.zeros_like, params.spreads))
    assert float(env.reset(jax.random.PRNGKey(3), still)[1].physical.Lp) == float(nominal.Lp)


def test_gymnax_step_truncates_at_the_horizon_and_autoresets():
    env, params = functional.make(SWINGUP)
    params = dataclasses.replace(params, max_steps_in_episode=jnp.asarray(20, jnp.int32))

    def body(carry, key):
        obs, state = carry
        obs, state, reward, terminated, truncated, info = env.step(key, state, jnp.array([1.0]), params)
        return (obs, state), (state.time, terminated, truncated, reward)

    init = env.reset(jax.random.PRNGKey(0), params)
    _, (time, terminated, truncated, reward) = jax.lax.scan(body, init, jax.random.split(jax.random.PRNGKey(1), 45))
    assert np.flatnonzero(np.asarray(truncated)).tolist() == [19, 39]
    assert not np.asarray(terminated).any()
    assert np.asarray(time)[[18, 19, 20]].tolist() == [19, 0, 1]  # reset in the step that ended it
    assert np.all((np.asarray(reward) >= 0) & (np.asarray(reward) <= 1))


def test_a_non_finite_action_ends_the_episode_as_a_divergence_without_nan():
    env, params = functional.make(SWINGUP)
    obs, state = env.reset(jax.random.PRNGKey(0), params)
    obs, new, reward, terminated, info = env.step_env(jax.random.PRNGKey(1), state, jnp.array([jnp.nan]), params)
    assert bool(terminated) and bool(info["diverged"]) and bool(env.is_terminated(new, params))
    assert np.all(np.isfinite(np.asarray(obs))) and np.isfinite(float(reward))
    np.testing.assert_array_equal(np.asarray(new.x), np.asarray(state.x))


@pytest.mark.parametrize(
    "kwargs, what",
    [
        (dict(dynamics="mujoco"), "mujoco"),
        (dict(sensors=Sensors(velocity="filter")), "filter"),
        (dict(plant="delay"), "delay"),
    ],
)
def test_what_needs_per_copy_python_state_is_refused_by_name(kwargs, what):
    with pytest.raises(EnvArgumentError, match=what):
        functional.make(SWINGUP, **kwargs)


def test_randomising_a_learned_model_is_refused():
    with pytest.raises((EnvArgumentError, ValueError), match="randomi|parameters"):
        functional.make(SWINGUP, dynamics=str(DELAN), plant=Plant(randomize=0.1))
