"""furuta_gym.diagnose.finish_ablation: the folds follow the diagnosis' held-out split, and the
friction laws an ablation swaps in behave as named (MuJoCo's soft friction loss lets a loaded
joint creep where the diagnosis' Karnopp law holds it)."""

import types

import jax.numpy as jnp
import numpy as np

import furuta_gym
from furuta_gym.diagnose import DiagnosisSettings
from furuta_gym.diagnose.finish_ablation import MUJOCO_IMPEDANCE, fold_of, soft_friction_dynamics
from furuta_gym.lagrangian import forward_dynamics, forward_dynamics_with_dry_friction
from furuta_gym.models import Furuta

furuta_gym.enable_x64()


def test_folds_are_every_third_segment_of_a_log():
    names = ["run01[0]", "run01[1]", "run01[2]", "run01[5]", "run02/2[11]"]
    assert [fold_of(types.SimpleNamespace(name=n)) for n in names] == [0, 1, 2, 2, 2]


def test_soft_friction_loss_creeps_where_karnopp_holds():
    model = Furuta()
    q, qd, u = jnp.array([0.0, 0.0]), jnp.zeros(2), jnp.array([0.5])
    limit = jnp.array([1.0, 1.0])  # far above what the input and gravity ask of either joint
    free = np.asarray(forward_dynamics(model, q, qd, u))
    held = np.asarray(forward_dynamics_with_dry_friction(model, limit, q, qd, u, 1e-3))
    soft = np.asarray(soft_friction_dynamics(model, limit, q, qd, u))
    assert abs(free[0]) > 1.0
    assert np.all(np.abs(held) < 1e-6 * abs(free[0]))
    # the constraint supplies only the impedance's share of the holding force: the rest moves it
    assert 0.5 * (1 - MUJOCO_IMPEDANCE) < soft[0] / free[0] < 2.0 * (1 - MUJOCO_IMPEDANCE)


def _segment(name, t0, n, dt=0.002):
    from furuta_gym.diagnose._fit import Segment

    t = t0 + dt * np.arange(n)
    q = np.stack([t, -t], axis=1)
    return Segment(name, t, q, np.ones_like(q), t[:, None].copy(), dt, 0, False)


def test_window_placements_start_where_named():
    from furuta_gym.diagnose._finish import log_starts, placed_windows
    from furuta_gym.diagnose._fit import InputDynamics

    # a log whose first sample is at 0.5 s, trimmed 0.05 s; its second segment starts 2.154 s later
    segs = [_segment("run01[0]", 0.55, 1077), _segment("run01[1]", 2.704, 1077)]
    starts = log_starts(segs, 0.05)
    assert starts == {"run01": 0.5}
    first = lambda win, k: np.round((win.x0[win.segment == k, 0] - 0.5) / 0.002).astype(int)  # noqa: E731
    own = placed_windows(segs, 50, InputDynamics(), "segments", starts)
    grid = placed_windows(segs, 50, InputDynamics(), "grid", starts)
    every = placed_windows(segs, 50, InputDynamics(), "starts", starts)
    # the segments' own: back to back from each segment's first sample (25 and 1102 on the log)
    assert first(own, 0)[:2].tolist() == [25, 75] and first(own, 1)[:2].tolist() == [1102, 1152]
    assert len(own.x0) == 2 * 21
    # on the log's grid: multiples of 50 samples from the log's first sample, inside each segment
    assert first(grid, 0)[:2].tolist() == [50, 100] and first(grid, 1)[:2].tolist() == [1150, 1200]
    assert np.all(first(grid, 0) % 50 == 0) and np.all(first(grid, 1) % 50 == 0)
    assert len(grid.x0) == 21 + 20
    # every 10 ms (5 samples) of the log
    assert first(every, 0)[:3].tolist() == [25, 30, 35] and first(every, 1)[:2].tolist() == [1105, 1110]
    assert len(every.x0) == 206 + 205
    # each window's measured positions follow its start
    k = 7
    assert np.allclose(grid.q[k, 0], grid.x0[k, :2] + [0.002, -0.002])


def test_the_finish_refits_on_windows_that_follow_one_another_with_a_gap():
    """The prediction-first refit's windows: one after another with a 10 ms gap from each log's
    first sample, so they never overlap and their starts move through every 10 ms point of a
    0.1 s cycle, where back-to-back windows of these two segments start at two points only."""
    from furuta_gym.diagnose._finish import refit_windows
    from furuta_gym.diagnose._fit import InputDynamics

    segs = [_segment("run01[0]", 0.55, 1077), _segment("run01[1]", 2.704, 1077)]
    fx = types.SimpleNamespace(L=50, segs=segs, settings=DiagnosisSettings().replaced(trim_seconds=0.05))
    win = refit_windows(fx, segs, InputDynamics())
    assert win.x0.shape == (19 + 18, 4) and win.us.shape == (37, 50, 1)
    start = np.round((win.x0[:, 0] - 0.5) / 0.002).astype(int)  # each start's sample on the log
    assert start[:3].tolist() == [55, 110, 165] and start[19:21].tolist() == [1155, 1210]
    assert sorted(set((start % 50).tolist())) == list(range(0, 50, 5))
    assert np.all(np.diff(start[:19]) == 55) and np.all(np.diff(start[19:]) == 55)
    back_to_back = {k % 50 for k in (25, 1102)}
    assert len(back_to_back) == 2


def test_dead_band_input_follows_the_delay_and_passes_nothing_below_its_band():
    """The dead-band variant's input: the delay first, then sign(u)·max(|u| − d, 0)."""
    from furuta_gym.diagnose._fit import InputDynamics
    from furuta_gym.diagnose.finish_ablation import DeadBandInput

    dt, u = 0.002, np.array([[0.0], [0.01], [-0.01], [0.5], [-0.5], [0.03]])
    banded = DeadBandInput("delay", 0.004, 0.02)
    delayed = InputDynamics("delay", 0.004).apply(u, dt)
    expected = np.sign(delayed) * np.maximum(np.abs(delayed) - 0.02, 0.0)
    assert np.allclose(banded.apply(u, dt), expected)
    assert np.allclose(DeadBandInput("none", 0.0, 0.02).apply(u, dt).ravel(), [0, 0, 0, 0.48, -0.48, 0.01])
    assert np.allclose(DeadBandInput("delay", 0.004).apply(u, dt), delayed)  # no band: the delay alone
