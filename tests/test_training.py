"""Losses, the training loop, checkpoints and the scale fit (issue 3, items 2, 3, 5)."""

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym.data import Trajectory
from furuta_gym.models import NMSD, make_model
from furuta_gym.signals import chirp
from furuta_gym.simulate import rollout_zoh, simulate
from furuta_gym.training import checkpoint as ckpt
from furuta_gym.training.losses import (
    augmentation_penalty,
    integral_loss,
    make_windows,
    trajectory_loss,
)
from furuta_gym.training.train import TrainSettings, fit_scale, train, training_step

DT = 0.01


def _nmsd_trajectory(x0, seconds, amplitude=1.0, f0=0.1, f1=1.1, t1=60.0, t_offset=0.0, name="0"):
    t = np.arange(0.0, seconds + DT / 2, DT)
    u = amplitude * chirp(t + t_offset, f0, f1, t1)[:, None]
    xs = np.asarray(simulate(NMSD(), np.asarray(x0, float), t, u, rtol=1e-10, atol=1e-12))
    return Trajectory(t, xs[:, :1], u, xs[:, 1:], name=name)


@pytest.fixture(scope="module")
def nmsd_data():
    """The paper's N-MSD recipe, shortened: a chirp-driven run cut into 2 s segments + a held-out run."""
    long = _nmsd_trajectory([0.6, -2.0], 20.0, t1=20.0)
    n = int(round(2.0 / DT))
    train_set = [
        Trajectory(
            long.t[k * n : k * n + n + 1] - long.t[k * n],
            long.q[k * n : k * n + n + 1],
            long.u[k * n : k * n + n + 1],
            long.qd[k * n : k * n + n + 1],
            name=str(k),
        )
        for k in range(10)
    ]
    held_out = _nmsd_trajectory([-0.5, 3.0], 6.0, t1=20.0, t_offset=3.0, name="test")
    return train_set, held_out


def _rmse(model, traj):
    x = np.asarray(simulate(model, traj.x[0], traj.t, traj.u, rtol=1e-6, atol=1e-9, throw=False))
    return float(np.sqrt(np.mean((x - traj.x) ** 2)))


# -- losses: gradients ------------------------------------------------------------------------


def test_every_loss_gradient_is_finite_and_matches_finite_differences(nmsd_data):
    train_set, _ = nmsd_data
    model = make_model("nmsd", "adln", jax.random.PRNGKey(1), hidden=(4, 4))
    traj_w = make_windows(train_set[:2], 6, stride=40)
    int_w = make_windows(train_set[:2], 41, stride=40, cover_end=True)
    params, static = eqx.partition(model, model.trainable())
    flat, unravel = jax.flatten_util.ravel_pytree(params)

    def losses(vec):
        m = eqx.combine(unravel(vec), static)
        return jnp.stack(
            [
                trajectory_loss(m, traj_w),
                integral_loss(m, int_w, normalize="momentum"),
                integral_loss(m, int_w, normalize="none", rule="simpson"),
                augmentation_penalty(m, traj_w),
            ]
        )

    # one compiled gradient for all four: a random positive combination, each loss divided by
    # its value so none hides under the others (a wrong gradient of any one shows up here)
    values = np.asarray(jax.jit(losses)(flat))
    assert np.all(np.isfinite(values)) and np.all(values > 0)
    weights = np.random.default_rng(1).uniform(0.5, 1.5, values.shape) / values
    value_and_grad = jax.jit(jax.value_and_grad(lambda v: losses(v) @ weights))
    value, grad = value_and_grad(flat)
    assert np.all(np.isfinite(grad)) and np.linalg.norm(grad) > 0
    direction = np.random.default_rng(0).standard_normal(flat.shape)
    direction /= np.linalg.norm(direction)
    eps = 1e-5
    fd = (value_and_grad(flat + eps * direction)[0] - value_and_grad(flat - eps * direction)[0]) / (2 * eps)
    ad = float(np.asarray(grad) @ direction)
    assert ad == pytest.approx(float(fd), rel=1e-4, abs=1e-8 * float(value))


# -- training -----------------------------------------------------------------------------------


def test_short_nmsd_training_with_l_prop_lowers_losses_and_held_out_error(nmsd_data, tmp_path):
    train_set, held_out = nmsd_data
    config = TrainSettings(
        epochs=(16,),
        horizons=(2,),
        learning_rate=1e-2,
        batch_size=128,
        progress=False,
        checkpoint_every=8,
    )
    hparams = dict(hidden=(16, 16))
    untrained = make_model("nmsd", "dln", jax.random.PRNGKey(config.seed), **hparams)
    model, history = train("dln", "nmsd", "prop", train_set, config, tmp_path, hparams=hparams)
    first, last = history[0], history[-1]
    assert last["itau"] < 0.1 * first["itau"]
    assert last["traj"] < 0.1 * first["traj"]
    before, after = _rmse(untrained, held_out), _rmse(model, held_out)
    assert after < 0.5 * before, (before, after)
    # files: final model, a snapshot, the resumable state and the history
    loaded = ckpt.load_model(tmp_path / "model.eqx", expected_system="nmsd")
    assert _rmse(loaded, held_out) == after
    assert (tmp_path / "model_epoch000008.eqx").exists() and (tmp_path / "history.json").exists()
    with pytest.raises(FileExistsError, match="resume"):
        train("dln", "nmsd", "prop", train_set, config, tmp_path, hparams=hparams)


