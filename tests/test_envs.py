"""Gymnasium envs over swappable dynamics (issues 2 and 4): API conventions, bad input,
backend equivalence, divergence, sensors, delay, plant variants and domain randomisation."""

import math
import pickle
import warnings
from typing import ClassVar

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import furuta_gym
from furuta_gym.effects import Effect
from furuta_gym.envs import FurutaEnv, FurutaSwingUp, NMSDEnv, NMSDReach, is_diverged
from furuta_gym.lagrangian import AbstractLagrangianSystem, SystemSpec
from furuta_gym.models import NMSD, Furuta, FurutaParameters
from furuta_gym.signals import derivative_filter
from furuta_gym.systems import FURUTA

FURUTA_ID, NMSD_ID = "furuta_gym/Furuta-v0", "furuta_gym/NMSD-v0"


def _random_actions(limit, n, seed=0):
    return np.random.default_rng(seed).uniform(-1.2 * limit, 1.2 * limit, (n, 1))


def _run(env, actions, seed=0, options=None):
    obs, _ = env.reset(seed=seed, options=options)
    out = [obs]
    for a in actions:
        obs, *_ = env.step(a)
        out.append(obs)
    return np.array(out)


# ---------------------------------------------------------------------------- Gymnasium API


@pytest.mark.parametrize("env_id", [FURUTA_ID, NMSD_ID])
def test_check_env_passes_with_no_undocumented_warning(env_id):
    env = gym.make(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=True)
    # documented: the raw state is unbounded (±infinity bounds) and the action is in physical
    # units (volts / newtons), not normalised to [-1, 1]
    documented = ("is -infinity", "is infinity", "symmetric and normalized space")
    unexpected = [str(w.message) for w in caught if not any(d in str(w.message) for d in documented)]
    assert unexpected == []
    assert len(caught) <= 3


def test_registered_on_import_with_documented_rates():
    assert FURUTA_ID in gym.registry and NMSD_ID in gym.registry
    fur, nmsd = gym.make(FURUTA_ID).unwrapped, gym.make(NMSD_ID).unwrapped
    assert fur.dt == pytest.approx(1 / 500) and nmsd.dt == pytest.approx(1 / 100)
    assert fur.action_space.high[0] == 5.0 and fur.observation_space.shape == (4,)
    assert fur.observation_space.dtype == np.float64
    assert gym.make(FURUTA_ID, frame_skip=5).unwrapped.dt == pytest.approx(0.01)


@pytest.mark.parametrize("env_id", [FURUTA_ID, NMSD_ID])
def test_same_seed_same_rollout_and_truncation(env_id):
    env = gym.make(env_id, episode_seconds=0.2)
    acts = _random_actions(env.unwrapped.max_action, 10)
    a, b = _run(env, acts, seed=3), _run(env, acts, seed=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a[0], _run(env, acts, seed=4)[0])
    env.reset(seed=0)
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, info = env.step(np.zeros(1))
        steps += 1
        assert not terminated
    assert steps == round(0.2 / env.unwrapped.dt) and info["time"] == pytest.approx(0.2)


def test_reset_options_state_and_info():
    env = gym.make(FURUTA_ID)
    x0 = np.array([0.1, math.pi, 0.0, 0.0])
    obs, info = env.reset(seed=0, options={"state": x0})
    np.testing.assert_array_equal(obs, x0)
    # upright at rest: energy mp·g·Lp, reward almost 1 (α = 0.1 costs a little)
    assert info["energy"] == pytest.approx(0.024 * 9.81 * 0.129)
    _, reward, *_ = env.step(np.zeros(1))
    assert 0.9 < reward <= 1.0
    obs, info = env.reset(seed=0)
    assert np.all(np.abs(obs) <= 0.01) and info["time"] == 0.0 and not info["diverged"]


