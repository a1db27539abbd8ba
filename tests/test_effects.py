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
