"""A step the C translation cannot take (an unknown primitive, a jaxpr form from a newer JAX) is
stepped by XLA, with one warning per model structure: it never breaks an env."""

import warnings

import gymnasium as gym
import numpy as np
import pytest

import furuta_gym  # noqa: F401  (registers the envs)
from furuta_gym._ckernel import CKernel, CKernelTranslationError, CKernelWarning, c_compiler, translate
from furuta_gym.envs import Actuation, Episode, _model_backend

pytestmark = pytest.mark.skipif(c_compiler() is None, reason="no C compiler on PATH")

FURUTA_ID = "furuta_gym/Furuta-v0"
ACTIONS = np.random.default_rng(3).uniform(-5, 5, (60, 1))


@pytest.fixture(autouse=True)
def fresh_kernels(monkeypatch):
    """No compiled or refused step carried over from another test."""
    monkeypatch.setattr(_model_backend, "_C_KERNEL_CACHE", {})


def _run(env):
    obs, _ = env.reset(seed=1)
    return np.array([obs] + [env.step(a)[0] for a in ACTIONS])


def _made_with_warnings(count=2, **kwargs):
    """``count`` envs of the same model structure and the CKernelWarnings their making gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        envs = [gym.make(FURUTA_ID, dynamics="analytic", **kwargs) for _ in range(count)]
    return envs, [str(w.message) for w in caught if issubclass(w.category, CKernelWarning)]


def test_an_unknown_primitive_falls_back_to_xla_with_one_warning(monkeypatch):
    monkeypatch.delitem(translate._UNARY, "sin")  # as if the translation had never heard of sin
    (env, again), messages = _made_with_warnings(episode=Episode(frame_skip=2))
    assert len(messages) == 1 and "primitive 'sin'" in messages[0] and "XLA" in messages[0]
    for made in (env, again):
        backend = made.unwrapped.backend
        assert backend.kernel == "xla" and "primitive 'sin'" in backend.kernel_fallback
    reference = gym.make(FURUTA_ID, dynamics="analytic", kernel="xla", episode=Episode(frame_skip=2))
    np.testing.assert_array_equal(_run(env), _run(reference))
    with pytest.raises(ValueError, match="kernel='c'.*primitive 'sin'"):  # asked for C: told why not
        gym.make(FURUTA_ID, dynamics="analytic", kernel="c", episode=Episode(frame_skip=2))


def test_a_jaxpr_form_from_another_jax_falls_back_to_xla_with_one_warning(monkeypatch):
    def newer_jax(name, params):  # a parameter layout the translation does not know
        raise KeyError("ctx_mesh")

    monkeypatch.setattr(translate, "_check_params", newer_jax)
    with pytest.raises(CKernelTranslationError, match="cannot translate this jaxpr.*KeyError.*ctx_mesh"):
        CKernel(lambda v: v * 2.0, np.ones(3))
    (env, _), messages = _made_with_warnings()
    assert len(messages) == 1 and "ctx_mesh" in messages[0]
    assert env.unwrapped.backend.kernel == "xla" and np.all(np.isfinite(_run(env)))


def test_a_split_step_without_c_translation_is_stepped_by_xla_beside_the_c_period(monkeypatch):
    # a delay of one substep splits every period: its step is a second kernel, built on first use
    original = CKernel.__init__

    def no_split(self, fn, *args, name="kernel"):
        if name.startswith("split"):
            raise CKernelTranslationError("no translation of the split step (for the test)")
        original(self, fn, *args, name=name)

    monkeypatch.setattr(CKernel, "__init__", no_split)
    settings = dict(episode=Episode(frame_skip=2), actuation=Actuation(delay=0.002))
    (env,), _ = _made_with_warnings(count=1, **settings)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = _run(env)
    assert [w for w in caught if issubclass(w.category, CKernelWarning)] != []
    assert env.unwrapped.backend.kernel == "c"  # the period step is still C
    reference = gym.make(FURUTA_ID, dynamics="analytic", kernel="xla", **settings)
    np.testing.assert_allclose(run, _run(reference), rtol=1e-10, atol=1e-12)
