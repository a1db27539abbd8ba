"""Per-stage losses in the training curriculum: a stage without a horizon trains on L_Iτ alone
(the cheap warm start the reproduction gives L_prop), the next stages on the full L_prop."""

import dataclasses
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from _simulated import nmsd_chirp_segments
from furuta_gym.models import make_model
from furuta_gym.training.train import TrainSettings, _integral_windows, train, training_step


@pytest.fixture(scope="module")
def segments():
    return nmsd_chirp_segments(1.0)


def test_an_itau_stage_then_prop_stages(segments, tmp_path):
    cfg = TrainSettings.for_system(
        "nmsd",
        epochs=(30, 2),
        horizons=(None, 2),
        batch_size=64,
        quadrature="simpson",
        progress=False,
        checkpoint_every=0,
    )
    model, history = train("dln", "nmsd", "prop", segments, cfg, out_dir=tmp_path / "run")
    assert [h["stage"] for h in history] == [0] * 30 + [1] * 2
    first, last_itau, prop = history[0], history[29], history[30]
    # the L_Iτ stage: no trajectory term, one full-batch step per epoch, and it learns
    assert first["horizon"] is None and "traj" not in first and first["steps"] == 1
    assert last_itau["itau"] < 0.8 * first["itau"]
    # the L_prop stages: both terms, minibatches of 2-step windows
    assert prop["horizon"] == 2 and prop["traj"] > 0 and prop["steps"] == (8 * 99) // 64
    assert prop["total"] == pytest.approx(prop["itau"] + prop["traj"], rel=1e-12)
    assert (tmp_path / "run" / "model.eqx").exists()


def test_a_stage_without_horizon_needs_the_integral_loss(segments):
    cfg = TrainSettings.for_system("nmsd", epochs=(1, 1), horizons=(None, 2), progress=False)
    with pytest.raises(ValueError, match="L_Iτ alone.*'traj'"):
        train("dln", "nmsd", "traj", segments, cfg)


def test_learning_rate_per_stage(segments):
    """One rate per stage: a second stage at a vanishing rate leaves the first stage's model."""
    with pytest.raises(ValueError, match="one value or one per stage"):
        TrainSettings(epochs=(1, 1), horizons=(None, 2), learning_rate=(1e-3,))
    with pytest.raises(ValueError, match="must be positive"):
        TrainSettings(epochs=(1,), horizons=(2,), learning_rate=(0.0,))
    base = dict(horizons=(None, None), quadrature="simpson", progress=False, checkpoint_every=0)
    hp = dict(hidden=(8, 8))
    two, _ = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(5, 5), learning_rate=(1e-2, 1e-15), **base),
        hparams=hp,
    )
    one, _ = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(5, 0), learning_rate=1e-2, **base),
        hparams=hp,
    )
    fast, _ = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(5, 5), learning_rate=1e-2, **base),
        hparams=hp,
    )
    a, b, c = (np.asarray(m.lagrangian_nets.potential_net.layers[0].weight) for m in (two, one, fast))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    assert np.max(np.abs(c - b)) > 1e-4


