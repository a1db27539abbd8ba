"""Learned models (DeLaN, APHYNITY, augmented DeLaN): structure guaranteed by construction."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym import lagrangian as lg
from furuta_gym.models import (
    MODEL_KINDS,
    NMSD,
    Aphynity,
    AugmentedDeLaN,
    DeLaN,
    Furuta,
    FurutaParameters,
    NMSDParameters,
    make_model,
)

# one compile per model structure instead of op-by-op dispatch of the autodiff graph
forward_dynamics = eqx.filter_jit(lg.forward_dynamics)

CASES = [(s, k) for s in ("furuta", "nmsd") for k in ("dln", "aph", "adln")]


@pytest.fixture(scope="module")
def models():
    return {(s, k): make_model(s, k, jax.random.PRNGKey(7)) for s, k in CASES}


def _random_states(n, count=20, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-3, 3, (count, n)), rng.uniform(-10, 10, (count, n))


@pytest.mark.parametrize("system,kind", CASES)
def test_mass_matrix_symmetric_positive_definite_and_potential_zero_at_origin(models, system, kind):
    model = models[(system, kind)]
    n = model.spec.n_dof
    qs, _ = _random_states(n)
    Ms = np.asarray(jax.vmap(model.mass_matrix)(jnp.asarray(qs)))
    np.testing.assert_array_equal(Ms, np.swapaxes(Ms, 1, 2))
    assert np.linalg.eigvalsh(Ms).min() > 0
    assert float(model.potential(jnp.zeros(n))) == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("kind", ["dln", "adln", "aph"])
def test_angles_enter_periodically(models, kind):
    """Angles enter as (cos, sin): q and q + 2π give the same M, V and τ_NC."""
    model = models[("furuta", kind)]
    qs, qds = _random_states(2, 5, seed=1)
    for q, qd in zip(qs, qds, strict=True):
        q2 = q + 2 * np.pi * np.array([1.0, -1.0])
        np.testing.assert_allclose(model.mass_matrix(q), model.mass_matrix(q2), rtol=1e-12, atol=0)
        np.testing.assert_allclose(model.potential(q), model.potential(q2), rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(
            model.nonconservative_force(q, qd), model.nonconservative_force(q2, qd), rtol=1e-9, atol=1e-15
        )


@pytest.mark.parametrize("system,kind", CASES)
def test_scale_leaves_free_dynamics_unchanged_but_not_forced(models, system, kind):
    """The overall scale multiplies L and τ_NC but not τ_u: free motion cannot see it (that is why
    it is fitted on a forced trajectory), forced motion can."""
    model = models[(system, kind)]
    scaled = model.with_scale(3.0)
    n = model.spec.n_dof
    q, qd = (jnp.asarray(a[0]) for a in _random_states(n, 1, seed=2))
    zero, one = jnp.zeros(1), jnp.ones(1)
    np.testing.assert_allclose(forward_dynamics(model, q, qd, zero), forward_dynamics(scaled, q, qd, zero), rtol=1e-10)
    forced_a = forward_dynamics(model, q, qd, one) - forward_dynamics(model, q, qd, zero)
    forced_b = forward_dynamics(scaled, q, qd, one) - forward_dynamics(scaled, q, qd, zero)
    np.testing.assert_allclose(forced_a, 3.0 * forced_b, rtol=1e-10)


def test_delan_known_structure_of_forces():
    m = make_model("nmsd", "dln", 0, damping_init=(0.5, 0.1))
    qd = jnp.array([2.0])
    np.testing.assert_allclose(m.nonconservative_force(jnp.zeros(1), qd), [-0.5 * 2 - 0.1 * 8], rtol=1e-14)
    np.testing.assert_allclose(m.input_force(jnp.zeros(1), qd, jnp.array([1.5])), [1.5])
    f = make_model("furuta", "dln", 0, damping_init=(5.1e-4, 1.5e-5))
    qd = jnp.array([3.0, -2.0])
    np.testing.assert_allclose(f.nonconservative_force(jnp.zeros(2), qd), [-5.1e-4 * 3, 1.5e-5 * 2], rtol=1e-12)
    # τ_u holds only the voltage term; the back-EMF is lumped into the rotor damping
    np.testing.assert_allclose(f.input_force(jnp.zeros(2), qd, jnp.array([2.0])), [0.042 / 8.4 * 2, 0.0])
    assert float(f.rotor_friction) == pytest.approx(5.1e-4 - 0.042**2 / 8.4, rel=1e-12)


def test_aphynity_back_emf_kept_in_the_prior_breaks_the_scale_symmetry():
    """With ``prior_back_emf=True`` the Furuta prior's τ_u holds −(kt·km/Rm)·α̇, which the overall
    scale does not multiply: free motion then changes with the scale, so the scale fitted on a
    forced trajectory would change the free dynamics the model was trained on (the default lumps
    the back-EMF into F_a instead, and the test above holds)."""
    kept = make_model("furuta", "aph", 0, prior_back_emf=True)
    q, qd, zero = jnp.array([0.3, 1.0]), jnp.array([4.0, -2.0]), jnp.zeros(1)
    a = forward_dynamics(kept, q, qd, zero)
    b = forward_dynamics(kept.with_scale(3.0), q, qd, zero)
    assert abs(float(a[0] - b[0])) > 1e-3 * abs(float(a[0]))
    lumped = make_model("furuta", "aph", 0)
    np.testing.assert_allclose(lumped.input_force(q, qd, jnp.array([2.0])), [0.042 / 8.4 * 2, 0.0], rtol=1e-14)
    np.testing.assert_allclose(
        kept.input_force(q, qd, jnp.array([2.0])), [0.042 / 8.4 * (2 - 0.042 * 4), 0.0], rtol=1e-14
    )


@pytest.mark.parametrize("system", ["furuta", "nmsd"])
def test_aphynity_prior_is_the_frictionless_analytic_model(system):
    m = make_model(system, "aph", 0, prior_back_emf=True) if system == "furuta" else make_model(system, "aph", 0)
    if system == "furuta":
        ref = Furuta(params=FurutaParameters(c_r=0.0, c_p=0.0))
    else:
        ref = NMSD(params=NMSDParameters(b1=0.0, b2=0.0))
    n = ref.spec.n_dof
    qs, qds = _random_states(n, 5, seed=3)
    for q, qd in zip(qs, qds, strict=True):
        np.testing.assert_allclose(m.mass_matrix(q), ref.mass_matrix(q), rtol=1e-14)
        np.testing.assert_allclose(m.potential(q), ref.potential(q), rtol=1e-14)
        np.testing.assert_allclose(m.input_force(q, qd, jnp.ones(1)), ref.input_force(q, qd, jnp.ones(1)), rtol=1e-14)
        np.testing.assert_allclose(m.nonconservative_force(q, qd), m.augmentation(q, qd))
    # physical parameters are learned as log-ratios: exp(θ) multiplies the nominal value
    moved = eqx.tree_at(lambda a: a.log_ratios, m, jnp.log(2.0) * jnp.ones_like(m.log_ratios))
    first = "mr" if system == "furuta" else "m"
    assert float(moved.physical_parameters[first]) == pytest.approx(2.0 * dict(m.nominal)[first])


def test_trainable_leaves_exclude_scale_and_only_weights_are_decayed(models):
    model = models[("furuta", "adln")]
    train = model.trainable()
    assert train.scale is False
    decayed = model.decayed()
    assert decayed.lagrangian_nets.mass_net.layers[0].weight is True
    assert decayed.lagrangian_nets.mass_net.layers[0].bias is False
    aph = models[("nmsd", "aph")]
    assert aph.decayed().log_ratios is False and aph.trainable().log_ratios is True


def test_factory_rebuilds_identical_skeleton_and_rejects_bad_arguments():
    a = make_model("furuta", "dln", 0, hidden=(8, 8))
    b = make_model("furuta", "dln", 0, **a.hyperparameters)
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    assert isinstance(a, DeLaN) and MODEL_KINDS == {"dln": DeLaN, "aph": Aphynity, "adln": AugmentedDeLaN}
    with pytest.raises(ValueError, match="model kind"):
        make_model("furuta", "mlp", 0)
    with pytest.raises(ValueError, match="unknown system"):
        make_model("cartpole", "dln", 0)
    with pytest.raises(ValueError, match="unknown DeLaN hyper-parameters"):
        make_model("nmsd", "dln", 0, width=3)
    with pytest.raises(ValueError, match="prior names unknown"):
        make_model("nmsd", "aph", 0, prior=(("mass", 2.0),))
