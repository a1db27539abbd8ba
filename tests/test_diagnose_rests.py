"""What rests say about dry friction, and what is below the sensor (issue 43).

A joint that stays at one encoder count was held by its dry friction against every other force on
it: the force that held it bounds the breakaway level from below, with no velocity estimate. An
effect smaller than one count or one sample is reported as not resolved, not as found or missed.
"""

from __future__ import annotations

import numpy as np
import pytest

import furuta_gym
from furuta_gym.data import Trajectory
from furuta_gym.diagnose import DiagnosisSettings, _diagnose, _fit, held_at_rest, layout_for, stop_excursions
from furuta_gym.diagnose._fit import NO_INPUT_DYNAMICS, Segment
from furuta_gym.diagnose._fitter import _Fitter
from furuta_gym.diagnose._prepare import _segments, prepare, sensor_resolution
from furuta_gym.diagnose._rests import rest_bound
from furuta_gym.diagnose._result import EffectEvidence
from furuta_gym.diagnose._verdict import _mark_unresolved
from furuta_gym.rigs import measured_like, sticky_rig
from furuta_gym.systems import get_spec

furuta_gym.enable_x64()
COUNT = 2 * np.pi / 2048
DT = 0.002


def _segment(alpha_counts: np.ndarray, u: np.ndarray) -> Segment:
    """A rotor at the given counts, the pendulum hanging still, input ``u`` (V)."""
    T = alpha_counts.size
    q = np.stack([alpha_counts * COUNT, np.zeros(T)], 1)
    return Segment("run[0]", np.arange(T) * DT, q, np.zeros((T, 2)), u[:, None], DT, 0, False)


def test_a_rotor_held_at_one_count_bounds_its_breakaway_by_the_force_it_was_held_against():
    layout = layout_for("furuta")
    theta = layout.nominal()
    theta[layout.index("spring:alpha")] = 2e-3  # a cable pulling back from 5 counts off its neutral
    force = theta[layout.index("K")] * 0.2 - 2e-3 * 5 * COUNT  # the motor's push minus the spring's pull
    # held at count 5 for 0.6 s (three 0.2 s windows), then moving
    counts = np.concatenate([np.full(300, 5.0), 5.0 + np.arange(1, 101)])
    seg = _segment(counts, np.full(counts.size, 0.2))
    bound = rest_bound(layout, theta, [seg], NO_INPUT_DYNAMICS, "alpha", COUNT, 0.2)
    assert bound.n_windows == 3
    assert bound.slack == pytest.approx(2 * theta[layout.index("J1")] * COUNT / 0.2**2)
    assert bound.held == pytest.approx(force - bound.slack, rel=1e-6)
    # a rotor that never stays on one count for a whole window says nothing
    moving = _segment(np.arange(400.0), np.full(400, 0.2))
    assert rest_bound(layout, theta, [moving], NO_INPUT_DYNAMICS, "alpha", COUNT, 0.2).n_windows == 0


def test_held_at_rest_takes_measured_trajectories_and_estimates_their_velocities():
    layout = layout_for("furuta")
    theta = layout.nominal()
    theta[layout.index("spring:alpha")] = 2e-3
    counts = np.concatenate([np.full(300, 5.0), 5.0 + np.arange(1, 101)])
    seg = _segment(counts, np.full(counts.size, 0.2))
    log = [Trajectory(t=seg.t, q=seg.q, u=seg.u, qd=None, name="run")]
    bound = held_at_rest(log, "alpha", layout, theta)  # the diagnosis' window, the QUBE's encoder
    expected = rest_bound(layout, theta, [seg], NO_INPUT_DYNAMICS, "alpha", COUNT, 0.2)
    assert bound.n_windows == expected.n_windows == 3
    # the estimated velocity is zero along a rest: the same force held it
    assert bound.held == pytest.approx(expected.held, rel=1e-6) and bound.held > 0


