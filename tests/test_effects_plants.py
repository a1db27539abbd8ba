"""The new plant effects (stiction, spring with a rest position, com_offset, actuator_lag): one law
in furuta_gym.effects, the same in the MuJoCo plant and in any model + WithEffects; and the
measured-like experiments that exercise them (sine_sweep, closed_loop_prbs).

Measured (this machine, 2026): MuJoCo vs analytic + WithEffects, generalized forces at 400 random
states ≤ 1e-17 N·m absolute; 0.5 s trajectories ≤ 2.4e-9 (the nominal MJCF's own floor, the
same without effects). Actuator lag τ = 5 ms, 0.2 s of ±3 V steps: MuJoCo (u_m integrated per RK4
stage) vs the env's model path (u_m's exact mean held per period) ≤ 6.5e-5 rad, ≤ 0.34 % of what
the lag itself changes (O(dt/τ): 0.7 % at τ = 2 ms, 0.08 % at 20 ms); MuJoCo itself is within
6e-7 rad of a 200-substep reference of the continuous lag.
"""

import dataclasses
import math
import pickle

import gymnasium as gym
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import furuta_gym
from furuta_gym import lagrangian as lag
from furuta_gym.effects import (
    EFFECT_UNITS,
    INPUT_EFFECTS,
    JOINT_EFFECTS,
    ActuatorLag,
    Effect,
    WithEffects,
)
from furuta_gym.envs._backends import MujocoBackend, make_backend
from furuta_gym.models import Furuta
from furuta_gym.rigs import measured_like
from furuta_gym.systems import get_spec

furuta_gym.enable_x64()

FURUTA_ID = "furuta_gym/Furuta-v0"
CASES = {
    "stiction": [
        Effect("coulomb_friction", "alpha", 8e-4),
        Effect("stiction", "alpha", 6e-4, stribeck_velocity=0.1),
        Effect("coulomb_friction", "beta", 5e-5),
        Effect("stiction", "beta", 5e-5),
    ],
    "spring_reference": [Effect("spring", "alpha", 1.5e-3, reference=0.4)],
    "com_offset": [Effect("com_offset", "beta", 2e-3)],
    "all": [
        Effect("coulomb_friction", "alpha", 8e-4),
        Effect("stiction", "alpha", 6e-4),
        Effect("spring", "alpha", 1.5e-3, reference=-0.3),
        Effect("com_offset", "beta", 0.05),
    ],
}


# ----------------------------------------------------------------------------- vocabulary


def test_vocabulary_units_and_validation():
    assert set(EFFECT_UNITS) == set(JOINT_EFFECTS + INPUT_EFFECTS)
    assert {"stiction", "com_offset"} <= set(JOINT_EFFECTS) and "actuator_lag" in INPUT_EFFECTS
    spec = get_spec("furuta")
    assert Effect("stiction", "alpha", 1e-3).unit(spec) == "N m"
    assert Effect("com_offset", "beta", 1e-3).unit(spec) == "rad"
    assert Effect("com_offset", "p", 1e-3).unit(get_spec("nmsd")) == "m"
    assert Effect("actuator_lag", "u", 0.01).unit(spec) == "s"
    with pytest.raises(ValueError, match="stribeck_velocity must be > 0"):
        Effect("stiction", "alpha", 1e-3, stribeck_velocity=0.0)
    with pytest.raises(ValueError, match="acts on the input"):
        Effect("actuator_lag", "alpha", 0.01)
    with pytest.raises(ValueError, match="acts on a joint"):
        Effect("com_offset", "u", 0.01)
    with pytest.raises(ValueError, match="unknown effect 'stickiness'"):
        Effect("stickiness", "alpha", 1.0)


