"""Issue 64's two rotor laws, simulated, and told apart from the logs' rests without a fit.

A cable whose rest moves (``moving_rest_rig``: the play operator) leaves the rotor wherever large
excursions dragged it; a fixed cable held by friction far above its sliding level
(``breakaway_rig``) keeps every rest within ±F_s/k of one neutral.
"""

from __future__ import annotations

import numpy as np
import pytest

import furuta_gym
from furuta_gym.diagnose import breakaway_rig, measured_like, moving_rest_rig
from furuta_gym.effects import Effect
from furuta_gym.envs import MujocoBackend

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
