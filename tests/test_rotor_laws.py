"""Issue 64's two rotor laws, simulated, and told apart from the logs' rests without a fit.

A cable whose rest moves (``moving_rest_rig``: the play operator) leaves the rotor wherever large
excursions dragged it; a fixed cable held by friction far above its sliding level
(``breakaway_rig``) keeps every rest within ±F_s/k of one neutral.
"""

from __future__ import annotations

import numpy as np
import pytest

import furuta_gym
from furuta_gym.data import Trajectory
from furuta_gym.diagnose import breakaway_rig, measured_like, moving_rest_rig, rest_drift
from furuta_gym.effects import Effect
from furuta_gym.envs import MujocoBackend
from furuta_gym.signals import quantize_encoder

furuta_gym.enable_x64()
SEEDS = range(5)
RELEASES, SECONDS = 6, 5.0


def _hold(rig) -> float:
    """F_s/k: how far from its neutral the rig's friction can hold the rotor (rad)."""
    spring = next(e for e in rig if e.kind.in_potential or e.kind.has_memory)
    return sum(e.coefficient for e in rig if e.kind.is_dry_friction) / spring.coefficient


@pytest.fixture(scope="module")
def releases():
    """Five logs of releases per law, each six releases of 5 s (one rig per seed)."""
    out = {}
    for law, rig in (("moving", moving_rest_rig), ("breakaway", breakaway_rig)):
        out[law] = [
            (
                rig(s),
                measured_like(
                    "furuta", rig(s), excitation="rotor_releases", n_trajectories=RELEASES, duration=SECONDS, seed=s
                ),
            )
            for s in SEEDS
        ]
    return out


def test_the_rigs_are_drawn_in_issue_64s_ranges():
    for seed in range(20):
        cable, coulomb, stiction = moving_rest_rig(seed)
        assert cable.kind.has_memory and 1.5e-3 <= cable.coefficient <= 2.5e-3 and 0.1 <= cable.play <= 0.8
        assert 1e-4 <= coulomb.coefficient <= 3e-4
        assert stiction.coefficient == pytest.approx(0.5 * coulomb.coefficient)  # breakaway 1.5x
        spring, coulomb, stiction = breakaway_rig(seed)
        assert not spring.kind.has_memory and 1.5e-3 <= spring.coefficient <= 2.5e-3
        assert abs(spring.reference) <= 0.1 and 1e-4 <= coulomb.coefficient <= 3e-4
        assert 5.0 <= 1.0 + stiction.coefficient / coulomb.coefficient <= 10.0
        assert stiction.stribeck_velocity == 0.02


def test_a_hand_carrying_the_rotor_drags_the_cables_neutral_and_a_reset_forgets_it():
    plant = MujocoBackend("furuta", 10, [Effect("hysteretic_spring", "alpha", 2e-3, play=0.3)], timestep=2e-4)
    plant.reset(np.zeros(4))
    plant.move(np.array([1.0, 0.0, 0.0, 0.0]))  # the neutral dragged to 0.7 ...
    plant.move(np.array([0.8, 0.0, 0.0, 0.0]))  # ... and left there: the cable pulls back 0.1 rad
    plant.step(np.zeros(1))
    pulled = plant.state[2]
    plant.reset(np.array([0.8, 0.0, 0.0, 0.0]))  # the neutral back at 0, dragged to 0.5: 0.3 rad
    plant.step(np.zeros(1))
    assert pulled < 0 and plant.state[2] / pulled == pytest.approx(3.0, rel=0.02)


def test_releases_start_at_rest_carried_half_a_radian_to_two_from_the_last_rest(releases):
    for _, log in releases["moving"] + releases["breakaway"]:
        for before, tr in zip(log[:-1], log[1:]):
            step = abs(tr.q[0, 0] - before.q[-1, 0])
            assert 0.5 - 0.01 <= step <= 2.0 + 0.01 and abs(tr.q[0, 0]) <= 2.5
            assert np.all(tr.u == 0.0) and abs(tr.q[0, 1]) <= 0.03