def test_pickle_roundtrip_continues_identically():
    env = gym.make(FURUTA_ID, dynamics="analytic").unwrapped
    acts = _random_actions(5.0, 20)
    env.reset(seed=1)
    for a in acts[:10]:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    for a in acts[10:]:
        o1, r1, *_ = env.step(a)
        o2, r2, *_ = clone.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2
    nm = pickle.loads(pickle.dumps(gym.make(NMSD_ID, plant="coulomb").unwrapped))
    nm.reset(seed=0)
    assert np.all(np.isfinite(nm.step(np.ones(1))[0]))
    # sensor filter and actuation delay memories travel too
    sensed = gym.make(
        FURUTA_ID, velocity="filter", encoder_counts=2048, actuation_delay_steps=3, measurement_noise=1e-3
    ).unwrapped
    sensed.reset(seed=2)
    for a in acts[:10]:
        sensed.step(a)
    twin = pickle.loads(pickle.dumps(sensed))
    for a in acts[10:]:
        np.testing.assert_array_equal(sensed.step(a)[0], twin.step(a)[0])


@pytest.mark.parametrize("env_id,dynamics", [(FURUTA_ID, "mujoco"), (FURUTA_ID, "analytic"), (NMSD_ID, "mujoco")])
def test_rgb_array_render_headless(env_id, dynamics, monkeypatch):
    env = gym.make(env_id, dynamics=dynamics, render_mode="rgb_array", width=96, height=64)
    env.reset(seed=0)
    frame0 = env.render()
    assert frame0.shape == (64, 96, 3) and frame0.dtype == np.uint8
    env.reset(options={"state": np.r_[1.0, 2.5, 0, 0] if env_id == FURUTA_ID else np.r_[0.8, 0]})
    frame1 = env.render()
    assert frame1.std() > 0 and not np.array_equal(frame0, frame1)  # the pose is drawn
    env.close()
    # "human" needs a display: a clear error instead of GLFW aborting the process
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ValueError, match="needs a display"):
        gym.make(env_id, render_mode="human")


# ---------------------------------------------------------------------------- bad input


def test_bad_inputs_give_clear_errors():
    env = gym.make(FURUTA_ID)
    env.reset(seed=0)
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError, match="finite"):
            env.step(np.array([bad]))
    with pytest.raises(ValueError, match=r"shape \(1,\)"):
        env.step(np.zeros(2))
    with pytest.raises((ValueError, TypeError), match="expected any of"):
        gym.make(FURUTA_ID, max_volts=3.0)
    with pytest.raises(ValueError, match=r"shape \(4,\)"):
        env.reset(options={"state": np.zeros(3)})
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        gym.make(NMSD_ID).reset(options={"state": np.zeros(4)})
    with pytest.raises(ValueError, match="unknown option"):
        env.reset(options={"stat": np.zeros(4)})
    with pytest.raises(ValueError, match="accepted: 'mujoco'"):
        gym.make(FURUTA_ID, dynamics="mjc")
    with pytest.raises(FileNotFoundError, match="not found"):
        gym.make(FURUTA_ID, dynamics="no/such/checkpoint.eqx")
    with pytest.raises(ValueError, match="'nmsd' model but this env simulates 'furuta'"):
        gym.make(FURUTA_ID, dynamics=NMSD())
    with pytest.raises(ValueError, match="unknown plant"):
        gym.make(FURUTA_ID, plant="rubber_band")
    with pytest.raises(ValueError, match="not a joint of furuta"):
        gym.make(FURUTA_ID, effects=[Effect("spring", "p", 1.0)])
    with pytest.raises(ValueError, match="multiple of the simulation timestep"):
        gym.make(FURUTA_ID, actuation_delay=0.003)
    with pytest.raises(ValueError, match="randomize"):
        gym.make(FURUTA_ID, randomize={"mass": 0.1})


def test_out_of_range_action_is_clipped_to_the_voltage_limit():
    env = gym.make(FURUTA_ID).unwrapped
    a = _run(env, [np.array([50.0])] * 5, seed=0)
    _, _, _, _, info = env.step(np.array([-50.0]))
    assert info["action"] == -5.0
    b = _run(env, [np.array([5.0])] * 5, seed=0)
    np.testing.assert_array_equal(a, b)


# ---------------------------------------------------------------------------- backends


