"""The diagnosis on realistic logs (issue 24): QUBE-like experiments in simulation and the real
QUBE-Servo runs shipped with the package.

Simulated (MuJoCo plant variants, encoder-quantised angles, velocities estimated):
* open-loop sine sweeps of a rotor held by dry friction against a cable spring — the spring only
  pays once the friction is modelled: both must be found, coefficients within ±35 %, held-out
  error ≥ 1.4× lower; the same with a cable neutral off zero and stiction above the Coulomb level;
* closed-loop balancing (PD + references + ±0.5 V feed-forward, like the MIT logs) with Coulomb
  friction, a pendulum centre-of-mass offset and an actuator lag;
* no-effect logs of both experiments: nothing reported.
Real: the vendored MIT runs, fitted on some, judged on runs never fitted. The full grid over
seeds is ``studies/diagnose_simulated.py`` (results in results/diagnose_sim, docs table
generated from them); ``-m slow`` runs more seeds here.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from furuta_gym.cli import main
from furuta_gym.diagnose import diagnose
from furuta_gym.effects import Effect
from furuta_gym.rigs import measured_like, sticky_rig

ROOT = Path(__file__).resolve().parents[1]
LOG = dict(n_trajectories=6, duration=10.0)
CLOSED_LOOP = dict(window=0.1, oe_max_windows=64)
SPRING_FRICTION = [Effect("spring", "alpha", 1.5e-3), Effect("coulomb_friction", "alpha", 8e-4)]
RIG = [Effect("coulomb_friction", "alpha", 3e-4), Effect("com_offset", "beta", 2e-3), Effect("actuator_lag", "u", 5e-3)]


def _coefficient(res, name, joint):
    for e in res.significant:
        if (e.name, e.joint) == (name, joint):
            return e.coefficient
        m = re.search(rf"{name} ([0-9.e-]+) s fits as well", e.note) if joint == "u" else None
        if m and e.joint == "u":
            return float(m.group(1))
    raise AssertionError(f"{name}:{joint} not found\n{res.table()}")


# the pendulum's centre-of-mass offset acts on a closed-loop log only as a small steady torque the
# controller fights; its estimate scatters more than the others' (the table in docs/diagnose.md,
# generated from results/diagnose_sim, shows by how much)
TOLERANCE = {"com_offset": 0.5}


def _check_planted(res, planted, min_ratio=1.4):
    assert len(res.significant) == len(planted), res.table()
    for p in planted:
        rel = TOLERANCE.get(p.name, 0.35)
        assert _coefficient(res, p.name, p.joint) == pytest.approx(p.coefficient, rel=rel), res.table()
    assert res.error_before.trajectory_rmse >= min_ratio * res.error_after.trajectory_rmse, res.table()


def test_spring_held_by_dry_friction_is_found_with_the_friction():
    res = diagnose(measured_like("furuta", SPRING_FRICTION, excitation="sine_sweep", seed=100, **LOG), "furuta")
    _check_planted(res, SPRING_FRICTION)
    assert {e.status for e in res.effects[:2]} == {"selected"}


CABLE_STICTION = [
    Effect("spring", "alpha", 1.5e-3, reference=0.1),
    Effect("coulomb_friction", "alpha", 6e-4),
    Effect("stiction", "alpha", 4e-4),
]


def _check_cable_with_stiction(res):
    """A cable whose neutral is off zero (a spring plus a constant torque: rest = τ0/k) and dry
    friction with a breakaway above Coulomb: all four found, nothing else, every coefficient
    within ±35 %, the rest position too (its rate over seeds is in docs/diagnose.md, generated
    from results/diagnose_sim)."""
    found = {(e.name, e.joint): e.coefficient for e in res.significant}
    assert set(found) == {
        ("spring", "alpha"),
        ("constant_torque", "alpha"),
        ("coulomb_friction", "alpha"),
        ("stiction", "alpha"),
    }, res.table()
    rest = found[("constant_torque", "alpha")] / found[("spring", "alpha")]
    assert rest == pytest.approx(0.1, rel=0.35), res.table()
    for p in CABLE_STICTION:
        assert found[(p.name, p.joint)] == pytest.approx(p.coefficient, rel=0.35), res.table()
    assert res.error_before.trajectory_rmse >= 1.4 * res.error_after.trajectory_rmse, res.table()


def test_cable_with_stiction_is_found_with_its_stiction():
    res = diagnose(measured_like("furuta", CABLE_STICTION, excitation="sine_sweep", seed=100, **LOG), "furuta")
    _check_cable_with_stiction(res)


def _rotor_repeat_share(data) -> float:
    return float(np.mean(np.concatenate([np.diff(tr.q[:, 0]) == 0 for tr in data])))


def _check_sticky_rig(res, rig):
    """Issue 43's sticky sweeps: the spring and the rotor's Coulomb friction within ±35 %, the
    breakaway (Coulomb + stiction) within ±50 %, the held-out error ≥ 1.4× lower (rates over
    seeds: docs/diagnose.md, generated from results/diagnose_sim)."""
    found = {e.name: e.coefficient for e in res.significant if e.joint == "alpha"}
    planted = {e.name: e.coefficient for e in rig}
    assert found.get("spring") == pytest.approx(planted["spring"], rel=0.35), res.table()
    assert found.get("coulomb_friction") == pytest.approx(planted["coulomb_friction"], rel=0.35), res.table()
    breakaway = found["coulomb_friction"] + found.get("stiction", 0.0)
    assert breakaway == pytest.approx(planted["coulomb_friction"] + planted["stiction"], rel=0.5), res.table()
    assert res.error_before.trajectory_rmse >= 1.4 * res.error_after.trajectory_rmse, res.table()


def test_sticky_sweep_rotor_mostly_repeats_its_count_and_its_rig_is_found():
    rig = sticky_rig(100)
    data = measured_like("furuta", rig, excitation="sticky_sweep", seed=100, **LOG)
    assert _rotor_repeat_share(data) >= 0.6
    _check_sticky_rig(diagnose(data, "furuta"), rig)


def test_a_spring_that_predicts_worse_without_its_stiction_is_found_with_it():
    """Seed 105 of the sticky grid with stops left out of the equation error (``stop_dwell``):
    the search finds the spring before the friction; refitted, it predicts worse until the
    stiction holds the rotor off the cable's neutral, and the stiction is tested only after the
    refits. Tried again with the stiction fitted free, both are found."""
    rig = sticky_rig(105)
    data = measured_like("furuta", rig, excitation="sticky_sweep", seed=105, **LOG)
    res = diagnose(data, "furuta", stop_dwell=0.04)
    _check_sticky_rig(res, rig)
    assert any("predicts worse without it" in e.note for e in res.significant if e.name == "stiction"), res.table()


@pytest.mark.parametrize("excitation", ["sine_sweep", "sticky_sweep", "closed_loop_prbs"])
def test_no_effect_logs_report_nothing(excitation):
    kw = CLOSED_LOOP if excitation == "closed_loop_prbs" else {}
    res = diagnose(measured_like("furuta", [], excitation=excitation, seed=100, **LOG), "furuta", **kw)
    assert res.found == [], res.table()
    assert res.error_after.trajectory_rmse == res.error_before.trajectory_rmse


@pytest.mark.parametrize("excitation", ["sine_sweep", "closed_loop_prbs"])
def test_measured_like_logs_encoder_counts_unless_told_exact_angles(excitation):
    count = 2 * np.pi / 2048
    short = dict(n_trajectories=1, duration=0.4, seed=3, excitation=excitation)
    counts = measured_like("furuta", [], **short)[0].q / count
    exact = measured_like("furuta", [], quantize=False, **short)[0].q
    assert np.abs(counts - np.round(counts)).max() < 1e-9
    off_grid = np.abs(exact / count - np.round(exact / count)) > 1e-3
    assert off_grid.mean() > 0.9
    if excitation == "sine_sweep":  # open loop: the same motion, only the sensor differs
        assert np.abs(counts * count - exact).max() <= count / 2 + 1e-12


def test_closed_loop_rig_effects_are_found():
    res = diagnose(
        measured_like("furuta", RIG, excitation="closed_loop_prbs", seed=100, **LOG), "furuta", **CLOSED_LOOP
    )
    _check_planted(res, RIG)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(101, 106))
@pytest.mark.parametrize("case", ["spring_friction", "rig", "cable_stiction"])
def test_realistic_cases_over_seeds(case, seed):
    effects, excitation, kw = {
        "spring_friction": (SPRING_FRICTION, "sine_sweep", {}),
        "cable_stiction": (CABLE_STICTION, "sine_sweep", {}),
        "rig": (RIG, "closed_loop_prbs", CLOSED_LOOP),
    }[case]
    res = diagnose(measured_like("furuta", effects, excitation=excitation, seed=seed, **LOG), "furuta", **kw)
    if case == "cable_stiction":
        _check_cable_with_stiction(res)
    else:
        _check_planted(res, effects)


def test_real_runs_fit_on_some_judged_on_others_via_cli(tmp_path, capsys):
    out = tmp_path / "qube.json"
    code = main(
        [
            "diagnose",
            "qube:1-3",
            "--test",
            "qube:4,5",
            "--system",
            "furuta",
            "--skip",
            "0.5",
            "--window",
            "0.1",
            "--oe-windows",
            "64",
            "--json",
            str(out),
        ]
    )
    assert code == 0
    assert "test-log errors" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["test_error_before"]["n_windows"] > 300  # two unseen runs of 19.5 s in 0.1 s windows
    # the rotor's dry friction is the consistent finding on these logs (docs/diagnose.md)
    found = {(e["name"], e["joint"]) for e in doc["effects"] if e["significant"]}
    assert ("coulomb_friction", "alpha") in found
    assert doc["test_error_after"]["trajectory_rmse"] < doc["test_error_before"]["trajectory_rmse"]


def test_qube_shorthand_rejects_bad_runs_and_other_systems():
    assert main(["diagnose", "qube:0-3", "--system", "furuta"]) == 2
    assert main(["diagnose", "qube:1-x", "--system", "furuta"]) == 2
    assert main(["diagnose", "qube:1", "--system", "nmsd"]) == 2


def test_published_diagnosis_numbers_match_their_result_files():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "diagnose_tables.py"), "--check"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
