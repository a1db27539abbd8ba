"""The model backends' C kernel (issue 4, the single learned-model env's speed): a JAX function's
jaxpr lowered to C must compute what JAX computes, primitive by primitive and for every model
the package ships, and the envs must behave the same whichever kernel steps them."""

import math
import pickle

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym
from furuta_gym._ckernel import CKernel, CKernelError, c_compiler
from furuta_gym.envs import _model_backend
from furuta_gym.models import make_model

pytestmark = pytest.mark.skipif(c_compiler() is None, reason="no C compiler on PATH")

FURUTA_ID, NMSD_ID = "furuta_gym/Furuta-v0", "furuta_gym/NMSD-v0"
RNG = np.random.default_rng(0)
W = RNG.normal(size=(5, 4))
V = RNG.normal(size=4)
B = RNG.normal(size=(3, 5, 4))


def _scan_with_outputs(w, v):
    def body(c, x):
        c = jnp.tanh(w[:4, :] @ c + x)
        return c, jnp.sum(c**2)

    return jax.lax.scan(body, v, jnp.stack([v, 2 * v, -v]), reverse=True)


PRIMITIVE_CASES = {
    "matvec": lambda w, v: w @ v,
    "vecmat": lambda w, v: v @ w.T,
    "batched_dot": lambda w, v: jnp.einsum("bij,bkj->bik", jnp.stack([w, 2 * w, -w]), jnp.stack([w, w, w])),
    "jacfwd_tanh": lambda w, v: jax.jacfwd(lambda x: jnp.tanh(w @ x))(v),
    "grad_softplus": lambda w, v: jax.grad(lambda x: jnp.sum(jax.nn.softplus(w @ x) ** 2))(v),
    "hessian": lambda w, v: jax.hessian(lambda x: jnp.sum(jnp.sin(w @ x)) + jnp.prod(x))(v),
    "broadcast": lambda w, v: w + v[None, :] * 2.0 - jnp.sum(v),
    "structure": lambda w, v: jnp.concatenate([jnp.pad(v, (2, 1)), w.T.ravel()[::3], jnp.flip(v)]),
    "stack_unstack_split": lambda w, v: jnp.stack([*jnp.split(v, 2)[::-1], w[0, :2]], axis=1),
    "reductions": lambda w, v: jnp.stack([jnp.max(w, axis=0), jnp.min(w, axis=0), jnp.prod(w[:2], axis=0)]),
    "cumulative": lambda w, v: jnp.concatenate([jnp.cumsum(w, axis=1).ravel(), jnp.cumsum(v[::-1])]),
    "where_clip_pow": lambda w, v: jnp.where(v > 0, jnp.clip(v, -0.5, 0.3), v**3 / (1 + v**2)),
    "elementwise": lambda w, v: jnp.stack(
        [
            jnp.exp(v),
            jnp.log1p(v**2),
            jnp.arctan2(v, 1.5),
            jnp.sign(v),
            jnp.abs(v),
            jnp.cos(v),
            jnp.sqrt(v**2 + 1),
            jax.nn.sigmoid(v),
        ]
    ),
    "integers_and_iota": lambda w, v: jnp.arange(4) * v + (v > 0).astype(jnp.float64),
    "fori_loop": lambda w, v: jax.lax.fori_loop(0, 3, lambda i, x: jnp.tanh(w[:4] @ x) + i, v),
    "scan_with_outputs": _scan_with_outputs,
    "while_loop": lambda w, v: jax.lax.while_loop(lambda c: c[1] < 5, lambda c: (c[0] * 1.1, c[1] + 1), (v, 0)),
    "cond": lambda w, v: jax.lax.cond(v[0] > 0, lambda x: x * 2, lambda x: -x, v),
    "switch": lambda w, v: jax.lax.switch(2, [lambda x: x, lambda x: 2 * x, lambda x: jnp.sin(x)], v),
}


@pytest.mark.parametrize("name", sorted(PRIMITIVE_CASES))
def test_lowered_function_equals_jax(name):
    fn = PRIMITIVE_CASES[name]
    expected = jax.tree_util.tree_leaves(fn(jnp.asarray(W), jnp.asarray(V)))
    got = jax.tree_util.tree_leaves(CKernel(fn, W, V)(W, V))
    assert len(got) == len(expected)
    for g, e in zip(got, expected, strict=True):
        assert g.shape == e.shape and g.dtype == e.dtype
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-13, atol=1e-14)


def test_nan_propagates_through_max_min_and_sign_as_in_xla():
    fn = lambda v: jnp.stack([jnp.maximum(v, 0.0), jnp.minimum(0.0, v), jnp.sign(v)])  # noqa: E731
    v = np.array([np.nan, -1.0, 2.0, np.inf])
    np.testing.assert_array_equal(CKernel(fn, v)(v), np.asarray(fn(jnp.asarray(v))))