def test_training_step_lowers_its_loss_and_refuses_an_unknown_one(nmsd_data):
    """The public step (benchmarks time it): finite, L_Iτ lower after a few steps; an unknown loss
    is one clear error."""
    train_set, _ = nmsd_data
    model = make_model("nmsd", "dln", jax.random.PRNGKey(0), hidden=(8, 8))
    step, params, opt_state = training_step(model, TrainSettings(progress=False), "itau")
    windows = make_windows(train_set, 11, stride=10, cover_end=True)
    lam, lr = jnp.asarray(0.0), jnp.asarray(3e-3)
    first = None
    for _ in range(20):
        params, opt_state, losses, ok = step(params, opt_state, None, windows, lam, lr)
        assert bool(ok) and np.isfinite(float(losses["itau"]))
        first = float(losses["itau"]) if first is None else first
    assert float(losses["itau"]) < 0.8 * first  # 20 steps halve it; a broken step leaves it
    with pytest.raises(ValueError, match="loss: expected one of"):
        training_step(model, TrainSettings(progress=False), "l2")


def _itau_config(**kw):
    base = dict(epochs=(4,), horizons=(2,), learning_rate=5e-3, progress=False, integral_batch_size=3)
    base.update(kw)
    return TrainSettings(**base)


def test_resume_continues_the_same_optimiser_state(nmsd_data, tmp_path):
    """2 epochs, stop, resume to 4 == 4 epochs straight, bit for bit."""
    train_set, _ = nmsd_data
    hp = dict(hidden=(4, 4))
    straight, h_straight = train("dln", "nmsd", "itau", train_set, _itau_config(), tmp_path / "a", hparams=hp)
    train("dln", "nmsd", "itau", train_set, _itau_config(epochs=(2,)), tmp_path / "b", hparams=hp)
    resumed, h_resumed = train(
        "dln", "nmsd", "itau", train_set, _itau_config(), tmp_path / "b", resume=True, hparams=hp
    )
    assert len(h_resumed) == 4 and [h["itau"] for h in h_resumed] == [h["itau"] for h in h_straight]
    for a, b in zip(jax.tree_util.tree_leaves(straight), jax.tree_util.tree_leaves(resumed), strict=True):
        np.testing.assert_array_equal(a, b)
    # resuming on other data is refused
    other = [Trajectory(tr.t, tr.q * 1.01, tr.u, tr.qd) for tr in train_set]
    with pytest.raises(ValueError, match="data_hash"):
        train("dln", "nmsd", "itau", other, _itau_config(epochs=(5,)), tmp_path / "b", resume=True, hparams=hp)


def test_resume_refuses_other_training_settings(nmsd_data, tmp_path):
    """A saved run continues only under its own settings: another step size or λ is refused
    (naming each), more epochs are not."""
    train_set, _ = nmsd_data
    hp = dict(hidden=(4, 4))
    train("dln", "nmsd", "itau", train_set, _itau_config(epochs=(2,)), tmp_path, hparams=hp)
    with pytest.raises(ValueError, match="other training settings") as err:
        train(
            "dln",
            "nmsd",
            "itau",
            train_set,
            _itau_config(epochs=(3,), learning_rate=1e-3, lambda_traj=0.5),
            tmp_path,
            resume=True,
            hparams=hp,
        )
    assert "learning_rate: saved 0.005, now 0.001" in str(err.value)
    assert "lambda_traj: saved 1.0, now 0.5" in str(err.value)
    assert "epochs" not in str(err.value)
    _, history = train("dln", "nmsd", "itau", train_set, _itau_config(epochs=(3,)), tmp_path, resume=True, hparams=hp)
    assert len(history) == 3


def test_nan_guard_skips_poisoned_steps_and_never_saves_nan(nmsd_data, tmp_path):
    train_set, _ = nmsd_data
    poisoned = list(train_set)
    bad_q = poisoned[3].q.copy()
    bad_q[50] = np.nan
    poisoned[3] = Trajectory(poisoned[3].t, bad_q, poisoned[3].u, poisoned[3].qd, name="bad")
    with pytest.warns(RuntimeWarning, match="NaN guard"):
        model, history = train(
            "dln", "nmsd", "itau", poisoned, _itau_config(epochs=(2,)), tmp_path, hparams=dict(hidden=(4, 4))
        )
    skipped = sum(h["skipped"] for h in history)
    assert skipped >= 1 and skipped < sum(h["steps"] for h in history)
    assert all(np.all(np.isfinite(np.asarray(l))) for l in jax.tree_util.tree_leaves(model))
    assert np.isfinite(history[-1]["itau"])
    assert np.all(np.isfinite(np.asarray(jax.tree_util.tree_leaves(ckpt.load_model(tmp_path / "model.eqx"))[0])))


