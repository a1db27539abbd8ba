"""The envs' settings as validated objects (Plant, Episode, Actuation, Sensors, Spaces, Camera,
Target): checked when built, one constructor signature for every env, and the older plain
keywords mapped onto them with one DeprecationWarning and the same observations."""

from __future__ import annotations

import inspect
import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import furuta_gym  # noqa: F401  (registers the envs)
from furuta_gym.effects import Effect
from furuta_gym.envs import (
    Actuation,
    Camera,
    EnvArgumentError,
    Episode,
    FurutaEnv,
    NMSDEnv,
    Plant,
    Sensors,
    Spaces,
    Target,
)
from furuta_gym.envs._actuation import delay_substeps
from furuta_gym.envs.vector import FurutaVectorEnv, NMSDVectorEnv
from furuta_gym.systems import get_spec

FURUTA_ID, NMSD_ID, SWINGUP_ID = "furuta_gym/Furuta-v0", "furuta_gym/NMSD-v0", "furuta_gym/FurutaSwingUp-v0"


@pytest.mark.parametrize(
    "build, named",
    [
        (lambda: Episode(frame_skip=0), "Episode.frame_skip"),
        (lambda: Episode(frame_skip=2.0), "Episode.frame_skip"),
        (lambda: Episode(seconds=-1.0), "Episode.seconds"),
        (lambda: Episode(reset_noise_scale=math.nan), "Episode.reset_noise_scale"),
        (lambda: Actuation(max_action=0.0), "Actuation.max_action"),
        (lambda: Actuation(max_action="5"), "Actuation.max_action"),
        (lambda: Actuation(delay=-0.002), "Actuation.delay"),
        (lambda: Actuation(delay_steps=-1), "Actuation.delay_steps"),
        (lambda: Sensors(encoder_counts=0), "Sensors.encoder_counts"),
        (lambda: Sensors(position_resolution=math.nan), "Sensors.position_resolution"),
        (lambda: Sensors(measurement_noise=-1.0), "Sensors.measurement_noise"),
        (lambda: Sensors(measurement_noise=[[0.1]]), "Sensors.measurement_noise"),
        (lambda: Sensors(velocity="kalman"), "Sensors.velocity"),
        (lambda: Spaces(observation="polar"), "Spaces.observation"),
        (lambda: Spaces(dtype="int32"), "Spaces.dtype"),
        (lambda: Spaces(normalize_action="yes"), "Spaces.normalize_action"),
        (lambda: Camera(width=0), "Camera.width"),
        (lambda: Plant(effects=["spring"]), "Plant.effects"),
        (lambda: Plant(randomize=1.5), "Plant.randomize"),
        (lambda: Plant(randomize={"mp": -0.1}), "Plant.randomize"),
        (lambda: Target(position="rand"), "target"),
        (lambda: Target(position=(0.5, 0.1)), "low <= high"),
        (lambda: Target(observe=1), "Target.observe"),
    ],
)
def test_a_settings_object_refuses_a_bad_field_when_built(build, named):
    with pytest.raises(EnvArgumentError, match=named):
        build()


def test_settings_are_frozen_normalised_and_compare_by_value():
    assert Sensors(measurement_noise=[0, 0, 1e-3, 2e-3]).measurement_noise == (0.0, 0.0, 1e-3, 2e-3)
    assert Spaces(dtype=np.float32) == Spaces(dtype="float32")
    assert Plant("coulomb") == Plant(presets=("coulomb",)) and Plant().presets == ()
    assert Target((0.2, 0.4)).range == (0.2, 0.4) and Target().range is None and Target("random").range == (-1, 1)
    with pytest.raises(AttributeError):
        Episode().frame_skip = 2  # type: ignore[misc]


def test_sensors_resolve_per_system_and_refuse_what_the_system_lacks():
    furuta, nmsd = get_spec("furuta"), get_spec("nmsd")
    s = Sensors(encoder_counts=2048, measurement_noise=[0.0, 0.0, 0.1, 0.2], velocity="filter")
    assert s.quantization(furuta) == pytest.approx((2 * math.pi / 2048,) * 2)
    assert s.noise(furuta) == (0.0, 0.0, 0.1, 0.2) and not s.exact
    assert Sensors(position_resolution=1e-3).quantization(nmsd) == (1e-3,) and Sensors().exact
    with pytest.raises(EnvArgumentError, match="position_resolution"):
        Sensors(encoder_counts=2048).quantization(nmsd)
    with pytest.raises(EnvArgumentError, match="measurement_noise"):
        Sensors(measurement_noise=[0.1, 0.2, 0.3]).noise(furuta)
    with pytest.raises(EnvArgumentError, match="no angular joint"):
        NMSDEnv(spaces=Spaces("trig"))


def test_actuation_delay_adds_the_settings_and_the_effects_in_substeps():
    effects = [Effect("input_delay", "u", 0.004), Effect("actuator_lag", "u", 0.003)]
    assert delay_substeps(Actuation(delay=0.002, delay_steps=1), effects, timestep=0.001, frame_skip=2) == 8
    with pytest.raises(EnvArgumentError, match="not a multiple"):
        delay_substeps(Actuation(delay=0.0015), [], 0.001, 2)


