"""First-call cost of the training steps (issue 3's benchmark): the L_traj step has no host
callbacks (so JAX's persistent cache can store it) yet computes the same loss as before; a
failed solve is skipped by the NaN guard; the on-disk cache of traced steps (``_step_cache``)
returns exactly what the live step returns and never serves a step stored under another key."""

import contextlib
import os

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym.simulate as simulate_module
from furuta_gym.data import Trajectory
from furuta_gym.lagrangian import vector_field
from furuta_gym.models import Furuta, make_model
from furuta_gym.simulate import rollout_zoh
from furuta_gym.training import _step_cache, losses as losses_module
from furuta_gym.training.losses import make_windows, trajectory_loss
from furuta_gym.training.train import TrainSettings, _build_optimizer, _make_step, train

DT = 0.01
HOST_CALLBACK_MARKERS = ("callback", "xla_ffi_python")


@pytest.fixture(scope="module")
def furuta_free():
    """Three short free Furuta runs (the paper's sampling of initial states)."""
    rng = np.random.default_rng(0)
    x0 = np.concatenate([rng.uniform(-np.pi, np.pi, (3, 2)), rng.uniform(-5, 5, (3, 2))], axis=1)
    us = jnp.zeros((40, 1))
    xs = [np.asarray(rollout_zoh(Furuta(), jnp.asarray(x), us, DT, 10)) for x in x0]
    t = np.arange(41) * DT
    return [Trajectory(t, x[:, :2], np.zeros((41, 1)), x[:, 2:], name=str(i)) for i, x in enumerate(xs)]


def _has_host_callback(lowered) -> bool:
    text = lowered.as_text()
    return any(m in text for m in HOST_CALLBACK_MARKERS)


def _now_and_before(furuta_free, monkeypatch, differentiate: bool):
    """The trajectory loss (with its gradient if ``differentiate``) as compiled now and under the
    previous formulation (vector field not jitted, diffrax's checks as host callbacks), and the
    lowering of each."""
    model = make_model("furuta", "dln", jax.random.PRNGKey(3), hidden=(4, 4))
    windows = make_windows(furuta_free, 4, stride=9)
    params, static = eqx.partition(model, model.trainable())

    def loss(p):
        return trajectory_loss(eqx.combine(p, static), windows)

    def now(p):
        return jax.value_and_grad(loss)(p) if differentiate else loss(p)

    def before(p):  # a distinct function: traced afresh under the patched (previous) formulation
        return jax.value_and_grad(loss)(p) if differentiate else loss(p)

    lowered_now = jax.jit(now).lower(params)
    with monkeypatch.context() as m:
        m.setattr(simulate_module, "_vector_field_once", vector_field)
        m.setattr(losses_module, "_runtime_checks_as_nan", contextlib.nullcontext)
        lowered_before = jax.jit(before).lower(params)
    return (lowered_now, lowered_now.compile()(params)), (lowered_before, lowered_before.compile()(params))


def test_trajectory_loss_equals_the_previous_formulation_without_host_callbacks(furuta_free, monkeypatch):
    # the value here; its gradient is checked against finite differences in test_training, and
    # against the previous formulation's under -m slow (two backward solves to compile)
    (lowered_now, value_now), (lowered_before, value_before) = _now_and_before(furuta_free, monkeypatch, False)
    assert not _has_host_callback(lowered_now)  # what lets the persistent cache store the step
    if losses_module.os.environ.get("EQX_ON_ERROR", "raise") == "raise":
        assert _has_host_callback(lowered_before)  # so the check above can fail
    assert np.isfinite(float(value_now)) and float(value_now) > 0
    assert float(value_now) == pytest.approx(float(value_before), rel=1e-12, abs=0)


@pytest.mark.slow
def test_trajectory_loss_gradient_equals_the_previous_formulation(furuta_free, monkeypatch):
    (lowered_now, (value_now, grad_now)), (_, (value_before, grad_before)) = _now_and_before(
        furuta_free, monkeypatch, True
    )
    assert not _has_host_callback(lowered_now)
    assert float(value_now) == pytest.approx(float(value_before), rel=1e-12, abs=0)
    flat_now = jax.flatten_util.ravel_pytree(grad_now)[0]
    flat_before = jax.flatten_util.ravel_pytree(grad_before)[0]
    assert np.linalg.norm(flat_before) > 0
    np.testing.assert_allclose(flat_now, flat_before, rtol=1e-10, atol=1e-12 * np.abs(flat_before).max())