def test_a_moving_rest_follows_the_release_and_a_fixed_neutral_holds_every_rest_near_it(releases):
    for rig, log in releases["moving"]:
        cable = rig[0]
        for tr in log:  # the neutral was dragged to within the play of the release point
            assert abs(tr.q[-1, 0] - tr.q[0, 0]) <= cable.play + _hold(rig)
        rests = [tr.q[-1, 0] for tr in log]
        assert np.ptp(rests) > 2 * _hold(rig)  # no fixed neutral could hold them all
    for rig, log in releases["breakaway"]:
        rests = np.array([tr.q[-1, 0] for tr in log])
        assert np.all(np.abs(rests - rig[0].reference) <= _hold(rig))


def _hand_log(path, dt=0.002) -> list[Trajectory]:
    """One trajectory through the (angle, seconds) stops of ``path``: each held for its seconds,
    joined by 0.1 s ramps; encoder-quantised, u = 0."""
    q = [np.full(int(round(s / dt)), a) for a, s in path[:1]]
    for (a0, _), (a1, s) in zip(path[:-1], path[1:]):
        q += [np.linspace(a0, a1, 50, endpoint=False), np.full(int(round(s / dt)), a1)]
    alpha = quantize_encoder(np.stack([np.concatenate(q), np.zeros(sum(map(len, q)))], 1))
    t = np.arange(len(alpha)) * dt
    return [Trajectory(t=t, q=alpha, u=np.zeros((len(t), 1)), name="hand")]


def test_rest_drift_reads_each_rest_and_the_share_of_the_excursion_before_it_that_it_followed():
    # rest at 0, out to +1 (0.1 s), rest at +0.8; out to -0.5, rest at -0.3; out to +1.4, rest +1.1
    path = [
        (0.0, 1.0),
        (1.0, 0.1),
        (0.8, 1.0),
        (-0.5, 0.1),
        (-0.3, 1.0),
        (1.4, 0.1),
        (1.1, 1.0),
        (-0.2, 0.1),
        (0.0, 1.0),
    ]
    drift = rest_drift(_hand_log(path))
    assert [round(r.position, 2) for r in drift.rests] == [0.0, 0.8, -0.3, 1.1, 0.0]
    assert [round(r.excursion, 2) for r in drift.rests[1:]] == [1.0, -0.5, 1.4, -0.2]
    # followed: 0.8 of 1; 1.1 of 1.3 down; 1.4 of 1.7 up; 1.1 of 1.3 down
    assert drift.follows == pytest.approx([0.8, 1.1 / 1.3, 1.4 / 1.7, 1.1 / 1.3], abs=2e-3)
    assert drift.sides == (1, -1, 1, -1) and drift.spread == pytest.approx(1.4, abs=4e-3)
    assert drift.verdict == "moving rest"
    # the same excursions, every rest back by one neutral: a fixed cable held by friction
    back = [
        (0.0, 1.0),
        (1.0, 0.1),
        (-0.1, 1.0),
        (-0.9, 0.1),
        (0.05, 1.0),
        (1.4, 0.1),
        (-0.05, 1.0),
        (-1.2, 0.1),
        (0.1, 1.0),
    ]
    drift = rest_drift(_hand_log(back))
    assert max(drift.follows) < 0 and drift.verdict == "fixed neutral held by friction"
    # a rest the joint never came back from says nothing; a log without rests says nothing
    stuck = [(0.0, 1.0), (1.0, 1.0), (-0.5, 1.0), (1.2, 1.0), (-0.8, 1.0)]
    assert rest_drift(_hand_log(stuck)).follows == () and rest_drift(_hand_log(stuck)).verdict == "cannot tell"
    assert rest_drift(_hand_log([(0.0, 0.2), (1.0, 0.2)])).rests == ()