def test_envs_hold_their_settings_and_quantise_as_declared():
    env = FurutaEnv(sensors=Sensors(encoder_counts=2048), actuation=Actuation(delay_steps=2))
    assert env.sensors == Sensors(encoder_counts=2048) and env.actuation.delay_steps == 2
    obs, _ = env.reset(seed=0)
    steps = env.encoder_steps
    assert np.allclose(obs[:2] / steps, np.round(obs[:2] / steps))
    nmsd = NMSDEnv()
    assert nmsd.task_settings == Target() and nmsd.max_action == 20.0 and FurutaEnv().max_action == 5.0


def test_one_signature_for_both_systems_and_the_vector_env():
    single = inspect.signature(FurutaEnv).parameters
    assert inspect.signature(NMSDEnv).parameters == single
    assert len(inspect.signature(FurutaEnv.__init__).parameters) <= 12
    for vector in (FurutaVectorEnv, NMSDVectorEnv):
        params = inspect.signature(vector).parameters
        shared = {name: p for name, p in params.items() if name in single}
        assert list(shared) == list(single)
        for name, p in shared.items():
            if name != "dynamics":  # a batched env integrates a model: "analytic" by default
                assert p == single[name], name
        assert shared["dynamics"].default == "analytic"


LEGACY = [
    (
        FURUTA_ID,
        dict(max_voltage=3.0, frame_skip=5, episode_seconds=0.2, reset_noise_scale=0.05),
        dict(actuation=Actuation(max_action=3.0), episode=Episode(frame_skip=5, seconds=0.2, reset_noise_scale=0.05)),
    ),
    (
        FURUTA_ID,
        dict(encoder_counts=2048, velocity="filter", measurement_noise=1e-3, actuation_delay_steps=1),
        dict(
            sensors=Sensors(encoder_counts=2048, velocity="filter", measurement_noise=1e-3),
            actuation=Actuation(delay_steps=1),
        ),
    ),
    (
        FURUTA_ID,
        dict(
            plant="coulomb",
            effects=[Effect("spring", "alpha", 2e-3)],
            randomize=0.1,
            observation="trig",
            dtype="float32",
            normalize_action=True,
        ),
        dict(
            plant=Plant("coulomb", effects=[Effect("spring", "alpha", 2e-3)], randomize=0.1),
            spaces=Spaces("trig", "float32", normalize_action=True),
        ),
    ),
    (
        NMSD_ID,
        dict(target="random", observe_target=True, max_force=10.0, position_resolution=1e-3),
        dict(
            task=Target("random", observe=True),
            actuation=Actuation(max_action=10.0),
            sensors=Sensors(position_resolution=1e-3),
        ),
    ),
]


def _run(env, steps=25):
    rng = np.random.default_rng(1)
    obs, info = env.reset(seed=4)
    out = [obs, info["state"]]
    high = env.action_space.high[0]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(
            rng.uniform(-high, high, (1,)).astype(env.action_space.dtype)
        )
        out += [obs, info["state"], [reward, terminated, truncated]]
    return np.concatenate([np.ravel(np.asarray(o, dtype=float)) for o in out])


@pytest.mark.parametrize("env_id, old, new", LEGACY)
def test_old_keywords_map_to_the_objects_with_one_warning_and_the_same_observations(env_id, old, new):
    with pytest.warns(DeprecationWarning) as caught:
        legacy = gym.make(env_id, **old)
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert len(deprecations) == 1
    message = str(deprecations[0].message)
    assert all(f"{k}=" in message for k in old if k != "plant")
    assert all(f"{k}={type(v).__name__}(" in message for k, v in new.items() if k != "plant" or "effects" in old)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        current = gym.make(env_id, **new)
    assert legacy.observation_space == current.observation_space and legacy.action_space == current.action_space
    np.testing.assert_array_equal(_run(legacy), _run(current))


def test_an_old_keyword_sets_one_field_on_top_of_the_objects_given():
    # the preset's Episode(frame_skip=10, seconds=None) keeps its horizon when frame_skip is overridden
    with pytest.warns(DeprecationWarning, match=r"episode=Episode\(frame_skip=5\)"):
        env = gym.make(SWINGUP_ID, frame_skip=5).unwrapped
    assert env.episode == Episode(frame_skip=5, seconds=None) and env.observation == "trig"


def test_bad_or_unknown_keywords_name_what_the_user_wrote():
    with pytest.warns(DeprecationWarning), pytest.raises(EnvArgumentError, match=r"frame_skip=0: Episode.frame_skip"):
        FurutaEnv(frame_skip=0)
    with pytest.raises(EnvArgumentError, match=r"unknown keyword argument\(s\) \['max_force'\]"):
        FurutaEnv(max_force=3.0)
    with pytest.raises(EnvArgumentError, match=r"sensors must be a furuta_gym.envs.Sensors"):
        FurutaEnv(sensors=dict(encoder_counts=2048))
    with pytest.raises(EnvArgumentError, match="no task settings"):
        FurutaEnv(task=Target())
    with pytest.raises(ValueError, match="unknown plant"):
        FurutaEnv(plant="stiff_spring")


def test_pickling_rebuilds_from_the_objects_without_warnings():
    env = gym.make(NMSD_ID, task=Target("random", observe=True), sensors=Sensors(position_resolution=1e-3)).unwrapped
    env.reset(seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        clone = pickle.loads(pickle.dumps(env))
    assert clone.task == env.task and clone.task_settings == env.task_settings
    np.testing.assert_array_equal(clone.step(np.array([1.0]))[0], env.step(np.array([1.0]))[0])