def test_stiction_law_and_com_offset_potential():
    e = Effect("stiction", "beta", 0.01, stribeck_velocity=0.2)
    for v in (-0.3, 0.05, 0.2, 1.0):
        expected = -0.01 * math.exp(-((v / 0.2) ** 2)) * np.sign(v)
        assert float(e.generalized_force(0.0, v)) == pytest.approx(expected)
    assert float(e.generalized_force(0.0, 0.0)) == 0.0  # sgn(0) = 0
    smooth = float(e.generalized_force(0.0, 1e-3, coulomb_smoothing=1e-3))
    assert smooth == pytest.approx(-0.01 * math.exp(-((1e-3 / 0.2) ** 2)) * math.tanh(1.0))
    # com_offset: the pendulum's potential seen through a shifted zero, V = ½mp g Lp (1 − cos(β − δ))
    base, delta = Furuta(), 0.05
    m = WithEffects(base, [Effect("com_offset", "beta", delta)])
    q = jnp.array([0.3, 1.1])
    p = base.params
    assert float(m.potential(q)) == pytest.approx(0.5 * p.mp * p.g * p.Lp * (1 - math.cos(1.1 - delta)))
    extra = lag.potential_derived_force(m, q, q) - lag.potential_derived_force(base, q, q)
    law = Effect("com_offset", "beta", delta).com_offset_force(base.potential, q, base.spec)
    np.testing.assert_allclose(extra, law, atol=1e-15)
    with pytest.raises(ValueError, match="com_offset_force"):
        Effect("com_offset", "beta", delta).generalized_force(0.0, 0.0)


def test_with_effects_rejects_actuator_lag():
    with pytest.raises(ValueError, match="actuator_lag has no memoryless Lagrangian form"):
        WithEffects(Furuta(), [Effect("actuator_lag", "u", 0.005)])


# ----------------------------------------------------------------------------- MuJoCo = model