def test_unknown_primitive_is_one_clear_error():
    with pytest.raises(CKernelError, match="primitive 'lu'"):
        CKernel(lambda a, b: jnp.linalg.solve(a, b), W[:4], V)


def test_in_place_buffers_and_compiled_library_reused():
    kernel = CKernel(lambda x, u: x + jnp.roll(x, 1) * u, V, np.ones(1))
    inputs, _ = kernel.new_buffers()
    inputs[0][:] = V
    inputs[1][:] = 0.5
    call = kernel.bind(inputs, [inputs[0]])  # the state is updated in place
    call()
    np.testing.assert_allclose(inputs[0], V + np.roll(V, 1) * 0.5, rtol=1e-15)
    again = CKernel(lambda x, u: x + jnp.roll(x, 1) * u, V, np.ones(1))
    assert again.library_path == kernel.library_path  # same source: the cached library
    with pytest.raises(ValueError, match=r"inputs\[0\].*shape \(4,\)"):
        kernel.bind([np.zeros(3), inputs[1]], [inputs[0]])
    with pytest.raises(ValueError, match="1 input and 1 output buffers; the kernel takes 2 and 1"):
        kernel.bind(inputs[:1], [inputs[0]])  # C would read a pointer past the array


# ------------------------------------------------------------------------------- the models

MODELS = {
    "furuta-analytic": ("furuta", "analytic"),
    "furuta-dln": ("furuta", "dln"),
    "furuta-aph": ("furuta", "aph"),
    "furuta-adln": ("furuta", "adln"),
    "nmsd-analytic": ("nmsd", "analytic"),
    "nmsd-dln": ("nmsd", "dln"),
    "nmsd-adln": ("nmsd", "adln"),
}


def _dynamics(system, kind):
    return "analytic" if kind == "analytic" else make_model(system, kind, key=jax.random.PRNGKey(3))