@pytest.mark.parametrize(
    "env_id,seconds,kwargs",
    [
        (FURUTA_ID, 2.0, {}),
        (NMSD_ID, 2.0, {}),
        (FURUTA_ID, 1.0, {"plant": ["cable_spring", "quadratic_drag", "weak_motor"]}),
        (FURUTA_ID, 1.0, {"frame_skip": 2, "actuation_delay": 0.002}),  # split-period delay
        (NMSD_ID, 2.0, {"plant": "quadratic_drag", "randomize": 0.2}),
        (FURUTA_ID, 1.0, {"randomize": 0.2}),
    ],
    ids=["furuta", "nmsd", "furuta-variants", "furuta-split-delay", "nmsd-drag-randomized", "furuta-randomized"],
)
def test_analytic_backend_equals_mujoco_backend(env_id, seconds, kwargs):
    mj = gym.make(env_id, **kwargs).unwrapped
    an = gym.make(env_id, dynamics="analytic", **kwargs).unwrapped
    n = round(seconds / mj.dt)
    acts = _random_actions(mj.max_action, n, seed=7)
    xs_mj, xs_an = _run(mj, acts, seed=5), _run(an, acts, seed=5)
    assert an.backend.parameters == mj.backend.parameters
    assert np.ptp(xs_mj[:, 0]) > 0.05  # it moved
    assert np.max(np.abs(xs_mj[:, : mj._n] - xs_an[:, : mj._n])) <= 1e-6


def test_any_lagrangian_object_is_a_backend():
    by_name = _run(gym.make(FURUTA_ID, dynamics="analytic"), _random_actions(5, 50))
    by_object = _run(gym.make(FURUTA_ID, dynamics=Furuta()), _random_actions(5, 50))
    np.testing.assert_array_equal(by_name, by_object)
    # an analytic model with its own parameters reports (and uses) them
    heavy = gym.make(FURUTA_ID, dynamics=Furuta(FurutaParameters(mp=0.048))).unwrapped
    _, info = heavy.reset(options={"state": [0.0, np.pi, 0.0, 0.0]})
    assert heavy.backend.parameters["mp"] == 0.048
    assert info["energy"] == pytest.approx(0.048 * 9.81 * 0.129)


class _Exploding(AbstractLagrangianSystem):
    """A broken 'learned model': the analytic Furuta with an absurd input gain or a NaN force."""

    base: Furuta
    gain: float
    nan: bool = False
    spec: ClassVar[SystemSpec] = FURUTA

    def mass_matrix(self, q):
        return self.base.mass_matrix(q)

    def potential(self, q):
        return self.base.potential(q)

    def nonconservative_force(self, q, qd):
        f = self.base.nonconservative_force(q, qd)
        return jnp.where(self.nan & (jnp.abs(qd[0]) > 1.0), jnp.nan, f)

    def input_force(self, q, qd, u):
        return self.gain * self.base.input_force(q, qd, u)


@pytest.mark.parametrize("nan", [False, True], ids=["huge", "nan"])
def test_broken_model_ends_with_diverged_and_no_nan(nan):
    env = gym.make(FURUTA_ID, dynamics=_Exploding(Furuta(), 1e3 if nan else 1e9, nan))
    env.reset(seed=0)
    for k in range(500):
        obs, reward, terminated, truncated, info = env.step(np.array([5.0]))
        assert np.all(np.isfinite(obs)) and math.isfinite(reward), f"step {k}"
        if terminated:
            break
    assert terminated and info["diverged"] and k < 499
    assert np.all(np.isfinite(info["state"])) and math.isfinite(info["energy"])
    again = env.step(np.array([5.0]))  # stepping on does not raise and stays terminated
    assert again[2] and np.array_equal(again[0], obs)


# ---------------------------------------------------------------------------- plant variants


def _free(env_kwargs, x0, steps, env_id=FURUTA_ID, action=0.0):
    env = gym.make(env_id, **env_kwargs)
    return _run(env, [np.array([action])] * steps, options={"state": np.asarray(x0, float)})


def test_cable_spring_pulls_the_rotor_back():
    x0 = [1.0, 0.0, 0.0, 0.0]
    nominal = _free({}, x0, 250)
    spring = _free({"plant": "cable_spring"}, x0, 250)
    assert abs(nominal[-1, 0] - 1.0) < 1e-6  # nothing pulls the textbook rotor
    assert spring[-1, 0] < 0.9  # the cable does
    # explicit Effect with the same value is the preset
    explicit = _free({"effects": [Effect("spring", "alpha", 2e-3)]}, x0, 250)
    np.testing.assert_array_equal(spring, explicit)