def test_cosine_decay_within_each_stage(segments):
    """Each stage's step falls from its rate to cosine_decay_to × rate along a cosine, and a stage
    restarts at its own rate; the training loop uses that step (a last epoch decayed to nothing
    leaves the model of the epoch before)."""
    cfg = TrainSettings(epochs=(5, 3), horizons=(None, 2), learning_rate=(1e-2, 1e-3), cosine_decay_to=0.01)
    rates = [cfg.epoch_learning_rate(e) for e in range(8)]
    np.testing.assert_allclose(
        rates,
        [
            1e-2,
            1e-2 * (0.01 + 0.99 * 0.5 * (1 + np.cos(np.pi / 4))),
            1e-2 * 0.505,
            1e-2 * (0.01 + 0.99 * 0.5 * (1 + np.cos(3 * np.pi / 4))),
            1e-4,
            1e-3,
            1e-3 * 0.505,
            1e-5,
        ],
        rtol=1e-12,
    )
    constant = TrainSettings(epochs=(5, 3), horizons=(None, 2), learning_rate=(1e-2, 1e-3))
    assert [constant.epoch_learning_rate(e) for e in range(8)] == [1e-2] * 5 + [1e-3] * 3
    for bad in (0.0, 1.5, -0.1):
        with pytest.raises(ValueError, match="cosine_decay_to must be in"):
            TrainSettings(epochs=(1,), horizons=(2,), cosine_decay_to=bad)
    with pytest.raises(ValueError, match="outside the 8 epochs"):
        cfg.epoch_learning_rate(8)

    base = dict(
        horizons=(None,),
        quadrature="simpson",
        progress=False,
        checkpoint_every=0,
        learning_rate=1e-2,
        keep_best_itau=False,
    )
    hp = dict(hidden=(8, 8))
    decayed, _ = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(2,), cosine_decay_to=1e-15, **base),
        hparams=hp,
    )
    one, _ = train("dln", "nmsd", "prop", segments, TrainSettings.for_system("nmsd", epochs=(1,), **base), hparams=hp)
    two, _ = train("dln", "nmsd", "prop", segments, TrainSettings.for_system("nmsd", epochs=(2,), **base), hparams=hp)
    a, b, c = (np.asarray(m.lagrangian_nets.potential_net.layers[0].weight) for m in (decayed, one, two))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    assert np.max(np.abs(c - b)) > 1e-4


def _weights(model):
    return np.concatenate(
        [np.ravel(leaf) for leaf in jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))]
    )


SPIKY = dict(horizons=(None,), quadrature="simpson", progress=False, checkpoint_every=0, learning_rate=0.1)


def test_a_full_batch_itau_stage_hands_on_its_lowest_loss_iterate(segments):
    """At a large step the L_Iτ loss jumps from epoch to epoch; the stage's result is the iterate
    of its lowest recorded loss (bit for bit the model after that many epochs), not the last."""
    hp = dict(hidden=(8, 8))
    best, history = train(
        "dln", "nmsd", "prop", segments, TrainSettings.for_system("nmsd", epochs=(12,), **SPIKY), hparams=hp
    )
    last, history_last = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(12,), keep_best_itau=False, **SPIKY),
        hparams=hp,
    )
    totals = [h["total"] for h in history]
    assert totals == [h["total"] for h in history_last]  # the same steps; only the hand-over differs
    after = history[-1]["best_after_epoch"]
    assert after < 11, f"the last iterates were the best ({totals}): this test needs a non-monotone stage"
    assert history[-1]["best_total"] == totals[after] == min(totals)
    assert "best_after_epoch" not in history_last[-1]
    reference, _ = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(after,), keep_best_itau=False, **SPIKY),
        hparams=hp,
    )
    np.testing.assert_array_equal(_weights(best), _weights(reference))
    assert np.max(np.abs(_weights(best) - _weights(last))) > 1e-6


def test_resuming_mid_stage_keeps_the_best_iterate(segments, tmp_path, monkeypatch):
    """Stopped (SIGTERM) in the middle of an L_Iτ stage and resumed: the same model as a run
    never stopped, so the best iterate travels in the training state."""
    import os
    import signal

    from furuta_gym.training import checkpoint as ckpt

    hp = dict(hidden=(8, 8))
    cfg = TrainSettings.for_system("nmsd", epochs=(12,), **SPIKY)
    straight, h_straight = train("dln", "nmsd", "prop", segments, cfg, out_dir=tmp_path / "a", hparams=hp)
    saves = {"n": 0}
    original = ckpt.save_training_state

    def save_then_stop(*args, **kwargs):
        out = original(*args, **kwargs)
        saves["n"] += 1
        if saves["n"] == 2:
            os.kill(os.getpid(), signal.SIGTERM)
        return out

    # blocks of at most 3 epochs here (the run above had its own lengths): saved after epochs 3, 6, …
    # (the module by name: furuta_gym.training.train is also the function's name in the package)
    monkeypatch.setattr(sys.modules["furuta_gym.training.train"], "BLOCK_CAPACITY", 3)
    monkeypatch.setattr(ckpt, "save_training_state", save_then_stop)
    with pytest.raises(KeyboardInterrupt, match="after epoch 6"):
        train("dln", "nmsd", "prop", segments, cfg, out_dir=tmp_path / "b", hparams=hp)
    monkeypatch.setattr(ckpt, "save_training_state", original)
    monkeypatch.undo()
    assert ckpt.read_header(tmp_path / "b" / "train_state.eqx")["has_best_model"]
    resumed, h_resumed = train("dln", "nmsd", "prop", segments, cfg, out_dir=tmp_path / "b", resume=True, hparams=hp)
    assert [h["total"] for h in h_resumed] == [h["total"] for h in h_straight]
    assert h_resumed[-1]["best_after_epoch"] == h_straight[-1]["best_after_epoch"] < 12
    np.testing.assert_array_equal(_weights(resumed), _weights(straight))


