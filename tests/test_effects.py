"""Extra physical effects added to a Lagrangian model follow the documented sign conventions."""

import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym import lagrangian as lg
from furuta_gym.effects import Effect, WithEffects
from furuta_gym.models import NMSD, Furuta

q, qd, u = jnp.array([0.3, 1.2]), jnp.array([2.0, -3.0]), jnp.array([1.5])


def test_each_joint_effect_adds_its_documented_force():
    base = Furuta()
    tau0 = base.nonconservative_force(q, qd)
    cases = {
        "coulomb_friction": -0.01 * np.sign(qd[1]),
        "viscous_friction": -0.01 * qd[1],
        "quadratic_drag": -0.01 * qd[1] * abs(qd[1]),
        "constant_torque": 0.01,
    }
    for name, expected in cases.items():
        m = WithEffects(base, [Effect(name, "beta", 0.01)])
        np.testing.assert_allclose(m.nonconservative_force(q, qd) - tau0, [0.0, expected], atol=1e-15)


def test_spring_is_conservative_and_restoring():
    m = WithEffects(Furuta(), [Effect("spring", "alpha", 2e-3, reference=0.1)])
    dV = m.potential(q) - Furuta().potential(q)
    assert float(dV) == pytest.approx(0.5 * 2e-3 * (0.3 - 0.1) ** 2)
    # the potential-derived force on alpha gains −k(α − α_ref)
    f = lg.potential_derived_force(m, q, qd) - lg.potential_derived_force(Furuta(), q, qd)
    np.testing.assert_allclose(f, [-2e-3 * 0.2, 0.0], atol=1e-15)


def test_input_gain_scales_the_input_force_and_delay_is_refused():
    m = WithEffects(NMSD(), [Effect("input_gain", "u", 0.25)])
    np.testing.assert_allclose(m.input_force(q[:1], qd[:1], u), 1.25 * u)
    with pytest.raises(ValueError, match="input_delay has no memoryless"):
        WithEffects(NMSD(), [Effect("input_delay", "u", 0.01)])


def test_bad_effect_names_and_joints_are_clear_errors():
    with pytest.raises(ValueError, match="unknown effect 'springy'"):
        Effect("springy", "alpha", 1.0)
    with pytest.raises(ValueError, match="acts on the input"):
        Effect("input_gain", "alpha", 1.0)
    with pytest.raises(ValueError, match="'beta' is not a joint of nmsd"):
        WithEffects(NMSD(), [Effect("spring", "beta", 1.0)])


def _rotor_held(limit_value: float, volts: float, seconds: float = 0.5, h: float = 1e-3):
    """Rotor angle and velocity after ``seconds`` of a constant voltage from rest, pendulum
    hanging, with dry friction of limit ``limit_value`` N·m on the rotor that holds (RK4)."""
    from furuta_gym.simulate import rollout_zoh

    model = Furuta()
    limit = jnp.array([limit_value, 0.0])

    def field(x, u_):
        return jnp.concatenate([x[2:], lg.forward_dynamics_with_dry_friction(model, limit, x[:2], x[2:], u_, h)])

    us = jnp.full((int(seconds / h), 1), volts)
    return np.asarray(rollout_zoh(model, jnp.zeros(4), us, h, 1, field)[-1])


def test_dry_friction_that_holds_is_the_plain_dynamics_without_a_limit_and_coulomb_while_sliding():
    model = Furuta()
    free = lg.forward_dynamics_with_dry_friction(model, jnp.zeros(2), q, qd, u, 1e-3)
    np.testing.assert_allclose(free, model.forward_dynamics(q, qd, u), rtol=1e-12)
    # sliding at 2 and -3 rad/s: the friction is -limit·sgn(q̇) on each joint, as Coulomb's law
    coulomb = WithEffects(model, [Effect("coulomb_friction", "alpha", 2e-3), Effect("coulomb_friction", "beta", 1e-4)])
    held = lg.forward_dynamics_with_dry_friction(model, jnp.array([2e-3, 1e-4]), q, qd, u, 1e-3)
    np.testing.assert_allclose(held, coulomb.forward_dynamics(q, qd, u), rtol=1e-10)


def test_dry_friction_that_holds_keeps_a_rotor_at_rest_below_breakaway_and_lets_it_go_above():
    # the motor's stall torque at 0.1 V is (kt/Rm)·0.1 = 5e-4 N·m
    alpha, alpha_dot = _rotor_held(1e-3, 0.1)[[0, 2]]
    assert abs(alpha) < 1e-12 and abs(alpha_dot) < 1e-12  # held exactly: no creep as tanh(q̇/ε) gives
    alpha = _rotor_held(1e-3, 0.3)[0]  # 1.5e-3 N·m > the limit: it turns
    assert alpha > 0.05
    # and slides as Coulomb friction says: the same rotor with the sgn law moves the same way
    from furuta_gym.simulate import rollout_zoh

    coulomb = WithEffects(Furuta(), [Effect("coulomb_friction", "alpha", 1e-3)])
    reference = np.asarray(rollout_zoh(coulomb, jnp.zeros(4), jnp.full((500, 1), 0.3), 1e-3, 1)[-1])
    # (they differ only in the first steps from rest: measured 0.12 %)
    np.testing.assert_allclose(alpha, reference[0], rtol=5e-3)