# -- checkpoints -------------------------------------------------------------------------------


@pytest.mark.parametrize("system,kind", [("nmsd", "dln"), ("furuta", "aph"), ("furuta", "adln")])
def test_checkpoint_roundtrip_is_bit_identical(tmp_path, system, kind):
    model = make_model(system, kind, jax.random.PRNGKey(3), hidden=(5, 7)).with_scale(1.2345)
    path = ckpt.save_model(tmp_path / "m.eqx", model, {"note": "x"})
    loaded = ckpt.load_model(path)
    assert type(loaded) is type(model)
    assert jax.tree_util.tree_structure(loaded) == jax.tree_util.tree_structure(model)
    for a, b in zip(jax.tree_util.tree_leaves(model), jax.tree_util.tree_leaves(loaded), strict=True):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
    header = ckpt.read_header(path)
    assert header["system"] == system and header["model_kind"] == kind and header["meta"] == {"note": "x"}
    assert "jax" in header["versions"]
    with pytest.raises(FileExistsError):
        ckpt.save_model(path, model)


def test_checkpoint_errors_are_clear(tmp_path):
    model = make_model("nmsd", "dln", 0, hidden=(4, 4))
    path = ckpt.save_model(tmp_path / "m.eqx", model)
    with pytest.raises(ckpt.CheckpointError, match="'nmsd' model; expected a 'furuta'"):
        ckpt.load_model(path, expected_system="furuta")
    with pytest.raises(FileNotFoundError, match="no such checkpoint"):
        ckpt.load_model(tmp_path / "missing.eqx")
    raw = path.read_bytes()
    (tmp_path / "cut.eqx").write_bytes(raw[:-20])
    with pytest.raises(ckpt.CheckpointError, match="corrupt"):
        ckpt.load_model(tmp_path / "cut.eqx")
    (tmp_path / "junk.eqx").write_bytes(b"hello")
    with pytest.raises(ckpt.CheckpointError, match="not a furuta-gym checkpoint"):
        ckpt.load_model(tmp_path / "junk.eqx")
    nan_model = eqx.tree_at(lambda m: m.log_damping, model, jnp.array([jnp.nan, 0.0]))
    with pytest.raises(ValueError, match="NaN"):
        ckpt.save_model(tmp_path / "nan.eqx", nan_model)


# -- scale fit ---------------------------------------------------------------------------------


def test_scale_fit_recovers_a_known_scale():
    """Data from a model at scale 2.5 (fine RK4, constant input so the input impulse is exact);
    fitting the scale-1 model recovers 2.5."""
    truth = make_model("nmsd", "dln", jax.random.PRNGKey(5), hidden=(8, 8)).with_scale(2.5)
    dt, sub = 0.005, 10
    us = np.full((800, 1), 0.7)
    xs = np.asarray(jax.jit(lambda x0: rollout_zoh(truth, x0, jnp.asarray(us), dt, sub))(jnp.array([0.3, -1.0])))
    t = np.arange(xs.shape[0]) * dt
    traj = Trajectory(t, xs[:, :1], np.full((len(t), 1), 0.7), xs[:, 1:], name="forced")
    fitted, fit = fit_scale(truth.with_scale(1.0), [traj], rule="simpson")
    assert fit.factor == pytest.approx(2.5, rel=1e-4)
    assert float(fitted.scale) == pytest.approx(2.5, rel=1e-4)
    assert fit.relative_residual_after < 1e-3 < fit.relative_residual_before
    with pytest.raises(ValueError, match="forced trajectory"):
        fit_scale(truth, [Trajectory(t, traj.q, np.zeros_like(traj.u), traj.qd)])


# -- CLI ---------------------------------------------------------------------------------------


def test_cli_trains_writes_a_loadable_model_and_reports_bad_input(nmsd_data, tmp_path, capsys):
    from furuta_gym.cli import main
    from furuta_gym.data import save_trajectories

    data = tmp_path / "train.csv"
    save_trajectories(data, nmsd_data[0][:4], "nmsd")
    out = tmp_path / "run"
    args = [
        "train",
        "--system",
        "nmsd",
        "--model",
        "dln",
        "--loss",
        "itau",
        "--data",
        str(data),
        "--out",
        str(out),
        "--epochs",
        "3",
        "--hidden",
        "4,4",
        "--no-progress",
    ]
    assert main(args) == 0
    model = ckpt.load_model(out / "model.eqx", expected_system="nmsd")
    assert model.hyperparameters["hidden"] == (4, 4)
    assert ckpt.read_header(out / "model.eqx")["meta"]["epoch"] == 3
    assert main(args) == 2  # the run exists: refused without --resume
    assert "--resume" in capsys.readouterr().err
    assert main(args[:-1] + ["--epochs", "4", "--resume", "--no-progress"]) == 0
    assert ckpt.read_header(out / "model.eqx")["meta"]["epoch"] == 4
    assert (
        main(
            [
                "train",
                "--system",
                "furuta",
                "--model",
                "dln",
                "--loss",
                "itau",
                "--data",
                str(data),
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "train.csv" in err
