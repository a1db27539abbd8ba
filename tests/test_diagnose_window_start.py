"""Open-loop prediction windows whose start velocity is estimated from the window's own positions
(Gauss-Newton on the start velocity, ``start_iterations``): what the stiction test uses, since a
smoothed velocity estimate does not resolve a joint that is about to stop."""

from __future__ import annotations

import numpy as np
import pytest

import furuta_gym
from furuta_gym.diagnose import _windows as windows_mod, diagnose
from furuta_gym.diagnose._library import layout_for
from furuta_gym.rigs import measured_like

furuta_gym.enable_x64()

DT, L = 0.002, 50


def _windows(layout, theta, velocity_error, noise=0.0, seed=0):
    """Four windows simulated by the model itself from known states, handed to the predictor with
    start velocities off by ``velocity_error`` (rad/s) and positions with Gaussian noise."""
    rng = np.random.default_rng(seed)
    x0 = np.array([[0.1, 3.0, 1.0, -2.0], [0.0, 0.2, -0.5, 3.0], [-0.3, 1.0, 0.0, 0.0], [0.5, np.pi, 2.0, 0.3]])
    us = rng.uniform(-2, 2, (4, L, 1))
    truth = windows_mod.Windows(x0, us, np.zeros((4, L, 2)), np.zeros(4, int), DT, L)
    q = windows_mod.predict_windows(layout, theta, truth, 2) + noise * rng.standard_normal((4, L, 2))
    start = x0.copy()
    start[:, 2:] += velocity_error
    return windows_mod.Windows(start, us, q, np.zeros(4, int), DT, L)


def test_estimated_start_velocity_recovers_the_true_one():
    layout = layout_for("furuta")
    theta = layout.nominal()
    win = _windows(layout, theta, velocity_error=np.array([0.3, -0.4]))
    as_given = windows_mod.window_errors(layout, theta, win, 2)[1]
    estimated = windows_mod.window_errors(layout, theta, win, 2, start_iterations=1)[1]
    assert as_given > 1e-3  # 0.3 rad/s over 0.1 s
    assert estimated < 1e-2 * as_given  # one Gauss-Newton step


def test_estimated_start_never_predicts_worse_and_reaches_the_noise_floor():
    layout = layout_for("furuta")
    theta = layout.nominal()
    noise = 1e-3
    win = _windows(layout, theta, velocity_error=np.array([0.2, 0.5]), noise=noise, seed=1)
    sums_given = windows_mod.window_square_sums(layout, theta, win, 2)
    sums_one = windows_mod.window_square_sums(layout, theta, win, 2, start_iterations=1)
    assert np.all(sums_one <= sums_given)
    rms = np.sqrt(sums_one.sum() / win.q.size)
    assert rms < 1.1 * noise  # two fitted numbers per window: just under the noise itself


def test_bad_start_iterations_is_named():
    data = measured_like("furuta", [], seed=0, n_trajectories=2, duration=3.0)
    with pytest.raises(ValueError, match="start_iterations"):
        diagnose(data, "furuta", start_iterations=-1)


def test_windows_under_several_parameter_sets_are_predicted_as_one_by_one():
    """The output-error fit's Jacobian predicts every (θ, window) pair in shared batches: each
    pair as if predicted alone, whatever batch it lands in (17 parameter sets × 4 windows: two
    batches that mix parameter sets, the last one padded)."""
    layout = layout_for("furuta")
    theta = layout.nominal()
    win = _windows(layout, theta, velocity_error=np.array([0.3, -0.4]))
    rng = np.random.default_rng(2)
    thetas = np.repeat(theta[None], 17, axis=0)
    thetas[:, : len(layout.base)] *= rng.uniform(0.9, 1.1, (17, len(layout.base)))
    thetas[:, layout.index("coulomb_friction:alpha")] = rng.uniform(0.0, 5e-4, 17)
    assert len(thetas) * len(win.x0) > windows_mod._BATCH
    together = windows_mod.predict_windows_at(layout, thetas, win, 2, start_iterations=1)
    alone = np.stack([windows_mod.predict_windows(layout, th, win, 2, start_iterations=1) for th in thetas])
    assert together.shape == (17, *win.q.shape)
    np.testing.assert_allclose(together, alone, rtol=1e-12, atol=1e-15)
    assert np.abs(together - together[:1]).max() > 1e-4  # the parameter sets do differ
