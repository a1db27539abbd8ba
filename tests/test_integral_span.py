"""L_Iτ over longer intervals (``TrainSettings.integral_span``;
:func:`furuta_gym.training.losses.span_sum`): the same equation, summed over consecutive
quadrature intervals, so that the estimated velocities' error weighs less against the physics."""

import numpy as np
import pytest

from furuta_gym.lagrangian import integral_residual, momentum
from furuta_gym.measured import prepare_log
from furuta_gym.models import Furuta, FurutaParameters
from furuta_gym.rigs import measured_like
from furuta_gym.training.losses import integral_loss, make_windows, span_sum
from furuta_gym.training.train import TrainSettings


def test_span_sum_groups_consecutive_intervals_with_a_shorter_last_group():
    x = np.arange(14.0).reshape(7, 2)
    out = np.asarray(span_sum(x, 3))
    assert np.array_equal(out, [x[0:3].sum(0), x[3:6].sum(0), x[6:7].sum(0)])
    assert np.array_equal(np.asarray(span_sum(x, 1)), x)


@pytest.mark.parametrize("rule", ["trapezoid", "simpson"])
def test_a_span_over_the_whole_window_is_one_residual_from_its_first_to_its_last_sample(rule):
    # free motion of a frictionless, input-free model: the residual over any interval is the
    # momentum change minus the impulse of the potential-derived forces; over the whole window
    # the momentum's interior samples cancel, so changing them changes only the impulse terms
    rng = np.random.default_rng(0)
    T, dt = 21, 0.01
    model = Furuta(FurutaParameters(g=0.0, c_r=0.0, c_p=0.0, km=0.0))
    q, qd, u = np.zeros((T, 2)), rng.normal(size=(T, 2)), np.zeros((T, 1))
    whole = np.asarray(span_sum(integral_residual(model, q, qd, u, dt, rule), T))[0]
    # with q fixed at 0 the mass matrix is constant and there is no force: residual = −Δp
    p0, p1 = np.asarray(momentum(model, q[0], qd[0])), np.asarray(momentum(model, q[-1], qd[-1]))
    assert np.allclose(whole, -(p1 - p0), rtol=1e-12, atol=1e-15)


@pytest.fixture(scope="module")
def balancing_windows():
    """Upright balancing under feedback, 2048-count encoders, velocities estimated from the
    counts: the shipped real runs' kind of data, where the truth is known."""
    runs = measured_like("furuta", (), excitation="closed_loop_prbs", n_trajectories=2, duration=6.0, seed=3)
    pieces = [p for tr in runs for p in prepare_log(tr, tr.name, skip=0.5, min_seconds=1.0)]
    return make_windows(pieces, 101, stride=100, cover_end=True)


def _gravity_contrast(windows, span):
    """L_Iτ without gravity over L_Iτ of the truth: how strongly the loss tells the physical
    potential from none."""

    def loss(g):
        return float(integral_loss(Furuta(FurutaParameters(g=g)), windows, rule="simpson", normalize="none", span=span))

    return loss(0.0) / loss(9.81)


def test_a_longer_span_lets_the_loss_see_gravity_through_encoder_counts(balancing_windows):
    paper, long = _gravity_contrast(balancing_windows, 1), _gravity_contrast(balancing_windows, 25)
    # per interval the estimator's error all but hides gravity; over 0.1 s it stands out
    assert paper < 2.0
    assert long > 3.0 * paper


def test_span_is_checked():
    with pytest.raises(ValueError, match="integral_span"):
        TrainSettings(integral_span=0)
    with pytest.raises(ValueError, match="integral_span"):
        TrainSettings(integral_span=2, resolution_tolerance=1e-3)
    with pytest.raises(ValueError, match="span"):
        integral_loss(Furuta(), _tiny_windows(), span=0)


def _tiny_windows():
    from furuta_gym.data import Trajectory

    t = np.arange(5) * 0.01
    return make_windows([Trajectory(t, np.zeros((5, 2)), np.zeros((5, 1)), np.zeros((5, 2)))], 5)


