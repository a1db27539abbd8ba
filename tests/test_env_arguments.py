"""The envs' sensor and actuation settings as validated objects (``env.sensors``,
``env.actuation``), built once from the keywords and read by the vector env."""

from __future__ import annotations

import math

import numpy as np
import pytest

from furuta_gym.effects import Effect
from furuta_gym.envs import Actuation, EnvArgumentError, FurutaEnv, NMSDEnv, Sensors
from furuta_gym.systems import get_spec


def test_sensors_from_keywords():
    s = Sensors.from_arguments(get_spec("furuta"), 2048, None, [0.0, 0.0, 0.1, 0.2], "filter")
    assert s.quantization == pytest.approx((2 * math.pi / 2048, 2 * math.pi / 2048))
    assert s.noise == (0.0, 0.0, 0.1, 0.2) and s.velocity == "filter" and not s.exact
    assert Sensors.from_arguments(get_spec("nmsd"), None, 1e-3, 0.0, "exact").quantization == (1e-3,)
    assert Sensors.from_arguments(get_spec("furuta"), None, None, 0.0, "exact").exact


@pytest.mark.parametrize("keywords, named", [
    (dict(encoder_counts=0), "encoder_counts"),
    (dict(measurement_noise=[0.1, 0.2, 0.3]), "measurement_noise"),
    (dict(measurement_noise=-1.0), "measurement_noise"),
    (dict(velocity="kalman"), "velocity"),
    (dict(position_resolution=float("nan")), "position_resolution"),
])
def test_bad_sensor_keyword_is_named(keywords, named):
    args = dict(encoder_counts=None, position_resolution=None, measurement_noise=0.0, velocity="exact") | keywords
    with pytest.raises(EnvArgumentError, match=named):
        Sensors.from_arguments(get_spec("furuta"), **args)


def test_encoder_counts_on_a_system_without_angles_is_refused():
    with pytest.raises(EnvArgumentError, match="position_resolution"):
        Sensors.from_arguments(get_spec("nmsd"), 2048, None, 0.0, "exact")


def test_actuation_adds_keyword_and_effect_delays_in_substeps():
    a = Actuation.from_arguments([Effect("input_delay", "u", 0.004), Effect("actuator_lag", "u", 0.003)],
                                 timestep=0.001, frame_skip=2, actuation_delay=0.002, actuation_delay_steps=1)
    assert a == Actuation(delay_substeps=2 + 2 + 4, lag=0.003)
    with pytest.raises(EnvArgumentError, match="not a multiple"):
        Actuation.from_arguments([], 0.001, 2, 0.0015, 0)
    with pytest.raises(EnvArgumentError, match="actuation_delay_steps"):
        Actuation.from_arguments([], 0.001, 2, 0.0, -1)


def test_envs_hold_their_settings_and_quantise_as_declared():
    env = FurutaEnv(encoder_counts=2048, actuation_delay_steps=2)
    assert env.sensors.quantization == pytest.approx((2 * math.pi / 2048,) * 2)
    assert env.actuation.delay_substeps == 2 * env.frame_skip
    obs, _ = env.reset(seed=0)
    steps = np.array(env.sensors.quantization)
    assert np.allclose(obs[:2] / steps, np.round(obs[:2] / steps))
    assert NMSDEnv().sensors.exact and NMSDEnv().actuation == Actuation()