def test_a_solve_hitting_max_steps_is_a_non_finite_loss_the_nan_guard_skips(furuta_free, tmp_path):
    model = make_model("furuta", "dln", jax.random.PRNGKey(4), hidden=(4, 4))
    config = TrainSettings.for_system(
        "furuta", epochs=(1,), horizons=(5,), batch_size=None, max_steps=1, progress=False, checkpoint_every=0
    )
    windows = make_windows(furuta_free, 6, stride=5)
    loss = float(jax.jit(lambda w: trajectory_loss(model, w, max_steps=1))(windows))
    assert not np.isfinite(loss)  # 5 samples cannot be reached in one step: inf, no exception

    with pytest.warns(RuntimeWarning, match="NaN guard"):
        trained, history = train("dln", "furuta", "traj", furuta_free, config, out_dir=tmp_path / "run", model=model)
    assert history[-1]["skipped"] == history[-1].get("steps", 1) >= 1
    before = jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))
    after = jax.tree_util.tree_leaves(eqx.filter(trained, eqx.is_inexact_array))
    assert all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))  # nothing applied, nothing NaN


@pytest.fixture(scope="module")
def itau_step(furuta_free):
    """A live (jitted) L_Iτ training step and its arguments; L_Iτ keeps the compiles short."""
    model = make_model("furuta", "dln", jax.random.PRNGKey(5), hidden=(4, 4))
    config = TrainSettings.for_system("furuta", progress=False)
    optimizer, trainable, params = _build_optimizer(model, config)
    _, static = eqx.partition(model, trainable)
    step = _make_step(static, optimizer, "itau", config, "momentum")
    assert not isinstance(step, _step_cache.ExportedStep)  # the tests leave the traced-step cache off
    windows = make_windows(furuta_free, 41, stride=40, cover_end=True)
    args = (params, optimizer.init(params), None, windows, jnp.asarray(1.0), jnp.asarray(1e-3))
    key = {
        "loss": "itau",
        "config": repr(config),
        "optimizer": _step_cache.optimizer_description(optimizer),
        "static": _step_cache.array_digest(static),
    }
    return step, args, key


def _never_traced(*args):
    raise RuntimeError("the stored step should have been loaded, not traced")


def test_exported_step_round_trips_through_disk_exactly(itau_step, tmp_path):
    step, args, key = itau_step
    assert key["optimizer"] is not None  # _build_optimizer registered what defines the optimiser
    live = step(*args)
    first = _step_cache.ExportedStep(step, key, tmp_path)(*args)  # exports and stores
    assert len(list(tmp_path.glob("step-*.jaxexport"))) == 1
    loaded = _step_cache.ExportedStep(_never_traced, key, tmp_path)(*args)  # a "new process"
    for out in (first, loaded):
        assert jax.tree_util.tree_structure(out) == jax.tree_util.tree_structure(live)
        for a, b in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(live), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert bool(loaded[3]) and float(loaded[2]["itau"]) > 0

    # another key (e.g. another learning rate) never loads that file: it traces (here: fails)
    other = dict(key, config=key["config"].replace("learning_rate=", "learning_rate=2*"))
    with pytest.warns(UserWarning, match="not exported"), pytest.raises(RuntimeError, match="should have been loaded"):
        _step_cache.ExportedStep(_never_traced, other, tmp_path)(*args)


def test_an_exported_step_compiles_once_for_a_whole_run(itau_step, tmp_path, no_persistent_cache):
    """The stored step returns arrays committed to their device, while a run's first params and
    optimiser state (and every batch) arrive uncommitted: feeding its outputs back, as training
    does, must not compile the step a second time (seconds per run for a trajectory loss)."""
    step, args, key = itau_step
    compiles, listening = [], [True]

    def on_duration(event, duration, **kwargs):
        if listening[0] and event == "/jax/core/compile/backend_compile_duration":
            compiles.append(duration)

    jax.monitoring.register_event_duration_secs_listener(on_duration)
    try:
        exported = _step_cache.ExportedStep(step, key, tmp_path)
        params, opt_state, _, _ = exported(*args)
        after_first = len(compiles)
        assert after_first >= 1  # the listener sees compilations
        for _ in range(3):
            params, opt_state, terms, ok = exported(params, opt_state, *args[2:])
        assert len(compiles) == after_first
        assert bool(ok) and float(terms["itau"]) > 0
    finally:
        listening[0] = False


def test_a_damaged_stored_step_is_replaced_not_trusted(itau_step, tmp_path):
    step, args, key = itau_step
    _step_cache.ExportedStep(step, key, tmp_path)(*args)
    (path,) = tmp_path.glob("step-*.jaxexport")
    path.write_bytes(path.read_bytes()[:100])
    with pytest.warns(UserWarning, match="unreadable"):
        out = _step_cache.ExportedStep(step, key, tmp_path)(*args)
    np.testing.assert_array_equal(np.asarray(out[2]["total"]), np.asarray(step(*args)[2]["total"]))
    assert path.stat().st_size > 100  # stored afresh


