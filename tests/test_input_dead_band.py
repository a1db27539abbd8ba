"""The input's dead band (issue 66): u_eff = sgn(u)·max(|u| − d, 0), one law in
furuta_gym.effects, the same in the analytic model's τ_u and in the MuJoCo plant's control.

Measured (this machine, 2026-12): MuJoCo vs analytic + WithEffects with d = 50 mV, 0.5 s of
random voltages within ±0.4 V: ≤ 1e-8 rad as every other effect (the nominal MJCF's own floor),
while the dead band itself moves the state by more than 1e-3."""

import pickle

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym
from furuta_gym.effects import Effect, WithEffects, dead_band
from furuta_gym.envs import Plant
from furuta_gym.envs._backends import MujocoBackend, make_backend
from furuta_gym.models import Furuta
from furuta_gym.systems import get_spec

furuta_gym.enable_x64()

FURUTA_ID = "furuta_gym/Furuta-v0"
BAND = Effect("input_dead_band", "u", 0.05)


def test_the_law_is_zero_inside_slope_one_outside_and_odd():
    u = np.array([-1.0, -0.2, -0.05, -0.03, 0.0, 0.03, 0.05, 0.2, 1.0])
    np.testing.assert_allclose(dead_band(u, 0.05), [-0.95, -0.15, 0.0, 0.0, 0.0, 0.0, 0.0, 0.15, 0.95], atol=1e-15)
    v = np.linspace(-2, 2, 401)
    np.testing.assert_array_equal(dead_band(-v, 0.05), -dead_band(v, 0.05))  # odd
    outside = v[np.abs(v) > 0.06]
    slope = (dead_band(outside + 1e-3, 0.05) - dead_band(outside, 0.05)) / 1e-3
    np.testing.assert_allclose(slope, 1.0, rtol=1e-9)
    np.testing.assert_array_equal(dead_band(v, 0.0), v)  # no width: the input itself
    np.testing.assert_allclose(np.asarray(dead_band(jnp.asarray(u), 0.05, jnp)), dead_band(u, 0.05), atol=1e-15)


def test_unit_bounds_and_its_place_in_the_model():
    assert BAND.unit(get_spec("furuta")) == "V"
    assert Effect("input_dead_band", "u", 0.1).unit(get_spec("nmsd")) == "N"
    for bad in (-0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="width must be in"):
            Effect("input_dead_band", "u", bad)
    with pytest.raises(ValueError, match="acts on the input"):
        Effect("input_dead_band", "alpha", 0.05)
    base, model = Furuta(), WithEffects(Furuta(), [BAND])
    q, qd = jnp.array([0.1, 0.2]), jnp.array([0.3, -0.1])
    for u in (0.03, -0.04, 0.3, -1.2):
        expected = base.input_force(q, qd, jnp.array([float(dead_band(u, 0.05))]))
        np.testing.assert_allclose(model.input_force(q, qd, jnp.array([u])), expected, atol=1e-15)


def test_mujoco_trajectory_equals_model_with_a_dead_band():
    us = np.repeat(np.random.default_rng(0).uniform(-0.4, 0.4, 13), 20)[:250]
    for x0 in ([0.2, 0.3, 0.0, 0.0], [0.0, np.pi - 0.2, 1.0, 0.0]):
        backends = [
            MujocoBackend("furuta", effects=[BAND]),
            make_backend("furuta", Furuta(), effects=[BAND]),
            MujocoBackend("furuta"),
        ]
        for b in backends:
            b.reset(np.array(x0))
        xs = np.array([[b.step(np.array([u])) for b in backends] for u in us])
        assert np.max(np.abs(xs[:, 0] - xs[:, 1])) <= 1e-8
        assert np.max(np.abs(xs[:, 0] - xs[:, 2])) > 1e-3


def test_a_plant_with_a_dead_band_and_a_delay_runs_alike_in_both_backends():
    """``plant=`` carries it through gym.make, after the input delay, in MuJoCo and analytically."""
    plant = Plant.nominal("furuta", effects=[Effect("input_delay", "u", 0.004), BAND])
    acts = np.repeat(np.random.default_rng(1).uniform(-0.3, 0.3, 10), 10)
    runs = {}
    for dynamics in ("mujoco", "analytic"):
        env = gym.make(FURUTA_ID, plant=plant, dynamics=dynamics).unwrapped
        env.reset(options={"state": np.array([0.0, 0.3, 0.0, 0.0])})
        runs[dynamics] = np.array([env.step(np.array([a]))[4]["state"] for a in acts])
    without = gym.make(FURUTA_ID, plant=Plant.nominal("furuta", [Effect("input_delay", "u", 0.004)])).unwrapped
    without.reset(options={"state": np.array([0.0, 0.3, 0.0, 0.0])})
    ref = np.array([without.step(np.array([a]))[4]["state"] for a in acts])
    assert np.max(np.abs(runs["mujoco"][:, :2] - runs["analytic"][:, :2])) <= 1e-6
    assert np.max(np.abs(runs["mujoco"][:, :2] - ref[:, :2])) > 1e-3


def test_mujoco_backend_with_a_dead_band_pickles_and_refuses_a_lag():
    a = MujocoBackend("furuta", effects=[BAND])
    a.reset(np.array([0.1, 0.2, 0.0, 0.0]))
    b = pickle.loads(pickle.dumps(a))
    for u in (0.04, 0.2, -0.3):
        np.testing.assert_array_equal(a.step(np.array([u])), b.step(np.array([u])))
    with pytest.raises(ValueError, match="input_dead_band with an actuator_lag"):
        MujocoBackend("furuta", effects=[BAND, Effect("actuator_lag", "u", 0.005)])


def test_the_written_mjcf_says_it_cannot_express_the_dead_band_and_keeps_it(tmp_path):
    from furuta_gym.envs import plant_mjcf

    plant = Plant.nominal("furuta", [Effect("coulomb_friction", "alpha", 2e-4), BAND])
    text = plant_mjcf(plant)
    comment = text[text.index("<!--") : text.index("-->")]
    assert "Not expressed in MJCF (furuta-gym's plant= restores them from <custom>): input_dead_band:u." in comment
    path = tmp_path / "rig.xml"
    path.write_text(text)
    assert BAND in Plant.load(path).effects


def test_the_diagnosis_scores_a_plant_with_its_delay_then_its_dead_band():
    """InputDynamics.of_effects: what a plant's effects put between the log and the plant, in the
    plant's order (the delay, then the dead band)."""
    from furuta_gym.diagnose import InputDynamics

    effects = [
        Effect("input_dead_band", "u", 0.05),
        Effect("input_delay", "u", 0.004),
        Effect("coulomb_friction", "alpha", 1e-4),
    ]
    dyn = InputDynamics.of_effects(effects)
    assert (dyn.kind, dyn.seconds, dyn.dead_band) == ("delay", 0.004, 0.05)
    u = np.array([0.0, 0.2, -0.2, 0.03, -0.03, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(dyn.apply(u, 0.002), dead_band(InputDynamics("delay", 0.004).apply(u, 0.002), 0.05))
    assert InputDynamics.of_effects([Effect("coulomb_friction", "alpha", 1e-4)]) == InputDynamics()
    assert InputDynamics.of_effects([Effect("actuator_lag", "u", 0.01)]) == InputDynamics("lag", 0.01)