def test_coulomb_friction_and_drag_dissipate_more():
    x0 = [0.0, 1.0, 5.0, 0.0]
    nominal = _free({}, x0, 500)
    coulomb = _free({"plant": "coulomb"}, x0, 500)
    drag = _free({"plant": "quadratic_drag"}, x0, 500)
    # the rotor spins down further with dry friction; the pendulum swing decays faster with drag
    assert abs(coulomb[-1, 0]) < abs(nominal[-1, 0]) - 0.05
    assert np.ptp(drag[-100:, 1]) < np.ptp(nominal[-100:, 1]) - 0.005
    # Coulomb friction on the model backend is the same sgn law
    an = _free({"plant": "coulomb", "dynamics": "analytic"}, x0, 100)
    assert np.max(np.abs(an[:, :2] - coulomb[:101, :2])) < 1e-6


def test_input_gain_and_delay_variants():
    x0 = [0.0, 0.0, 0.0, 0.0]
    nominal = _free({}, x0, 50, action=2.0)
    weak = _free({"plant": "weak_motor"}, x0, 50, action=2.0)
    assert 0.7 < weak[-1, 0] / nominal[-1, 0] < 0.9
    delayed = _free({"plant": "delay"}, x0, 50, action=2.0)  # 4 ms = two periods
    np.testing.assert_array_equal(delayed[:3], np.zeros((3, 4)))
    np.testing.assert_allclose(delayed[2:], nominal[:-2], atol=1e-12)
    by_steps = _free({"actuation_delay_steps": 2}, x0, 50, action=2.0)
    np.testing.assert_array_equal(by_steps, delayed)


def test_nmsd_variants():
    x0 = [0.0, 2.0]
    nominal = _free({}, x0, 100, env_id=NMSD_ID)
    stiff = _free({"plant": "stiff_spring"}, x0, 100, env_id=NMSD_ID)
    assert np.max(stiff[:, 0]) < np.max(nominal[:, 0])


# ---------------------------------------------------------------------------- sensors


def test_encoder_quantisation_noise_and_filtered_velocity():
    x0 = np.array([0.0, 1.0, 0.0, 0.0])
    acts = [np.array([1.0])] * 100
    exact = _run(gym.make(FURUTA_ID), acts, options={"state": x0})
    enc = gym.make(FURUTA_ID, encoder_counts=2048, velocity="filter")
    meas = _run(enc, acts, options={"state": x0})
    step = 2 * np.pi / 2048
    np.testing.assert_allclose(meas[:, :2] / step, np.round(meas[:, :2] / step), atol=1e-9)
    assert np.max(np.abs(meas[:, :2] - exact[:, :2])) <= step / 2 + 1e-12
    # velocities are the paper's derivative filter run causally on the measured angles ...
    offline = derivative_filter(meas[:, :2], enc.unwrapped.dt)
    np.testing.assert_allclose(meas[:, 2:], offline, atol=1e-9)
    # ... which tracks the true velocity with its ≈16 ms (8-step) lag
    assert np.corrcoef(meas[58:, 3], exact[50:-8, 3])[0, 1] > 0.95
    noisy = gym.make(FURUTA_ID, measurement_noise=0.01)
    a, b = _run(noisy, acts, seed=2), _run(noisy, acts, seed=2)
    np.testing.assert_array_equal(a, b)  # seeded
    info_state = noisy.unwrapped.backend.state
    assert 0.003 < np.std(a[-1] - info_state) < 0.03


def test_domain_randomisation_is_seeded_and_changes_the_plant():
    env = gym.make(FURUTA_ID, randomize=0.2).unwrapped
    env.reset(seed=0)
    p0 = env.backend.parameters
    env.reset(seed=0)
    assert env.backend.parameters == p0
    env.reset(seed=1)
    p1 = env.backend.parameters
    assert p1 != p0 and p1["g"] == 9.81
    assert all(0.8 <= p1[k] / v <= 1.2 for k, v in furuta_gym.envs.default_parameters("furuta").items())
    only_mass = gym.make(FURUTA_ID, randomize={"mp": 0.5}).unwrapped
    only_mass.reset(seed=0)
    changed = {k for k, v in only_mass.backend.parameters.items() if v != p0.get(k) or k == "mp"}
    assert "mp" in changed and only_mass.backend.parameters["Lp"] == 0.129


# ---------------------------------------------------------------------------- tasks