def test_sensor_resolution_is_the_encoder_count_of_quantised_joints_only():
    spec = get_spec("furuta")
    t = np.arange(200) * DT
    counts = np.round(np.sin(3 * t) * 200) * COUNT + np.pi  # an offset keeps the steps whole counts
    q = np.stack([counts, np.sin(2 * t) + 0.01 * t], 1)  # the pendulum's angle is not quantised
    res = sensor_resolution([Trajectory(t=t, q=q, u=np.zeros((200, 1)), qd=None, name="a")], spec)
    assert res == {"alpha": pytest.approx(COUNT)}


def test_effects_below_one_count_or_one_sample_are_kept_but_reported_not_resolved():
    notes: list[str] = []
    effects = [
        EffectEvidence("com_offset", "beta", 2e-3, "rad", True, 0.1, 5.0, "selected"),
        EffectEvidence("com_offset", "beta", 4e-3, "rad", True, 0.1, 5.0, "selected"),
        EffectEvidence("input_delay", "u", 1.5e-3, "s", True, 0.1, 5.0, "selected"),
        EffectEvidence("actuator_lag", "u", 5e-3, "s", True, 0.1, 5.0, "selected"),
        EffectEvidence("com_offset", "beta", 1e-3, "rad", False, 0.0, 0.0, "tested"),
    ]
    _mark_unresolved(effects, {"beta": COUNT}, DT, notes)
    assert [e.resolved for e in effects] == [False, True, False, True, True]
    assert all(e.significant for e in effects[:4])
    assert "under one encoder count" in effects[0].note and "under one sample period" in effects[2].note
    assert len(notes) == 2
    assert effects[0].to_json()["resolved"] is False


def test_an_interval_in_which_the_joint_stops_is_left_out_of_its_equations():
    """A joint that stays on one count for a period of the velocity estimate's bandwidth (40 ms at
    25 Hz) stopped there, and its dry friction then held it with an unknown force: that interval
    is left out of its equation error, like one at rest throughout. Moving a count every few
    samples, it is kept."""
    layout = layout_for("furuta")
    moving = np.arange(50) // 3  # a count every 3 samples (6 ms)
    dwells = np.concatenate([np.full(25, 50.0), 50.0 + np.arange(25)])  # 50 ms on one count, then moving
    counts = np.concatenate([moving, dwells, np.full(51, 75.0)])  # moving; a stop; at rest throughout
    for stop_dwell, expected in ((0.04, [False, True, True]), (None, [False, False, True])):
        seg = _segment(counts.astype(float), np.zeros(counts.size))
        _fit.build_regressors([seg], layout, layout.nominal(), 50, "zoh", stop_dwell=stop_dwell)
        assert seg.rest[:, 0].tolist() == expected