def test_the_step_cache_is_off_unless_asked_for(monkeypatch):
    monkeypatch.setenv("FURUTA_GYM_STEP_CACHE", "0")
    assert _step_cache.step_cache_dir() is None
    monkeypatch.delenv("FURUTA_GYM_STEP_CACHE")
    before = jax.config.jax_compilation_cache_dir  # the test session's own cache, if any
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        assert _step_cache.step_cache_dir() is None  # the library writes nothing by itself
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_training_commands_turn_the_cache_on_where_asked_and_never_when_told_not_to(tmp_path):
    import subprocess
    import sys

    code = (
        "import jax; from furuta_gym.cli._cache import enable_compilation_cache as e; "
        "p = e(); print(p, jax.config.jax_compilation_cache_dir)"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("FURUTA_GYM_COMPILATION_CACHE",)}
    env["JAX_COMPILATION_CACHE_DIR"] = str(tmp_path / "c")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [str(tmp_path / "c")] * 2 and (tmp_path / "c").is_dir()
    # without JAX_COMPILATION_CACHE_DIR it lives under the one cache root, which XDG_CACHE_HOME
    # moves like the C kernels' (an empty XDG_CACHE_HOME is a cold start for everything)
    del env["JAX_COMPILATION_CACHE_DIR"]
    env.pop("FURUTA_GYM_CACHE", None)
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == [str(tmp_path / "xdg" / "furuta_gym" / "jax")] * 2
    env["FURUTA_GYM_COMPILATION_CACHE"] = "0"
    env["JAX_COMPILATION_CACHE_DIR"] = str(tmp_path / "d")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split()[0] == "None" and not (tmp_path / "d").exists()


def test_fast_compile_steps_compute_what_the_optimised_ones_do_live_and_exported(furuta_free, tmp_path, monkeypatch):
    """``TrainSettings.fast_compile`` (XLA optimisation level 0 for the trajectory-loss steps, used
    by ``reproduce --quick``): the live jitted step carries the options, the step is still
    exported to the disk cache (a nested jit may not carry them, which once made every export
    fail and fall back) and agrees with the optimised step to rounding."""
    import warnings

    model = make_model("furuta", "dln", jax.random.PRNGKey(5), hidden=(4, 4))
    windows = make_windows(furuta_free, 41, stride=40, cover_end=True)
    traj_windows = make_windows(furuta_free, 3, stride=7)
    outputs = []
    for fast in (False, True):
        config = TrainSettings.for_system("furuta", progress=False, fast_compile=fast)
        optimizer, trainable, params = _build_optimizer(model, config)
        _, static = eqx.partition(model, trainable)
        args = (params, optimizer.init(params), traj_windows, windows, jnp.asarray(1.0), jnp.asarray(1e-3))
        live = _make_step(static, optimizer, "prop", config, "momentum")
        assert not isinstance(live, _step_cache.ExportedStep)
        if fast:  # JAX refuses compiler options below an outer trace: so they are on this jit
            with pytest.raises(ValueError, match="compiler_options"):
                jax.make_jaxpr(live)(*args)
        store = tmp_path / f"fast_{fast}"
        monkeypatch.setattr(_step_cache, "step_cache_dir", lambda store=store: store)
        exported = _make_step(static, optimizer, "prop", config, "momentum")
        monkeypatch.undo()
        assert isinstance(exported, _step_cache.ExportedStep)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # "training step not exported" is a failed export
            # a live step and its export agree exactly (test_exported_step_round_trips_through_disk_exactly),
            # and the fast live step's options are checked above: one compile of each suffices
            outputs.append(exported(*args))
        assert len(list(store.glob("step-*.jaxexport"))) == 1
    reference = outputs[0]
    for out in outputs[1:]:
        for a, b in zip(jax.tree_util.tree_leaves(out), jax.tree_util.tree_leaves(reference), strict=True):
            np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=1e-10, atol=1e-14)
    assert float(reference[2]["traj"]) > 0 and float(reference[2]["itau"]) > 0
    # a stage of L_Iτ alone keeps the optimised code: it runs thousands of cheap-to-compile steps
    config = TrainSettings.for_system("furuta", progress=False, fast_compile=True)
    optimizer, trainable, params = _build_optimizer(model, config)
    _, static = eqx.partition(model, trainable)
    itau = _make_step(static, optimizer, "itau", config, "momentum")
    jax.make_jaxpr(itau)(params, optimizer.init(params), None, windows, jnp.asarray(1.0), jnp.asarray(1e-3))