def test_task_functions_agree_on_floats_numpy_and_jax():
    rng = np.random.default_rng(0)
    xs, us = rng.normal(size=(50, 4)) * 3, rng.normal(size=(50, 1)) * 4
    task = FurutaSwingUp()
    batch_np = task.reward(None, us, xs)
    batch_jax = np.asarray(task.reward(None, jnp.asarray(us), jnp.asarray(xs)))
    scalar = np.array([task.reward(None, u.tolist(), x.tolist()) for x, u in zip(xs, us, strict=True)])
    np.testing.assert_allclose(batch_np, scalar, rtol=1e-12)
    np.testing.assert_allclose(batch_jax, scalar, rtol=1e-12)
    assert np.all((batch_np >= 0) & (batch_np <= 1))
    assert task.reward(None, [0.0], [0.0, math.pi, 0.0, 0.0]) == pytest.approx(1.0)
    assert task.reward(None, [0.0], [0.0, 0.0, 0.0, 0.0]) == 0.0
    reach = NMSDReach(target=0.3)
    assert reach.reward(None, [0.0], [0.3, 0.0]) == pytest.approx(1.0)
    assert reach.reward(None, [0.0], [1.3, 0.0]) < 0.01
    assert bool(is_diverged(np.array([np.nan, 0.0]))) and not is_diverged([1.0, 2.0])
    assert np.asarray(task.terminated(jnp.zeros((3, 4)))).shape == (3,)
    nm = NMSDEnv(target=0.2)
    nm.reset(seed=0, options={"target": 0.7})
    assert nm.task.target == 0.7 and isinstance(FurutaEnv().task, FurutaSwingUp)


# ---------------------------------------------------------------------------- CLI


def test_rollout_cli_writes_plot_video_and_refuses_to_overwrite(tmp_path, capsys):
    from furuta_gym.cli import main

    png, gif, csv = tmp_path / "r.png", tmp_path / "r.gif", tmp_path / "r.csv"
    argv = [
        "rollout",
        "--system",
        "nmsd",
        "--policy",
        "chirp",
        "--seconds",
        "0.5",
        "--out",
        str(png),
        "--video",
        str(gif),
        "--data",
        str(csv),
    ]
    assert main(argv) == 0
    assert png.stat().st_size > 1000 and gif.stat().st_size > 1000
    from furuta_gym.data import load_trajectories

    (traj,) = load_trajectories(csv, "nmsd")
    assert traj.q.shape == (51, 1) and np.ptp(traj.u) > 1.0
    before = png.stat().st_mtime_ns
    assert main(argv) == 2  # exists: refused, nothing touched
    assert "refusing to overwrite" in capsys.readouterr().err
    assert png.stat().st_mtime_ns == before
    assert main(argv + ["--overwrite"]) == 0
    assert main(["rollout", "--dynamics", "nope", "--out", str(tmp_path / "x.png")]) == 2
    assert "accepted: 'mujoco'" in capsys.readouterr().err


# ---------------------------------------------------------------------------- checkpoints


def test_learned_checkpoint_by_path_and_object_and_broken_weights(tmp_path):
    import equinox as eqx
    import jax

    from furuta_gym.models import make_model
    from furuta_gym.training.checkpoint import save_model

    model = make_model("furuta", "dln", 0)
    path = save_model(tmp_path / "delan.eqx", model)
    acts = _random_actions(5.0, 20)
    by_path = _run(gym.make(FURUTA_ID, dynamics=str(path)), acts)
    by_object = _run(gym.make(FURUTA_ID, dynamics=model), acts)
    np.testing.assert_array_equal(by_path, by_object)
    assert np.all(np.isfinite(by_path))
    nmsd_path = save_model(tmp_path / "nmsd.eqx", make_model("nmsd", "dln", 0))
    with pytest.raises(ValueError, match="'nmsd' model; expected a 'furuta' model"):
        gym.make(FURUTA_ID, dynamics=str(nmsd_path))
    # huge weights: the learned model blows up; the env ends the episode cleanly
    huge = jax.tree_util.tree_map(lambda w: w * 1e4, model, is_leaf=eqx.is_inexact_array)
    env = gym.make(FURUTA_ID, dynamics=huge)
    env.reset(seed=0)
    for _ in range(200):
        obs, reward, terminated, _, info = env.step(np.array([5.0]))
        assert np.all(np.isfinite(obs)) and math.isfinite(reward)
        if terminated:
            break
    assert terminated and info["diverged"]