@pytest.mark.parametrize("name", sorted(CASES))
def test_mujoco_forces_equal_model_with_effects(name):
    """Whole right-hand side M q̈ = … at random states, including exactly zero velocities (the
    sgn law's sgn(0) = 0) and velocities around the Stribeck velocity."""
    effects = CASES[name]
    backend = MujocoBackend("furuta", effects=effects)
    model = WithEffects(Furuta(), effects)
    rhs = jax.jit(
        lambda q, qd, u: (
            lag.coriolis_force(model, q, qd)
            - lag.potential_derived_force(model, q, qd)
            - model.nonconservative_force(q, qd)
            - model.input_force(q, qd, u)
        )
    )
    rng = np.random.default_rng(0)
    d = backend.data
    for i in range(400):
        q, qd, u = rng.uniform(-4, 4, 2), rng.uniform(-0.3, 0.3, 2), rng.uniform(-5, 5, 1)
        if i % 4 == 0:
            qd[i % 8 // 4] = 0.0
        d.qpos[:], d.qvel[:], d.ctrl[:] = q, qd, u
        with backend.passive_forces():
            mujoco.mj_forward(backend.model, d)
        ours = d.qfrc_bias - d.qfrc_passive - d.qfrc_actuator
        np.testing.assert_allclose(ours, rhs(q, qd, u), rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", sorted(CASES))
def test_mujoco_trajectory_equals_model_with_effects(name):
    """0.5 s of random voltages from hanging and from near upright: ≤ 1e-8 (measured ≤ 2.4e-9,
    the same as with no effect), while the effect itself moves the state by far more."""
    effects = CASES[name]
    us = np.repeat(np.random.default_rng(0).uniform(-3, 3, 13), 20)[:250]
    for x0 in ([0.2, 0.3, 0.0, 0.0], [0.0, np.pi - 0.2, 1.0, 0.0]):
        x0 = np.array(x0)
        backends = [
            MujocoBackend("furuta", effects=effects),
            make_backend("furuta", Furuta(), effects=effects),
            MujocoBackend("furuta"),
        ]
        for b in backends:
            b.reset(x0)
        xs = np.array([[b.step(np.array([u])) for b in backends] for u in us])
        assert np.max(np.abs(xs[:, 0] - xs[:, 1])) <= 1e-8
        assert np.max(np.abs(xs[:, 0] - xs[:, 2])) > 1e-3


def test_spring_reference_and_com_offset_rest_where_they_should():
    """The cable's neutral and the pendulum's shifted bottom are equilibria of the MuJoCo plant."""
    plant = MujocoBackend(
        "furuta", effects=[Effect("spring", "alpha", 2e-3, reference=0.4), Effect("com_offset", "beta", 0.05)]
    )
    plant.reset(np.array([0.4, 0.05, 0.0, 0.0]))
    for _ in range(250):
        x = plant.step(np.zeros(1))
    np.testing.assert_allclose(x, [0.4, 0.05, 0.0, 0.0], atol=1e-12)
    plant = MujocoBackend("furuta", effects=[Effect("com_offset", "beta", 0.05)])
    plant.reset(np.zeros(4))  # released at β = 0, off the new bottom: swings about β = δ
    betas = np.array([plant.step(np.zeros(1))[1] for _ in range(2500)])
    assert betas.mean() == pytest.approx(0.05, rel=0.02) and betas.min() > -1e-3


def test_com_offset_on_a_joint_gravity_does_not_act_on_is_refused():
    with pytest.raises(ValueError, match="com_offset' on joint 'p'.*spring', 'p', k, reference"):
        MujocoBackend("nmsd", effects=[Effect("com_offset", "p", 0.01)])
    with pytest.raises(ValueError, match="com_offset' on joint 'p'"):
        gym.make("furuta_gym/NMSD-v0", effects=[Effect("com_offset", "p", 0.01)])
    with pytest.raises(ValueError, match="com_offset' on joint 'alpha'"):
        MujocoBackend("furuta", effects=[Effect("com_offset", "alpha", 0.01)])


def test_mujoco_backend_with_new_effects_pickles():
    effects = CASES["all"] + [Effect("actuator_lag", "u", 0.005)]
    a = MujocoBackend("furuta", effects=effects)
    a.reset(np.array([0.1, 0.2, 0.0, 0.0]))
    for _ in range(20):
        a.step(np.array([2.0]))
    b = pickle.loads(pickle.dumps(a))
    np.testing.assert_array_equal(b.lagged_input, a.lagged_input)
    for _ in range(20):
        np.testing.assert_array_equal(a.step(np.array([-1.0])), b.step(np.array([-1.0])))


# ----------------------------------------------------------------------------- actuator lag


def test_actuator_lag_step_response_has_its_time_constant():
    tau, dt = 0.01, 0.002
    plant = MujocoBackend("furuta", effects=[Effect("actuator_lag", "u", tau)])
    plant.reset(np.zeros(4))
    assert plant.lagged_input[0] == 0.0  # reset: u_m = 0
    p = plant.parameters
    for _ in range(round(tau / dt)):
        x = plant.step(np.array([1.0]))
    # the rotor's actuator torque kt/Rm·(u_m − km·α̇) gives u_m back
    mujoco.mj_forward(plant.model, plant.data)
    u_m = plant.data.qfrc_actuator[0] / (p["kt"] / p["Rm"]) + p["km"] * x[2]
    assert u_m == pytest.approx(1 - math.exp(-1), rel=1e-4)
    assert plant.lagged_input[0] == pytest.approx(1 - math.exp(-1), rel=1e-4)
    # the model path's exact discretisation: u_m at τ, and the held means carry its exact integral
    lag_ = ActuatorLag(tau)
    means = [lag_.advance(np.ones(1), dt)[0] for _ in range(5)]
    assert lag_.state[0] == pytest.approx(1 - math.exp(-1), rel=1e-12)
    assert sum(means) * dt == pytest.approx(tau - tau * (1 - math.exp(-1)), rel=1e-12)


def _run(env, actions, x0):
    env.reset(options={"state": x0})
    return np.array([x0] + [env.step(np.array([a]))[4]["state"] for a in actions])


@pytest.mark.parametrize("kwargs", [{}, {"frame_skip": 2, "actuation_delay": 0.002}], ids=["500Hz", "split-delay"])
def test_actuator_lag_mujoco_and_model_path_agree(kwargs):
    """τ = 5 ms, 0.2 s of ±3 V steps: measured ≤ 6.5e-5 rad and ≤ 0.34 % of the lag's own effect."""
    effects = [Effect("actuator_lag", "u", 0.005)]
    x0 = np.array([0.0, 0.3, 0.0, 0.0])
    acts = np.repeat(np.random.default_rng(0).uniform(-3, 3, 10), 10 // kwargs.get("frame_skip", 1))
    mj = _run(gym.make(FURUTA_ID, effects=effects, **kwargs).unwrapped, acts, x0)
    an = _run(gym.make(FURUTA_ID, effects=effects, dynamics="analytic", **kwargs).unwrapped, acts, x0)
    nominal = _run(gym.make(FURUTA_ID, **kwargs).unwrapped, acts, x0)
    diff = np.max(np.abs(mj[:, :2] - an[:, :2]))
    effect = np.max(np.abs(mj[:, :2] - nominal[:, :2]))
    assert diff <= 1.5e-4 and diff <= 0.01 * effect, (diff, effect)


@pytest.mark.parametrize("dynamics", ["mujoco", "analytic"])
def test_env_with_actuator_lag_pickles_and_reports_its_state(dynamics):
    env = gym.make(FURUTA_ID, effects=[Effect("actuator_lag", "u", 0.005)], dynamics=dynamics).unwrapped
    assert any("actuator_lag" in f for f in env.per_episode_state_features())
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([3.0]))
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(10):
        a, b = env.step(np.array([-2.0])), clone.step(np.array([-2.0]))
        np.testing.assert_array_equal(a[0], b[0])


# ----------------------------------------------------------------------------- measured-like data


def _longest_still_run(alpha: np.ndarray, dt: float, off_zero: float = 0.05) -> float:
    """Longest time the encoder count stays the same at |α| > off_zero."""
    change = np.flatnonzero(np.diff(alpha) != 0) + 1
    starts, ends = np.r_[0, change], np.r_[change, len(alpha)]
    still = [(e - s) * dt for s, e in zip(starts, ends, strict=True) if abs(alpha[s]) > off_zero]
    return max(still, default=0.0)


def test_sine_sweep_rotor_sticks_off_zero_against_a_cable_spring():
    effects = [Effect("spring", "alpha", 1.5e-3, reference=0.0), Effect("coulomb_friction", "alpha", 8e-4)]
    data = measured_like("furuta", effects, excitation="sine_sweep", n_trajectories=4, duration=10.0, seed=0)
    assert all(tr.qd is None and tr.q.shape == (5001, 2) for tr in data)
    step = 2 * np.pi / 2048
    assert np.allclose(data[0].q / step, np.round(data[0].q / step))  # encoder counts
    assert abs(data[0].q[0, 1]) < 0.06 and abs(data[0].q[0, 0]) < 0.11  # from rest, hanging
    u = np.concatenate([tr.u[:, 0] for tr in data])
    assert 0.15 < np.mean(u == 0) < 0.5 and np.abs(u).max() <= 2.0  # sines with rests
    still = [_longest_still_run(tr.q[:, 0], 0.002) for tr in data]
    assert max(still) >= 0.5, still


def test_closed_loop_prbs_balances_with_the_rig_effects():
    effects = [
        Effect("coulomb_friction", "alpha", 3e-4),
        Effect("com_offset", "beta", 2e-3),
        Effect("actuator_lag", "u", 0.005),
    ]
    data = measured_like("furuta", effects, excitation="closed_loop_prbs", n_trajectories=2, duration=10.0, seed=0)
    for tr in data:
        assert np.max(np.abs(tr.q[:, 1] - np.pi)) < 0.5
        assert np.mean(np.abs(tr.u) >= 10.0) < 0.01  # saturation is rare (here: never)
        assert 0.4 < np.sqrt(np.mean(tr.u**2)) < 2.0  # the PRBS and the controller act
    with pytest.raises(ValueError, match="Furuta"):
        measured_like("nmsd", excitation="sine_sweep")
    with pytest.raises(ValueError, match="excitation must be one of"):
        measured_like("furuta", excitation="square")


def test_the_closed_loop_experiment_is_an_object_whose_knobs_act():
    """``excitation=ClosedLoopBalancing(...)``: its defaults are ``"closed_loop_prbs"`` bit for
    bit; a lower voltage limit clips the command; a subclass sees every run's signals (how a
    study records its feed-forward); bad gains are one clear error."""
    from furuta_gym.rigs import ClosedLoopBalancing

    short = dict(n_trajectories=2, duration=0.6, seed=4)
    named = measured_like("furuta", excitation="closed_loop_prbs", **short)
    default = measured_like("furuta", excitation=ClosedLoopBalancing(), **short)
    assert all(np.array_equal(a.u, b.u) and np.array_equal(a.q, b.q) for a, b in zip(named, default, strict=True))
    clipped = measured_like("furuta", excitation=ClosedLoopBalancing(voltage_limit=0.3), **short)
    assert np.abs(np.concatenate([tr.u for tr in clipped])).max() == pytest.approx(0.3)

    @dataclasses.dataclass(frozen=True)
    class Recorded(ClosedLoopBalancing):
        feeds: list = dataclasses.field(default_factory=list, compare=False)

        def signals(self, n, dt, rng):
            rotor, pendulum, feed = super().signals(n, dt, rng)
            self.feeds.append(feed)
            return rotor, pendulum, feed

    recorded = Recorded(feedforward=1.0)  # twice the rig's: the same draws, the feed doubled
    louder = measured_like("furuta", excitation=recorded, **short)
    assert len(recorded.feeds) == 2 and np.abs(recorded.feeds[0]).max() <= 1.0 + 1e-12
    assert not np.array_equal(louder[0].u, default[0].u)
    with pytest.raises(ValueError, match="gains needs exactly"):
        ClosedLoopBalancing(gains={"kp_theta": 6.0})
    with pytest.raises(ValueError, match="velocity_cutoff must be > 0"):
        ClosedLoopBalancing(velocity_cutoff=0.0)


@pytest.mark.parametrize("excitation", ["sine_sweep", "closed_loop_prbs"])
def test_true_velocities_are_the_simulators_and_only_on_request(excitation):
    """``true_velocities=True`` attaches the simulated velocities: the derivative of the exact
    angles (central differences at 2 ms agree to a small fraction of the motion)."""
    short = dict(n_trajectories=1, duration=0.6, seed=3, excitation=excitation, quantize=False)
    (plain,) = measured_like("furuta", **short)
    (tr,) = measured_like("furuta", true_velocities=True, **short)
    assert plain.qd is None and tr.qd is not None and tr.qd.shape == tr.q.shape
    assert np.array_equal(plain.q, tr.q) and np.array_equal(plain.u, tr.u)  # the same run
    central = (tr.q[2:] - tr.q[:-2]) / (2 * tr.dt)
    scale = np.abs(tr.qd).max(axis=0)
    assert np.all(np.abs(central - tr.qd[1:-1]).max(axis=0) < 0.05 * scale), scale


# ----------------------------------------------------------------------------- a cable whose neutral moves


def test_cable_neutral_is_the_play_operator():
    from furuta_gym.effects import CableNeutral

    n = CableNeutral(Effect("hysteretic_spring", "alpha", 2e-3, reference=0.1, play=0.3))
    assert n.force(0.3) == 2e-3 * (0.1 - 0.3)  # within the play: a spring about its neutral
    n.advance(0.3)
    assert n.neutral == 0.1
    assert n.force(1.0) == pytest.approx(-2e-3 * 0.3)  # beyond it the neutral is dragged along
    n.advance(1.0)
    assert n.neutral == pytest.approx(0.7)
    n.advance(0.5)  # back within the play: the neutral stays where the swing left it
    assert n.neutral == pytest.approx(0.7) and n.force(0.5) == pytest.approx(2e-3 * 0.2)
    n.reset()
    assert n.neutral == 0.1
    with pytest.raises(ValueError, match="play must be >= 0"):
        Effect("hysteretic_spring", "alpha", 2e-3, play=-0.1)


def test_a_rotor_comes_back_to_where_a_swing_left_a_hysteretic_cable_not_to_zero():
    effects = [Effect("hysteretic_spring", "alpha", 2e-3, play=0.3)]
    plant = MujocoBackend("furuta", 10, effects, timestep=2e-4)
    fixed = MujocoBackend("furuta", 10, [Effect("spring", "alpha", 2e-3)], timestep=2e-4)
    for backend in (plant, fixed):
        backend.reset(np.zeros(4))
    for k in range(4000):  # half a second of 1 V at 1 Hz (one push), then 7.5 s at rest
        u = np.array([math.sin(2 * math.pi * k * 0.002) if k < 250 else 0.0])
        x, x_fixed = plant.step(u), fixed.step(u)
    neutral = plant._neutrals[0][1].neutral
    assert neutral > 0.3  # the push dragged the neutral along
    assert x[0] == pytest.approx(neutral, abs=0.02)  # the rotor settles on the dragged neutral
    assert abs(x_fixed[0]) < 0.02  # a fixed spring pulls it back to zero
    plant.reset(np.zeros(4))
    assert plant._neutrals[0][1].neutral == 0.0  # a reset restores the cable
    # a model backend keeps no such state: a clear error, not a silently different plant
    with pytest.raises(ValueError, match="memory"):
        make_backend("furuta", "analytic", substeps=1, effects=effects)
    with pytest.raises(ValueError, match="no memoryless Lagrangian form"):
        WithEffects(Furuta(), effects)
