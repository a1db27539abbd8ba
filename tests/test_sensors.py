"""One sensor model (furuta_gym.sensors.Sensors) for the envs, the data generation and the
controllers' closed loops: one type, read the same way by all three."""

import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym import sensors as spine
from furuta_gym.controllers import LQR, Sensor, closed_loop
from furuta_gym.envs import EnvArgumentError, FurutaEnv, Sensors
from furuta_gym.models import Furuta
from furuta_gym.signals import ENCODER_COUNTS_PER_REV
from furuta_gym.systems import get_spec
from furuta_gym.training import datagen
from furuta_gym.training.datagen import FurutaRecipe, generate_datasets

FURUTA, NMSD = get_spec("furuta"), get_spec("nmsd")


def test_one_type_across_the_layers():
    assert Sensors is spine.Sensors and EnvArgumentError is spine.SettingsError
    assert Sensor() == Sensors.qube() == Sensors(encoder_counts=ENCODER_COUNTS_PER_REV, velocity="filter")
    env = FurutaEnv(sensors=Sensors(encoder_counts=1024, measurement_noise=(0.0, 1e-3)))
    # what the batched envs read of their template, from its settings
    np.testing.assert_array_equal(env.encoder_steps, [2 * np.pi / 1024] * 2)
    np.testing.assert_array_equal(env.noise_std, [0.0, 0.0, 1e-3, 1e-3])
    assert env.per_episode_state_features() == ["measurement_noise"]


def test_noise_per_component_pair_or_scalar():
    assert Sensors(measurement_noise=0.1).noise(FURUTA) == (0.1,) * 4
    assert Sensors(measurement_noise=(0.1, 0.2)).noise(FURUTA) == (0.1, 0.1, 0.2, 0.2)
    assert Sensors(measurement_noise=(0.1, 0.2)).noise(NMSD) == (0.1, 0.2)  # one joint: the same reading
    assert Sensors(measurement_noise=(0, 0, 1, 2)).noise(FURUTA) == (0.0, 0.0, 1.0, 2.0)
    with pytest.raises(EnvArgumentError, match="Sensors.filter_xi"):
        Sensors(filter_xi=0.0)
    with pytest.raises(EnvArgumentError, match="Sensors.filter_omega0"):
        Sensors(filter_omega0=float("inf"))


def _moving_ground_truth(x0s, t, us):
    """A cheap stand-in ground truth that moves (so quantisation, noise and the filter act)."""
    x0s, t = np.asarray(x0s), np.asarray(t)
    n = x0s.shape[1] // 2
    q = x0s[:, None, :n] + 1.3 * np.sin(3.1 * t)[None, :, None]
    qd = x0s[:, None, n:] + 4.03 * np.cos(3.1 * t)[None, :, None]
    return np.concatenate([q, qd], axis=2)


def test_the_data_generation_measures_with_the_same_type():
    """The generators take the one sensor model; the options object they took before (its old name
    still served, deprecated) measures as the Sensors it describes, bit for bit."""
    recipe = FurutaRecipe(
        n_train=2,
        n_test_free=1,
        test_free_duration=1.0,
        n_test_forced=1,
        test_forced_duration=1.0,
        scale_fit_duration=1.0,
    )
    with pytest.warns(DeprecationWarning, match="furuta_gym.sensors.Sensors"):
        options = datagen.SensorOptions(quantize=True, noise_std=1e-3, velocity="filter")
    assert options.sensors == Sensors.qube(measurement_noise=(1e-3, 0.0))
    kw = dict(recipe=recipe, ground_truth=_moving_ground_truth, seed=4)
    a = generate_datasets("furuta", sensor=options, **kw)
    b = generate_datasets("furuta", sensor=options.sensors, **kw)
    for name in a:
        for x, y in zip(a[name], b[name], strict=True):
            np.testing.assert_array_equal(x.q, y.q)
            np.testing.assert_array_equal(x.qd, y.qd)
    step = 2 * np.pi / 2048
    q = np.concatenate([tr.q for tr in a["train"]])
    np.testing.assert_allclose(q / step, np.round(q / step), atol=1e-9)  # on the encoder's grid
    with pytest.raises(ValueError, match="no angular joint"):
        generate_datasets("nmsd", small=True, ground_truth=_moving_ground_truth, sensor=Sensors(encoder_counts=2048))


def test_closed_loops_read_the_same_type():
    model = Furuta()
    lqr = LQR.from_model(model)
    x0 = jnp.array([0.3, np.pi + 0.15, -0.5, 0.4])
    exact_velocity = closed_loop(lqr, model, x0, 50, sensor=Sensors(encoder_counts=2048))
    step = 2 * np.pi / 2048
    obs, xs = np.asarray(exact_velocity.obs), np.asarray(exact_velocity.xs)
    np.testing.assert_allclose(obs[:, :2] / step, np.round(obs[:, :2] / step), atol=1e-9)
    np.testing.assert_array_equal(obs[:, 2:], xs[:-1, 2:])  # velocity="exact": the true velocity
    filtered = np.asarray(closed_loop(lqr, model, x0, 50, sensor=Sensor()).obs)
    assert np.max(np.abs(filtered[:, 2:] - obs[:, 2:])) > 1e-3  # the filter's lag shows
    with pytest.raises(ValueError, match="draws no noise"):
        closed_loop(lqr, model, x0, 50, sensor=Sensors(measurement_noise=1e-3))