def test_read_only_settings_report_what_was_configured():
    """The settings a batched copy reads (vector.py) come from public read-only properties."""
    plain = FurutaEnv(dynamics="analytic", episode_seconds=0.5)
    assert plain.system_spec is FURUTA
    assert plain.max_episode_steps == 250  # 0.5 s at 500 Hz
    np.testing.assert_array_equal(plain.encoder_steps, [0.0, 0.0])
    assert plain.per_episode_state_features() == []
    sensed = FurutaEnv(
        dynamics="analytic",
        encoder_counts=2048,
        measurement_noise=1e-3,
        velocity="filter",
        actuation_delay_steps=1,
        episode_seconds=None,
    )
    np.testing.assert_allclose(sensed.encoder_steps, [2 * math.pi / 2048] * 2)
    sensed.encoder_steps[:] = 0.0  # a copy: the env keeps quantising
    assert sensed.encoder_steps[0] > 0
    assert sensed.max_episode_steps is None
    features = " ".join(sensed.per_episode_state_features())
    assert "measurement_noise" in features and "filter" in features and "delay" in features
    assert "randomize" not in features


def test_initial_state_sampling_and_reset_options_without_an_episode():
    """The two calls the batched env makes on its template: the same draw as reset(seed), and a
    task option applied without starting an episode (unknown keys refused by name)."""
    import gymnasium as gym
    from gymnasium.utils import seeding

    env = gym.make("furuta_gym/Furuta-v0", dynamics="analytic", reset_noise_scale=0.2).unwrapped
    obs, _ = env.reset(seed=5)
    drawn = env.sample_initial_state(seeding.np_random(5)[0])
    np.testing.assert_array_equal(drawn, obs)
    assert np.all(np.abs(drawn) <= 0.2) and np.any(drawn != 0.0)
    np.testing.assert_array_equal(env.sample_initial_state(None), np.zeros(4))

    nmsd = gym.make("furuta_gym/NMSD-v0", dynamics="analytic").unwrapped
    nmsd.apply_reset_options({"target": 0.25})
    assert nmsd.task.target == 0.25
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) \['goal'\]"):
        nmsd.apply_reset_options({"goal": 1.0})


@pytest.mark.parametrize(
    "env_id,randomize", [("furuta_gym/Furuta-v0", None), ("furuta_gym/Furuta-v0", 0.2), ("furuta_gym/NMSD-v0", 0.2)]
)
def test_info_energy_is_the_models_energy_at_the_plants_parameters(env_id, randomize):
    # the env's float energy (no JAX per step) and lagrangian.energy of the analytic model with
    # the plant's parameters (drawn anew at each reset) are one physics: equal to rounding
    from furuta_gym.lagrangian import energy
    from furuta_gym.models import system_definition

    env = gym.make(env_id, randomize=randomize)
    definition = system_definition(env.unwrapped.system)
    n = definition.spec.n_dof
    rng = np.random.default_rng(1)
    drawn = set()
    for seed in range(4):
        x = rng.uniform(-3, 3, 2 * n)
        _, info = env.reset(seed=seed, options={"state": x})
        params = env.unwrapped.physical_parameters()
        drawn.add(tuple(sorted(params.items())))
        model = definition.model(params=definition.parameters(**params))
        expected = float(energy(model, jnp.asarray(x[:n]), jnp.asarray(x[n:])))
        assert info["energy"] == pytest.approx(expected, rel=1e-12)
    assert len(drawn) == (1 if randomize is None else 4)
    env.close()


@pytest.mark.parametrize("env_class", [FurutaEnv, NMSDEnv])
def test_the_signature_is_the_documented_keywords(env_class):
    # typed keywords help() and IDEs show, the same set as the docstring's table
    import inspect
    import re

    params = inspect.signature(env_class).parameters
    declared = {n for n, p in params.items() if p.kind is p.KEYWORD_ONLY}
    section = env_class.__doc__.split("## Arguments")[1].split("\n    ## ")[0]
    documented = set(re.findall(r"`+(\w+)`+", section))
    assert declared - documented == set()  # every keyword is documented
    assert len(inspect.signature(env_class.__init__).parameters) <= 12
