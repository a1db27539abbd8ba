"""Angle wrapping, divergence only on velocities, observation layouts, the RL preset
``furuta_gym/FurutaSwingUp-v0`` and N-MSD's observed / random target."""

import math
import os
import pickle
import sys
import warnings

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

import furuta_gym  # noqa: F401  (registers the envs)
from furuta_gym.envs import EnvArgumentError, FurutaSwingUp, is_diverged
from furuta_gym.envs._tasks import divergence_bounds, wrap_angle

FURUTA_ID, NMSD_ID, SWINGUP_ID = (
    "furuta_gym/Furuta-v0",
    "furuta_gym/NMSD-v0",
    "furuta_gym/FurutaSwingUp-v0",
)
HEADLESS = sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _no_warnings(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn(*args, **kwargs)
    return [str(w.message) for w in caught if "float64" not in str(w.message).lower()]


# ---------------------------------------------------------------------------- divergence


def test_constant_voltage_past_the_old_false_divergence_point_never_diverges():
    # 0.1 s per step: 2 100 steps = 210 s at +5 V, past the ~204.6 s where α crossed 1e4
    env = gym.make(FURUTA_ID, frame_skip=50, episode_seconds=None)
    env.reset(seed=0)
    for _ in range(2100):
        obs, reward, terminated, truncated, info = env.step(np.array([5.0]))
        assert not terminated and not info["diverged"]
    assert info["state"][0] > 1.02e4 and np.array_equal(obs, info["state"])
    assert info["time"] == pytest.approx(210.0)


@pytest.mark.parametrize("dynamics", ["mujoco", "analytic"])
def test_state_near_the_old_angle_bound_keeps_running(dynamics):
    env = gym.make(FURUTA_ID, dynamics=dynamics, frame_skip=10, episode_seconds=None)
    env.reset(options={"state": [9999.0, 3.0, 0.0, 0.0]})
    for _ in range(100):
        _, reward, terminated, _, info = env.step(np.array([5.0]))
        assert not terminated and not info["diverged"] and 0.0 <= reward <= 1.0
    assert info["state"][0] > 1e4


def test_batched_env_does_not_diverge_on_angles_either():
    venv = gym.make_vec(FURUTA_ID, num_envs=2, dynamics="analytic", frame_skip=10, batched=True)
    x0s = np.array([[9999.0, 3.0, 0.0, 0.0], [-9999.5, 0.0, 0.0, 0.0]])
    out = venv.rollout(lambda obs: jnp.array([5.0]) * jnp.sign(obs[0]), 50, x0s=x0s)
    assert not np.any(np.asarray(out.diverged))
    assert np.all(np.abs(np.asarray(out.states)[:, -1, 0]) > 1e4)
    venv.close()


def test_velocities_and_non_finite_values_still_diverge():
    bounds = divergence_bounds(1e4, (True, True))
    assert bounds == (math.inf, math.inf, 1e4, 1e4)
    assert not is_diverged([1e6, -1e6, 0.0, 0.0], bounds)
    assert is_diverged([0.0, 0.0, 2e4, 0.0], bounds) and is_diverged([math.nan, 0, 0, 0], bounds)
    assert is_diverged([math.inf, 0, 0, 0], bounds)
    batch = np.array([[1e6, 0, 0, 0], [0, 0, 0, -2e4], [np.nan, 0, 0, 0]])
    np.testing.assert_array_equal(is_diverged(batch, bounds), [False, True, True])
    np.testing.assert_array_equal(np.asarray(is_diverged(jnp.asarray(batch), bounds)), [False, True, True])
    # a velocity beyond the bound through the env: terminated, diverged, last good observation
    env = gym.make(FURUTA_ID, episode_seconds=None)
    obs0, _ = env.reset(options={"state": [0.0, 0.0, 9999.99, 0.0]})
    *_, terminated, _, info = env.step(np.array([5.0]))
    assert terminated and info["diverged"]


# ---------------------------------------------------------------------------- reward


def test_centred_factor_is_two_pi_periodic_in_alpha():
    task = FurutaSwingUp()
    up = [0.0, math.pi, 0.0, 0.0]
    for alpha in (0.0, 0.3, -1.2, math.pi / 2, 3.0):
        ref = task.reward(None, [0.0], [alpha, *up[1:]])
        for k in (-3, -1, 1, 2, 1000):
            x = [alpha + 2 * math.pi * k, *up[1:]]
            assert task.reward(None, [0.0], x) == pytest.approx(ref, abs=1e-9)
    # α = 2π is centred (scores like 0, not like π/2)
    assert task.reward(None, [0.0], [2 * math.pi, *up[1:]]) == pytest.approx(1.0)
    xs = np.array([[a, math.pi, 0.0, 0.0] for a in (0.4, 0.4 + 2 * math.pi, 0.4 - 20 * math.pi)])
    us = np.zeros((3, 1))
    for r in (task.reward(None, us, xs), np.asarray(task.reward(None, jnp.asarray(us), jnp.asarray(xs)))):
        np.testing.assert_allclose(r, r[0], rtol=1e-9)


def test_wrap_angle_range():
    a = np.linspace(-50, 50, 10001)
    w = wrap_angle(a)
    assert np.all((w > -math.pi) & (w <= math.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi


# ---------------------------------------------------------------------------- observations


@pytest.mark.parametrize("dtype", ["float64", "float32"])
@pytest.mark.parametrize("observation", ["wrapped", "trig"])
def test_wrapped_and_trig_observations_are_bounded_and_match_the_state(observation, dtype):
    env = gym.make(FURUTA_ID, observation=observation, dtype=dtype, frame_skip=5)
    space = env.observation_space
    assert space.dtype == np.dtype(dtype) and space.shape == ((4,) if observation == "wrapped" else (6,))
    assert np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))
    obs, info = env.reset(seed=1, options={"state": [40.0, -9.0, 3.0, -2.0]})
    actions = np.random.default_rng(0).uniform(-5, 5, 300)
    tol = 1e-6 if dtype == "float32" else 1e-12
    for k, a in enumerate(actions):
        if k:
            obs, _, _, _, info = env.step(np.array([a]))
        assert obs.dtype == np.dtype(dtype) and space.contains(obs)
        al, be, ad, bd = info["state"]
        if observation == "wrapped":
            assert np.all(obs[:2] > -math.pi - tol) and np.all(obs[:2] <= math.pi + tol)
            expected = [math.atan2(math.sin(al), math.cos(al)), math.atan2(math.sin(be), math.cos(be)), ad, bd]
            np.testing.assert_allclose(np.cos(obs[:2]), np.cos(expected[:2]), atol=tol * 10)
            np.testing.assert_allclose(np.sin(obs[:2]), np.sin(expected[:2]), atol=tol * 10)
            np.testing.assert_allclose(obs[2:], [ad, bd], rtol=tol)
        else:
            expected = [math.cos(al), math.sin(al), math.cos(be), math.sin(be), ad, bd]
            np.testing.assert_allclose(obs, expected, rtol=tol, atol=tol)


def test_default_observation_is_unchanged_raw_float64():
    env = gym.make(FURUTA_ID)
    obs, info = env.reset(options={"state": [7.0, 1.0, 0.0, 0.0]})
    assert obs.dtype == np.float64 and env.observation_space.shape == (4,)
    assert np.array_equal(obs, info["state"]) and obs[0] == 7.0
    assert env.action_space.high[0] == 5.0


def test_observation_options_give_clear_errors():
    with pytest.raises(EnvArgumentError, match="observation"):
        gym.make(FURUTA_ID, observation="polar")
    with pytest.raises(EnvArgumentError, match="dtype"):
        gym.make(FURUTA_ID, dtype="int32")
    with pytest.raises(EnvArgumentError, match="normalize_action"):
        gym.make(FURUTA_ID, normalize_action="yes")
    with pytest.raises(EnvArgumentError, match="no angular joint"):
        gym.make(NMSD_ID, observation="trig")
    with pytest.raises(EnvArgumentError, match="observation='trig'"):
        gym.make_vec(FURUTA_ID, num_envs=2, dynamics="analytic", observation="trig", batched=True)
    # by default make_vec picks the env that supports the options: 32 copies with trig -> sync
    auto = gym.make_vec(FURUTA_ID, num_envs=32, dynamics="analytic", observation="trig")
    assert isinstance(auto, gym.vector.SyncVectorEnv) and auto.observation_space.shape == (32, 6)
    auto.close()


def test_observation_with_sensors_and_pickle():
    env = gym.make(FURUTA_ID, observation="trig", encoder_counts=2048, measurement_noise=1e-3)
    env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step(np.array([1.0]))
        assert env.observation_space.contains(obs)
    clone = pickle.loads(pickle.dumps(env.unwrapped))
    a = clone.step(np.array([1.0]))[0]
    b = env.unwrapped.step(np.array([1.0]))[0]
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------------- the RL preset


def test_rl_preset_spaces_horizon_and_rates():
    env = gym.make(SWINGUP_ID)
    assert env.spec.max_episode_steps == 500
    assert env.observation_space.dtype == np.float32 and env.observation_space.shape == (6,)
    assert env.action_space.dtype == np.float32
    np.testing.assert_array_equal(env.action_space.low, [-1.0])
    np.testing.assert_array_equal(env.action_space.high, [1.0])
    u = env.unwrapped
    assert u.dt == pytest.approx(0.02) and u.metadata["render_fps"] == 50 == env.metadata["render_fps"]
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    steps, truncated, terminated = 0, False, False
    while not (truncated or terminated):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        steps += 1
        assert env.observation_space.contains(obs) and 0.0 <= reward <= 1.0
    assert truncated and not terminated and steps == 500
    assert info["time"] == pytest.approx(10.0)
    # the normalised action is scaled to the voltage limit (info reports volts)
    env.reset(seed=0)
    assert env.step(np.array([0.5], np.float32))[4]["action"] == pytest.approx(2.5)
    assert env.step(np.array([3.0], np.float32))[4]["action"] == pytest.approx(5.0)


def test_rl_preset_passes_gymnasium_check_env_without_warnings():
    env = gym.make(SWINGUP_ID)
    # render_mode="human" needs a display: headless, the rgb_array mode is checked on its own
    assert _no_warnings(check_env, env.unwrapped, skip_render_check=HEADLESS) == []
    viewer = gym.make(SWINGUP_ID, render_mode="rgb_array", width=64, height=64)
    viewer.reset(seed=0)
    assert _no_warnings(env_render_passive_checker, viewer.unwrapped) == []
    viewer.close()


def test_rl_preset_passes_stable_baselines3_check_env():
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(SWINGUP_ID)
    assert _no_warnings(sb3_checker.check_env, env.unwrapped) == []


# ---------------------------------------------------------------------------- N-MSD target


def test_nmsd_target_in_observation_and_random_per_reset():
    env = gym.make(NMSD_ID, target="random", observe_target=True)
    assert env.observation_space.shape == (3,)
    targets = []
    for seed in range(20):
        obs, info = env.reset(seed=seed)
        assert obs[2] == info["target"] == env.unwrapped.task.target
        targets.append(info["target"])
        obs, *_, info = env.step(np.array([1.0]))
        assert obs[2] == info["target"] == targets[-1]
    assert all(-1.0 <= t <= 1.0 for t in targets) and len(set(targets)) == 20
    assert env.reset(seed=3)[1]["target"] == targets[3]  # seeded
    obs, info = env.reset(seed=3, options={"target": 0.25})  # an explicit target wins
    assert obs[2] == 0.25 == info["target"]
    ranged = gym.make(NMSD_ID, target=(0.2, 0.4))
    assert ranged.observation_space.shape == (2,)  # default: target not observed
    drawn = [ranged.reset(seed=s)[1]["target"] for s in range(10)]
    assert all(0.2 <= t <= 0.4 for t in drawn) and len(set(drawn)) == 10
    fixed = gym.make(NMSD_ID, observe_target=True, target=0.3)
    assert fixed.reset(seed=0)[0][2] == 0.3 and fixed.reset(seed=1)[1]["target"] == 0.3


def test_nmsd_target_errors_pickle_and_vector():
    for bad, match in (
        ("rand", "target"),
        ((1.0,), "range"),
        ((0.5, 0.1), "low <= high"),
        (math.nan, "target"),
        ((0.0, 5e3), "target range"),
    ):
        with pytest.raises(EnvArgumentError, match=match):
            gym.make(NMSD_ID, target=bad)
    with pytest.raises(EnvArgumentError, match="observe_target"):
        gym.make(NMSD_ID, observe_target=1)
    env = gym.make(NMSD_ID, target="random", observe_target=True).unwrapped
    env.reset(seed=5)
    clone = pickle.loads(pickle.dumps(env))
    assert clone.task.target == env.task.target
    np.testing.assert_array_equal(clone.step(np.array([2.0]))[0], env.step(np.array([2.0]))[0])
    assert clone.reset(seed=9)[1]["target"] == env.reset(seed=9)[1]["target"]
    with pytest.raises(EnvArgumentError, match="random target"):
        gym.make_vec(NMSD_ID, num_envs=2, dynamics="analytic", target="random", batched=True)
    with pytest.raises(EnvArgumentError, match="observe_target"):
        gym.make_vec(NMSD_ID, num_envs=2, dynamics="analytic", observe_target=True, batched=True)
    auto = gym.make_vec(NMSD_ID, num_envs=20, dynamics="analytic", target="random", observe_target=True)
    obs, info = auto.reset(seed=3)
    assert obs.shape == (20, 3) and len(set(np.round(info["target"], 12))) == 20
    auto.close()


def test_published_sac_comparison_matches_its_result_file():
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "bench" / "sac_preset.py"
    out = subprocess.run([sys.executable, str(script), "--check"], capture_output=True, text=True, cwd=script.parent)
    assert out.returncode == 0, out.stdout + out.stderr
