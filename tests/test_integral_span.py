"""L_Iτ over longer intervals (``TrainConfig.integral_span``;
:func:`furuta_gym.training.losses.span_sum`): the same equation, summed over consecutive
quadrature intervals, so that the estimated velocities' error weighs less against the physics."""

import numpy as np
import pytest

from furuta_gym.diagnose import measured_like
from furuta_gym.lagrangian import integral_residual, momentum
from furuta_gym.measured import prepare_log
from furuta_gym.models import Furuta, FurutaParameters
from furuta_gym.training.losses import integral_loss, make_windows, span_sum
from furuta_gym.training.train import TrainConfig


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
        return float(integral_loss(Furuta(FurutaParameters(g=g)), windows, rule="simpson", normalize="none",
                                   span=span))
    return loss(0.0) / loss(9.81)


def test_a_longer_span_lets_the_loss_see_gravity_through_encoder_counts(balancing_windows):
    paper, long = _gravity_contrast(balancing_windows, 1), _gravity_contrast(balancing_windows, 25)
    # per interval the estimator's error all but hides gravity; over 0.1 s it stands out
    assert paper < 2.0
    assert long > 3.0 * paper


def test_span_is_checked():
    with pytest.raises(ValueError, match="integral_span"):
        TrainConfig(integral_span=0)
    with pytest.raises(ValueError, match="integral_span"):
        TrainConfig(integral_span=2, resolution_tolerance=1e-3)
    with pytest.raises(ValueError, match="span"):
        integral_loss(Furuta(), _tiny_windows(), span=0)


def _tiny_windows():
    from furuta_gym.data import Trajectory

    t = np.arange(5) * 0.01
    return make_windows([Trajectory(t, np.zeros((5, 2)), np.zeros((5, 1)), np.zeros((5, 2)))], 5)
