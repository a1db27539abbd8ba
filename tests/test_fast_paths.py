"""The speed-motivated rewrites compute the same numbers as the straightforward formulation.

Rewrites checked (see BENCHMARKS.md, batched env section, for why they exist):

* learned models: the (cos, sin) features with a custom jvp reusing the primal values
  (``models._learned.cos_sin``), and DeLaN's Cholesky factor assembled from its entries with
  ``L Lᵀ`` as a product-and-sum, against plain ``jnp.cos``/``jnp.sin`` features, a scatter into
  ``tril_indices`` and ``L @ L.T`` — values, parameter gradients (training) and second
  derivatives (linearisation of the dynamics);
* the XLA:CPU compiler options of the model-backed env steps
  (:func:`furuta_gym.simulate.small_kernel_compiler_options`), against the default compile, for
  DeLaN, APHYNITY, augmented DeLaN and the analytic models.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym import lagrangian as lg
from furuta_gym.models import _augmented, _delan, analytic_model, make_model
from furuta_gym.simulate import rk4_step, small_kernel_compiler_options

LEARNED = [(s, k) for s in ("furuta", "nmsd") for k in ("dln", "aph", "adln")]


def _reference_features(spec, q, position_scale):
    """The original formulation: per-coordinate jnp.cos / jnp.sin, stacked."""
    parts = []
    for i, angular in enumerate(spec.angular):
        if angular:
            parts += [jnp.cos(q[i]), jnp.sin(q[i])]
        else:
            parts.append(q[i] / position_scale)
    return jnp.stack(parts)


def _reference_cholesky(self, q):
    """The original formulation: diagonal matrix, then a scatter of the strict lower triangle."""
    n = self.spec.n_dof
    out = self.mass_net(_reference_features(self.spec, q, self.position_scale))
    diag = jax.nn.softplus(out[:n] + 0.5413248546129181) + self.eps
    L = jnp.diag(diag)
    if n > 1:
        rows, cols = jnp.tril_indices(n, -1)
        L = L.at[rows, cols].set(out[n:])
    return L


def _reference_mass_matrix(self, q):
    L = _reference_cholesky(self, q)
    return self.mass_scale * (L @ L.T)


def _states(n, count=8, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-3.0, 3.0, (count, n))
    qd = rng.uniform(-10.0, 10.0, (count, n))
    u = rng.uniform(-5.0, 5.0, (count, 1))
    return jnp.asarray(q), jnp.asarray(qd), jnp.asarray(u)


def _dynamics_and_parameter_gradient(model, q, qd, u):
    """q̈ at a batch of states and the gradient of Σq̈² w.r.t. every model array (what training
    differentiates), in one compile."""

    def qdd(m):
        return jax.vmap(lambda a, b, c: lg.forward_dynamics(m, a, b, c))(q, qd, u)

    def loss(m):
        return jnp.sum(qdd(m) ** 2)

    return eqx.filter_jit(lambda m: (qdd(m), eqx.filter_grad(loss)(m), jax.vmap(m.mass_matrix)(q)))(model)


def _assert_trees_close(a, b, rtol=1e-12):
    la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
    assert len(la) == len(lb)
    for x, y in zip(la, lb, strict=True):
        x, y = np.asarray(x), np.asarray(y)
        scale = max(np.max(np.abs(y)), 1e-300)
        np.testing.assert_allclose(x, y, rtol=0, atol=rtol * scale)


@pytest.mark.parametrize("system,kind", LEARNED)
def test_learned_model_dynamics_and_gradients_equal_the_reference_formulation(system, kind, monkeypatch):
    model = make_model(system, kind, jax.random.PRNGKey(11))
    # trained-looking weights: scale up so the networks are far from their near-identity start
    model = jax.tree_util.tree_map(lambda a: a * 3.0 if eqx.is_inexact_array(a) else a, model)
    q, qd, u = _states(model.spec.n_dof)
    fast = _dynamics_and_parameter_gradient(model, q, qd, u)

    monkeypatch.setattr(_delan, "coordinate_features", _reference_features)
    monkeypatch.setattr(_augmented, "coordinate_features", _reference_features)
    monkeypatch.setattr(_delan.LagrangianNetworks, "cholesky_factor", _reference_cholesky)
    monkeypatch.setattr(_delan.LagrangianNetworks, "mass_matrix", _reference_mass_matrix)
    reference = _dynamics_and_parameter_gradient(model, q, qd, u)

    assert np.all(np.isfinite(np.asarray(reference[0])))
    for got, want in zip(fast, reference, strict=True):  # q̈, parameter gradient, M(q)
        _assert_trees_close(got, want)


def test_second_derivatives_through_the_features_equal_the_reference(monkeypatch):
    """The linearisation (∂q̈/∂x, a derivative of a derivative) sees the custom jvp twice."""
    model = make_model("furuta", "dln", jax.random.PRNGKey(5))
    x = jnp.asarray([0.4, -2.0, 1.5, -4.0])
    u = jnp.asarray([2.0])
    fast = eqx.filter_jit(lg.linearize)(model, x, u)
    monkeypatch.setattr(_delan, "coordinate_features", _reference_features)
    monkeypatch.setattr(_delan.LagrangianNetworks, "cholesky_factor", _reference_cholesky)
    monkeypatch.setattr(_delan.LagrangianNetworks, "mass_matrix", _reference_mass_matrix)
    reference = eqx.filter_jit(lg.linearize)(model, x, u)
    _assert_trees_close(fast, reference)


@pytest.mark.parametrize("system", ["furuta", "nmsd"])
def test_env_step_compiler_options_do_not_change_the_step(system):
    """The model-backed envs' compile options (YNNPACK for bare products only) give the default
    compile's RK4 step, for every model family, batched (where XLA picks library products)."""
    models = [analytic_model(system)] + [make_model(system, k, jax.random.PRNGKey(3)) for k in ("dln", "aph", "adln")]
    n = models[0].spec.n_dof
    rng = np.random.default_rng(2)
    xs = jnp.asarray(rng.uniform(-2.0, 2.0, (256, 2 * n)))
    us = jnp.asarray(rng.uniform(-5.0, 5.0, (256, 1)))

    def steps(ms, x, u):  # every model in one compile
        return [jax.vmap(lambda a, b, m=m: rk4_step(m, a, b, 0.002))(x, u) for m in ms]

    default = eqx.filter_jit(steps)(models, xs, us)
    tuned = eqx.filter_jit(steps, compiler_options=small_kernel_compiler_options())(models, xs, us)
    for got, want in zip(tuned, default, strict=True):
        assert np.all(np.isfinite(np.asarray(want)))
        _assert_trees_close(got, want)