def _reversal_counts(a: float, samples: int = 200) -> np.ndarray:
    """Encoder counts of a free rotor under a constant acceleration ``a`` (rad/s²) through a
    reversal whose apex sits just inside a count's edge: the longest a free joint stays on it."""
    t = (np.arange(samples) - samples // 2) * DT
    return np.round(0.5 * a * t**2 / COUNT - 0.49)


def test_a_free_parabola_through_a_reversal_stays_within_one_count_of_its_free_excursion():
    # constant acceleration over T: the parabola through a reversal in its middle spans a·T²/8
    assert _fit.free_excursion(np.full(101, 3.0), DT) == pytest.approx(3.0 * (100 * DT) ** 2 / 8, rel=1e-9)
    # a fast force oscillation leaves a free joint within a fraction of a count (f = 20 Hz)
    t = np.arange(100) * DT
    assert _fit.free_excursion(10.0 * np.sin(2 * np.pi * 20 * t), DT) < 0.5 * COUNT


def test_the_held_test_decides_as_the_free_excursion_does():
    """held_samples decides most stops from the chord's bounds on the excursion; it answers as
    free_excursion's hull would, on stretches of every shape and limits on both sides and at the
    excursion itself."""
    rng = np.random.default_rng(0)
    for _ in range(300):
        n = int(rng.integers(3, 80))
        a = rng.normal(rng.normal(0, 3), rng.uniform(0, 20), n) + rng.uniform(0, 30) * np.sin(np.arange(n) * 0.3)
        w = _fit.free_excursion(a, DT)
        for limit in (w * 0.5, w * 0.999, w, w * 1.001, w * 2.0, 1e-12):
            assert _fit._excursion_exceeds(a, DT, limit) == (w > limit)


def test_a_stop_is_left_out_when_the_force_on_it_would_have_moved_a_free_joint_but_not_in_a_slow_pass():
    """The rotor's counts of a free reversal at 0.2 V (a = K·u/J1 = 4.3 rad/s²): 74 ms on the
    apex's count, as long as a free joint can stay on one count at that force, and kept. The
    same counts at 2 V: the free joint would have moved nine counts in that time, so its dry
    friction held it, and the intervals the stop touches are left out (``held_stop`` = 2)."""
    layout = layout_for("furuta")
    theta = layout.nominal()
    K, J1 = theta[layout.index("K")], theta[layout.index("J1")]
    counts = _reversal_counts(K * 0.2 / J1)
    apex = np.flatnonzero(counts == counts.min())
    assert apex.size == 37 and (apex[0], apex[-1]) == (82, 118)
    kept, held = (_fit.held_samples(counts * COUNT, np.full(counts.size, K * u / J1), DT, 2.0) for u in (0.2, 2.0))
    assert not kept.any()
    assert np.flatnonzero(held).tolist() == apex.tolist()
    assert _fit.free_excursion(np.full(apex.size, K * 2.0 / J1), DT) / COUNT == pytest.approx(9.2, abs=0.1)
    for u, expected in ((0.2, [False] * 3), (2.0, [False, True, True])):
        seg = _segment(counts, np.full(counts.size, u))
        _fit.build_regressors([seg], layout, theta, 50, "zoh", held_stop=2.0)
        assert seg.rest[:, 0].tolist() == expected
        _fit.build_regressors([seg], layout, theta, 50, "zoh")  # off by default
        assert not seg.rest[:, 0].any()
    # the same, as the calibration study reads it from a measured log (velocities estimated)
    log = [Trajectory(t=np.arange(counts.size) * DT, q=_segment(counts, counts).q, u=np.full((counts.size, 1), 2.0))]
    (stop,) = stop_excursions(log, "alpha", layout, theta)
    assert (stop.start, stop.samples) == (82, 37)
    assert stop.excursion == pytest.approx(9.2, abs=0.1)


def _equation_error_coefficients(data, keys, **settings) -> dict[str, float]:
    """The equation-error fit of the declared model with ``keys`` added, as the search fits it."""
    spec, notes = get_spec("furuta"), []
    layout = layout_for("furuta")
    trajs, qds, resolved = prepare(data, spec, DiagnosisSettings().replaced(**settings), {}, notes)
    fixed = _diagnose._anchor(spec, layout, None, True, notes)
    theta_fixed = layout.nominal()
    for k, v in fixed.items():
        theta_fixed[layout.index(k)] = v
    segs = _segments(trajs, qds, resolved)
    fx = _Fitter(spec, layout, segs, [], theta_fixed, {layout.index(k) for k in fixed}, resolved, notes)
    theta, _ = fx.fit_ee([c for c in layout.candidates if c.key in keys])
    return {k: float(theta[layout.index(k)]) for k in ["J1", *keys]}


def test_stops_left_out_keep_the_equation_error_spring_of_a_sticky_sweep_unbiased():
    """On a sticky sweep whose rotor stops at most reversals (issue 43's grid, seed 106), the
    intervals with a stop are where the estimated velocities, and with them the momentum and
    sgn(q̇), are wrong: fitted with them (``held_stop=None`` leaves out only whole intervals at rest),
    the rotor's inertia comes out low and the spring, which trades against it at low frequency,
    far too weak. Left out (``stop_dwell``), both come out right. Leaving out only the stops that
    friction held (``held_stop``) mends the inertia and most of the spring's shortfall: the slow passes
    it keeps carry velocities the estimate smears too."""
    rig = sticky_rig(106)
    data = measured_like("furuta", rig, excitation="sticky_sweep", seed=106, n_trajectories=6, duration=10.0)
    keys = ["spring:alpha", "constant_torque:alpha", "coulomb_friction:alpha", "stiction:alpha"]
    planted_j1 = layout_for("furuta").nominal()[layout_for("furuta").index("J1")]
    stops_out = _equation_error_coefficients(data, keys, stop_dwell=0.04)
    # whole rests only: the held-stop rule, on by default, turned off (what this test is about)
    whole_rests_only = _equation_error_coefficients(data, keys, held_stop=None)
    assert stops_out["spring:alpha"] == pytest.approx(rig[0].coefficient, rel=0.1)
    assert stops_out["J1"] == pytest.approx(planted_j1, rel=0.02)
    assert whole_rests_only["spring:alpha"] < 0.7 * rig[0].coefficient
    assert whole_rests_only["J1"] < 0.97 * planted_j1
    held_out = _equation_error_coefficients(data, keys)  # the default: held_stop=2
    assert 0.75 * rig[0].coefficient < held_out["spring:alpha"] < 0.9 * rig[0].coefficient
    assert held_out["J1"] == pytest.approx(planted_j1, rel=0.02)


def test_stop_dwell_is_off_by_default_and_checked():
    assert DiagnosisSettings().rests.stop_dwell is None
    with pytest.raises(ValueError, match="stop_dwell: expected a positive time in s or None, got -0.04"):
        DiagnosisSettings().replaced(stop_dwell=-0.04).resolved("furuta", DT)
    from furuta_gym.cli import build_parser

    args = build_parser().parse_args(["diagnose", "log.csv", "--system", "furuta", "--stop-dwell", "0.04"])
    assert args.stop_dwell == 0.04


def test_held_stop_is_on_by_default_can_be_turned_off_and_is_checked():
    assert DiagnosisSettings().rests.held_stop == 2.0
    assert DiagnosisSettings().replaced(held_stop=None).resolved("furuta", DT).rests.held_stop is None
    with pytest.raises(ValueError, match="held_stop: expected a number of counts >= 1 or None, got 0.5"):
        DiagnosisSettings().replaced(held_stop=0.5).resolved("furuta", DT)
    from furuta_gym.cli import build_parser
    from furuta_gym.cli.diagnose import UNSET

    parse = build_parser().parse_args
    base = ["diagnose", "log.csv", "--system", "furuta"]
    assert parse(base).held_stop is UNSET  # not given: DiagnosisSettings' default
    assert parse([*base, "--held-stop", "3"]).held_stop == 3.0
    for off in ("off", "OFF", "0", "none"):
        assert parse([*base, "--held-stop", off]).held_stop is None
    for bad in ("0.5", "-2", "two"):
        with pytest.raises(SystemExit):
            parse([*base, "--held-stop", bad])


def test_held_stop_off_on_the_cli_reaches_diagnose(monkeypatch, tmp_path):
    """``--held-stop off`` passes ``held_stop=None`` on to ``diagnose``; no flag passes nothing, so
    the default (2 counts) holds."""
    from furuta_gym.cli import build_parser, diagnose as cli

    seen = []

    class Stop(Exception):
        pass

    def fake_diagnose(*args, **kwargs):
        seen.append(kwargs)
        raise Stop

    monkeypatch.setattr(cli, "_load", lambda data, args: ([], []))  # (trajectories, reading notes)
    monkeypatch.setattr("furuta_gym.diagnose.diagnose", fake_diagnose)  # run() imports it when called
    for extra, expected in ((["--held-stop", "off"], None), ([], "absent"), (["--held-stop", "4"], 4.0)):
        args = build_parser().parse_args(["diagnose", str(tmp_path / "log.csv"), "--system", "furuta", *extra])
        with pytest.raises(Stop):
            cli.run(args)
        assert seen[-1].get("held_stop", "absent") == expected
    assert DiagnosisSettings().rests.held_stop == 2.0