def test_the_scale_fit_over_a_longer_span_is_not_diluted_by_velocity_noise():
    """Noise in estimated velocities is noise in the scale fit's regressor Ā (momentum at the
    interval ends): per interval it biases the scale towards zero; over a span it weighs less."""
    import jax
    import jax.numpy as jnp

    from furuta_gym.data import Trajectory
    from furuta_gym.models import make_model
    from furuta_gym.simulate import rollout_zoh
    from furuta_gym.training.train import fit_scale

    truth = make_model("nmsd", "dln", jax.random.PRNGKey(5), hidden=(8, 8)).with_scale(2.5)
    dt, n = 0.01, 1000
    us = np.sin(2 * np.pi * 0.4 * np.arange(n) * dt)[:, None]
    xs = np.asarray(rollout_zoh(truth, jnp.array([0.3, -1.0]), jnp.asarray(us), dt, 20))[:n]
    noisy_qd = xs[:, 1:] + np.random.default_rng(0).normal(0.0, 0.05 * np.std(xs[:, 1]), size=(n, 1))
    traj = Trajectory(np.arange(n) * dt, xs[:, :1], us, noisy_qd, name="forced, noisy velocities")
    factor = {span: fit_scale(truth.with_scale(1.0), [traj], rule="simpson", span=span)[1].factor for span in (1, 20)}
    assert factor[1] < 0.9 * 2.5  # diluted
    assert abs(factor[20] - 2.5) < 0.25 * abs(factor[1] - 2.5)


def test_reproduce_sums_the_integral_residual_of_its_L_prop_runs_only():
    from furuta_gym.training.reproduce import ReproduceSettings, training_settings

    config = ReproduceSettings(systems=("furuta",), integral_span=10)
    assert training_settings("furuta", config, 0, "prop", "dln").integral_span == 10
    assert training_settings("furuta", config, 0, "traj", "dln").integral_span == 1
    assert training_settings("furuta", ReproduceSettings(), 0, "prop", "dln").integral_span == 1
    with pytest.raises(ValueError, match="integral_span must be a positive integer"):
        ReproduceSettings(integral_span=0)


def test_reproduce_can_train_on_velocities_estimated_offline_and_records_it():
    from furuta_gym.data import Trajectory
    from furuta_gym.training._reproduce_data import _training_data
    from furuta_gym.training.reproduce import ReproduceSettings, run_settings

    t = np.arange(200) * 0.01
    q = np.stack([np.sin(2 * t), 0.5 * np.cos(3 * t)], axis=1)
    lagged = np.stack([2 * np.cos(2 * (t - 0.016)), -1.5 * np.sin(3 * (t - 0.016))], axis=1)
    data = {
        "train": [Trajectory(t, q, np.zeros((200, 1)), lagged)],
        "scale_fit": [Trajectory(t, q, np.ones((200, 1)), lagged)],
    }
    offline = ReproduceSettings(systems=("furuta",), training_velocities="zero_phase")
    train, forced = _training_data("furuta", data, offline)
    exact = np.stack([2 * np.cos(2 * t), -1.5 * np.sin(3 * t)], axis=1)
    inner = slice(20, -20)  # away from the filter's ends
    for trajs in (train, forced):
        assert np.max(np.abs(trajs[0].qd[inner] - exact[inner])) < 0.2 * np.max(np.abs(lagged - exact))
    assert _training_data("furuta", data, ReproduceSettings(systems=("furuta",)))[0][0].qd is lagged
    assert run_settings("furuta", "dln", "prop", 0, offline)["training_velocities"] == "zero_phase"
    assert "training_velocities" not in run_settings("furuta", "dln", "prop", 0, ReproduceSettings())
    with pytest.raises(ValueError, match="training_velocities must be one of"):
        ReproduceSettings(training_velocities="filter")


def test_reproduce_command_line_names_the_span_and_the_training_velocities():
    from furuta_gym.cli import build_parser
    from furuta_gym.cli.reproduce import config_from_args

    _, config = config_from_args(
        build_parser().parse_args(["reproduce", "--integral-span", "5", "--training-velocities", "zero_phase"])
    )
    assert (config.integral_span, config.training_velocities) == (5, "zero_phase")
    _, default = config_from_args(build_parser().parse_args(["reproduce"]))
    assert (default.integral_span, default.training_velocities) == (1, "recorded")