def test_a_one_epoch_itau_stage_keeps_its_step_when_it_lowered_the_loss(segments):
    """The last step's result is evaluated at the stage's end, so a stage of one epoch is not
    undone when its step helped (and is when it hurt)."""
    hp = dict(hidden=(8, 8))
    cfg = dict(horizons=(None,), quadrature="simpson", progress=False, checkpoint_every=0)
    kept, history = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(1,), learning_rate=1e-3, **cfg),
        hparams=hp,
    )
    plain, _ = train(
        "dln",
        "nmsd",
        "prop",
        segments,
        TrainSettings.for_system("nmsd", epochs=(1,), learning_rate=1e-3, keep_best_itau=False, **cfg),
        hparams=hp,
    )
    assert history[-1]["best_after_epoch"] == 1 and history[-1]["best_total"] < history[-1]["total"]
    np.testing.assert_array_equal(_weights(kept), _weights(plain))


def test_itau_epochs_in_compiled_blocks_are_the_per_epoch_steps(segments, tmp_path):
    """A full-batch L_Iτ stage runs its epochs as compiled loops (``_itau_block``); each epoch is
    still one step of the public training step on every window in that epoch's order, so the
    run equals those steps taken one by one (to rounding), and a run stopped between two blocks
    and resumed equals a run never stopped bit for bit, whatever lengths its blocks had."""
    hp = dict(hidden=(8, 8))
    cfg = TrainSettings.for_system("nmsd", epochs=(11,), keep_best_itau=False, **{**SPIKY, "learning_rate": 1e-2})
    blocked, history = train("dln", "nmsd", "prop", segments, cfg, out_dir=tmp_path / "a", hparams=hp)
    assert [h["steps"] for h in history] == [1] * 11 and len({h["total"] for h in history}) == 11

    model = make_model("nmsd", "dln", jax.random.PRNGKey(cfg.seed), **hp)
    windows, normalization = _integral_windows(segments, cfg, "prop", min(len(tr) for tr in segments))
    step, params, opt_state = training_step(model, cfg, "itau", normalization)
    totals = []
    for epoch in range(11):
        order = np.random.default_rng([cfg.seed, epoch]).permutation(windows.n_windows)
        lr = jnp.asarray(cfg.epoch_learning_rate(epoch))
        params, opt_state, terms, ok = step(params, opt_state, None, windows.take(order), jnp.asarray(1.0), lr)
        assert bool(ok)
        totals.append(float(terms["total"]))
    # XLA may fuse the step inside the loop differently: the same arithmetic up to rounding
    np.testing.assert_allclose([h["total"] for h in history], totals, rtol=1e-12, atol=0)
    one_by_one = eqx.combine(params, eqx.partition(model, model.trainable())[1])
    np.testing.assert_allclose(_weights(blocked), _weights(one_by_one), rtol=0, atol=1e-12)

    train("dln", "nmsd", "prop", segments, dataclasses.replace(cfg, epochs=(4,)), out_dir=tmp_path / "b", hparams=hp)
    resumed, h_resumed = train("dln", "nmsd", "prop", segments, cfg, out_dir=tmp_path / "b", resume=True, hparams=hp)
    assert [h["total"] for h in h_resumed] == [h["total"] for h in history]
    np.testing.assert_array_equal(_weights(resumed), _weights(blocked))