def _trajectory(env, actions, seed=0):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, _, terminated, truncated, _ = env.step(a)
        out.append(obs)
    return np.array(out)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_c_kernel_env_equals_xla_kernel_env(name):
    system, kind = MODELS[name]
    env_id, limit = (FURUTA_ID, 5.0) if system == "furuta" else (NMSD_ID, 10.0)
    dynamics = _dynamics(system, kind)
    actions = np.random.default_rng(1).uniform(-limit, limit, (300, 1))
    c_env = gym.make(env_id, dynamics=dynamics, kernel="c")
    xla_env = gym.make(env_id, dynamics=dynamics, kernel="xla")
    assert (c_env.unwrapped.backend.kernel, xla_env.unwrapped.backend.kernel) == ("c", "xla")
    c_run, xla_run = _trajectory(c_env, actions), _trajectory(xla_env, actions)
    assert np.abs(c_run[-1] - c_run[0]).max() > 1e-3  # the state did move
    np.testing.assert_allclose(c_run, xla_run, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kind", ["analytic", "dln"])
def test_c_kernel_with_plant_effects_delay_randomisation_and_pickle(kind):
    # domain randomisation needs physical parameters: the analytic model has them, DeLaN not
    randomize = 0.1 if kind == "analytic" else None
    kw = dict(
        dynamics=_dynamics("furuta", kind),
        plant=["coulomb", "cable_spring"],
        actuation_delay=0.006,
        frame_skip=4,
        randomize=randomize,
    )
    actions = np.random.default_rng(2).uniform(-5, 5, (200, 1))
    runs = {}
    for kernel in ("c", "xla"):
        env = gym.make(FURUTA_ID, kernel=kernel, **kw)
        first = _trajectory(env, actions[:100], seed=4)
        env = pickle.loads(pickle.dumps(env))  # mid-episode: the state travels, the kernel is rebuilt
        assert env.unwrapped.backend.kernel == kernel
        rest = [env.step(a)[0] for a in actions[100:]]
        runs[kernel] = np.concatenate([first, rest])
        # a second episode (randomize: new parameters, which the C kernel takes as inputs)
        runs[kernel + "-2"] = _trajectory(env, actions[:50], seed=None)
    np.testing.assert_allclose(runs["c"], runs["xla"], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(runs["c-2"], runs["xla-2"], rtol=1e-10, atol=1e-12)
    if randomize:  # other parameters, another path from the same start
        assert np.abs(runs["c-2"][1:, 1] - runs["c"][1:51, 1]).max() > 1e-6


def test_c_kernel_broken_model_diverges_without_nan():
    import equinox as eqx

    model = make_model("furuta", "dln", key=jax.random.PRNGKey(0))
    huge = jax.tree_util.tree_map(lambda w: w * 1e4, model, is_leaf=eqx.is_inexact_array)
    env = gym.make(FURUTA_ID, dynamics=huge, kernel="c")
    env.reset(seed=0)
    for _ in range(2000):
        obs, _, terminated, _, info = env.step(np.array([5.0]))
        assert np.all(np.isfinite(obs))
        if terminated:
            break
    assert terminated and info["diverged"]


# ----------------------------------------------------------------------------- the argument


def test_kernel_argument_errors():
    with pytest.raises(ValueError, match=r"kernel must be one of \['auto', 'c', 'xla'\]"):
        gym.make(FURUTA_ID, dynamics="analytic", kernel="gcc")
    with pytest.raises(ValueError, match="dynamics='mujoco' is stepped by MuJoCo"):
        gym.make(FURUTA_ID, kernel="c")


def test_without_a_compiler_auto_falls_back_to_xla_and_c_says_why(monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setattr(_model_backend, "_C_KERNEL_CACHE", {})
    env = gym.make(NMSD_ID, dynamics="analytic")
    backend = env.unwrapped.backend
    assert backend.kernel == "xla" and "C compiler" in backend.kernel_fallback
    env.reset(seed=0)
    assert np.all(np.isfinite(env.step(np.array([1.0]))[0]))
    with pytest.raises(ValueError, match=r"kernel='c' needs a C compiler: none found as '/nonexistent/cc'"):
        gym.make(NMSD_ID, dynamics="analytic", kernel="c")


def test_auto_uses_c_when_it_can():
    env = gym.make(NMSD_ID, dynamics="analytic")
    assert env.unwrapped.backend.kernel == "c" and env.unwrapped.backend.kernel_fallback is None
    assert not math.isnan(env.reset(seed=0)[0][0])
    assert furuta_gym is not None


def test_indexed_updates_and_gathers_with_constant_indices():
    idx = np.array([2, 0, 2])

    def fn(w, v):
        a = jnp.zeros(5).at[idx].add(v[:3]).at[1].set(v[3])
        b = w[jnp.array([4, 1]), 1:3]  # a gather
        c = jax.lax.dynamic_slice(v, (1,), (2,))
        return a, b, c, jnp.zeros((2, 2)).at[jnp.tril_indices(2)].set(v[:3] * 2)[::-1]

    expected = jax.tree_util.tree_leaves(fn(jnp.asarray(W), jnp.asarray(V)))
    got = jax.tree_util.tree_leaves(CKernel(fn, W, V)(W, V))
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-14, atol=1e-15)


def test_indices_computed_in_the_step_are_refused_clearly():
    with pytest.raises(CKernelError, match="'dynamic_slice' only with indices known"):
        CKernel(lambda v, k: jax.lax.dynamic_slice(v, (k,), (2,)), V, np.int64(1))


def test_batched_env_refuses_a_kernel_and_its_template_builds_none():
    from furuta_gym.envs.vector import FurutaVectorEnv

    with pytest.raises(ValueError, match="kernel='c' chooses a single env's step kernel"):
        FurutaVectorEnv(4, dynamics="analytic", kernel="c")
    env = FurutaVectorEnv(4, dynamics="analytic")
    assert env._template.backend.kernel == "xla"  # the template only specifies; it never steps


def test_a_step_too_large_for_the_stack_is_refused_and_auto_takes_xla(monkeypatch):
    from furuta_gym._ckernel import translate

    monkeypatch.setattr(translate, "MAX_STACK_BYTES", 4096)
    monkeypatch.setattr(_model_backend, "_C_KERNEL_CACHE", {})
    with pytest.raises(CKernelError, match=r"MiB of intermediates"):
        CKernel(lambda w, v: jnp.tanh(jnp.outer(v, v) @ jnp.ones((4, 200))), W, V)
    backend = gym.make(FURUTA_ID, dynamics=_dynamics("furuta", "dln")).unwrapped.backend
    assert backend.kernel == "xla" and "intermediates" in backend.kernel_fallback


def test_a_failing_compiler_is_one_clear_error_and_auto_takes_xla(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    monkeypatch.setenv("FURUTA_GYM_CACHE", str(tmp_path))  # nothing cached to fall back on
    monkeypatch.setattr(_model_backend, "_C_KERNEL_CACHE", {})
    with pytest.raises(CKernelError, match="the C compiler .*false failed on the generated kernel"):
        CKernel(lambda v: v * 2.0, V)
    backend = gym.make(NMSD_ID, dynamics="analytic").unwrapped.backend
    assert backend.kernel == "xla" and "failed on the generated kernel" in backend.kernel_fallback


def test_auto_tries_the_c_translation_once_per_model_structure(monkeypatch):
    """With domain randomisation every reset rebuilds the step for new parameters: a model whose
    step C cannot take must fall back without tracing and translating it again each time."""
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setattr(_model_backend, "_C_KERNEL_CACHE", {})
    attempts = []
    original = CKernel.__init__

    def counting(self, *args, **kwargs):
        attempts.append(1)
        original(self, *args, **kwargs)

    monkeypatch.setattr(CKernel, "__init__", counting)
    env = gym.make(NMSD_ID, dynamics="analytic", randomize=0.1)
    for seed in range(4):
        env.reset(seed=seed)
        env.step(np.array([1.0]))
    assert env.unwrapped.backend.kernel == "xla" and len(attempts) == 1
