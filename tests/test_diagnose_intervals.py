"""Intervals of a diagnosis' fitted parameters and effect coefficients (issue 45, item 3).

* The interval function against a linear-Gaussian problem whose covariance is known exactly
  (errors correlated within clusters, as the residuals of one prediction window are): the
  cluster-robust covariance recovers it and its 95 % intervals cover; the iid s²(JᵀJ)⁻¹ does not.
* A near-null direction: unbounded, with a note naming the combination.
* mujoco.sysid's eigen handling and our own copy of it agree (mujoco.sysid is optional).
* On simulated logs the truth lies inside the 95 % interval: a few logs here; ≥ 20 logs per
  scenario in the slow test, as ``studies/diagnose_intervals.py`` records them.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from furuta_gym.diagnose import _intervals, diagnose
from furuta_gym.diagnose._intervals import (
    Interval,
    cluster_intervals,
    own_calculate_intervals,
    sysid_calculate_intervals,
)
from furuta_gym.envs import Plant
from furuta_gym.rigs import measured_like

ROOT = Path(__file__).resolve().parents[1]
_CACHE: dict = {}


def _experiment():
    """studies/diagnose_intervals.py as a module: the scenarios and truths are defined once."""
    spec = importlib.util.spec_from_file_location("diagnose_intervals", ROOT / "studies" / "diagnose_intervals.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _clustered_problem(rng, G=120, m=8, P=3, sigma_u=1.0, sigma_e=0.5):
    """X with a per-cluster component and errors u_g + ε: the exact covariance of OLS is
    (XᵀX)⁻¹ Xᵀ Ω X (XᵀX)⁻¹ with Ω block-diagonal σu²·11ᵀ + σe²·I."""
    groups = np.repeat(np.arange(G), m)
    X = rng.normal(size=(G, P))[groups] + 0.3 * rng.normal(size=(G * m, P))
    bread = np.linalg.inv(X.T @ X)
    meat = sum(
        X[groups == g].T @ (sigma_u**2 * np.ones((m, m)) + sigma_e**2 * np.eye(m)) @ X[groups == g] for g in range(G)
    )
    return X, groups, bread @ meat @ bread


def test_cluster_covariance_recovers_the_known_covariance_and_covers():
    rng = np.random.default_rng(0)
    X, groups, exact = _clustered_problem(rng)
    beta = np.array([1.0, -2.0, 0.5])
    G = groups.max() + 1
    covered, iid_covered, var = [], [], []
    for _ in range(300):
        y = X @ beta + rng.normal(size=G)[groups] + 0.5 * rng.normal(size=X.shape[0])
        b = np.linalg.lstsq(X, y, rcond=None)[0]
        iv = cluster_intervals(X, y - X @ b, groups, b)
        covered.append((iv.lower <= beta) & (beta <= iv.upper))
        iid_covered.append(np.abs(b - beta) <= iv.iid_half_width)
        var.append(np.diag(iv.covariance))
    assert np.mean(var, axis=0) == pytest.approx(np.diag(exact), rel=0.1)
    assert np.all(np.abs(np.mean(covered, axis=0) - 0.95) < 0.04), np.mean(covered, axis=0)
    assert np.all(np.mean(iid_covered, axis=0) < 0.7), np.mean(iid_covered, axis=0)  # far too narrow


def test_independent_errors_give_the_iid_intervals():
    """Without correlation the sandwich and s²(JᵀJ)⁻¹ estimate the same covariance."""
    rng = np.random.default_rng(1)
    X = rng.normal(size=(4000, 3)) * [1.0, 1e-3, 1e3]  # units far apart: columns are normalised
    b = np.array([1.0, 2.0, 3.0])
    y = X @ b + rng.normal(size=4000)
    est = np.linalg.lstsq(X, y, rcond=None)[0]
    iv = cluster_intervals(X, y - X @ est, np.arange(4000) // 4, est)
    assert iv.half_width == pytest.approx(iv.iid_half_width, rel=0.1)


def test_near_null_direction_is_unbounded_and_named():
    rng = np.random.default_rng(2)
    J = rng.normal(size=(300, 4))
    J[:, 2] = J[:, 0] + 2.0 * J[:, 1] + 1e-9 * rng.normal(size=300)  # not exactly, but below the resolution
    r = rng.normal(size=300)
    iv = cluster_intervals(J, r, np.arange(300) // 10, np.zeros(4))
    assert list(iv.unbounded) == [True, True, True, False]
    assert np.isfinite(iv.half_width[3])
    notes = _intervals._null_note(iv, ["a", "b", "c", "d"], "output-error")
    assert len(notes) == 1 and notes[0].startswith("interval unbounded for a, b, c:")
    assert Interval(-np.inf, np.inf, "output_error").to_json() == "unbounded"


def _random_problems():
    rng = np.random.default_rng(3)
    for k in range(12):
        J = rng.normal(size=(150, 5)) * rng.uniform(0.01, 100.0, 5)
        if k % 3 == 1:
            J[:, 4] = J[:, 0] - J[:, 2]
        if k % 3 == 2:
            J[:, 1] = 0.0
        yield [rng.normal(size=100), rng.normal(size=50)], J


def test_mujoco_sysid_and_our_copy_agree():
    calculate = _intervals._mujoco_calculate_intervals()
    if calculate is None:
        pytest.skip("mujoco.sysid unavailable (older MuJoCo or without mujoco[sysid]): only our copy runs")
    for residuals, J in _random_problems():
        for thresh in (1e-15, 1e-10):
            s_mj, h_mj = calculate(residuals, J, 0.05, thresh)
            s_own, h_own = own_calculate_intervals(residuals, J, 0.05, thresh)
            assert np.array_equal(np.isinf(h_mj), np.isinf(h_own))
            finite = np.isfinite(h_mj)
            np.testing.assert_allclose(h_own[finite], h_mj[finite], rtol=1e-9)
            np.testing.assert_allclose(s_own, s_mj, rtol=1e-8, atol=1e-12 * np.abs(s_mj).max())


def test_without_mujoco_sysid_the_intervals_are_the_same(monkeypatch):
    """The fallback path (no mujoco.sysid) gives the diagnosis the same intervals."""
    rng = np.random.default_rng(4)
    with_sysid = []
    for residuals, J in _random_problems():
        r = np.concatenate(residuals)
        with_sysid.append(cluster_intervals(J, r, np.arange(r.size) // 5, np.zeros(J.shape[1])))
    monkeypatch.setattr(_intervals, "_mujoco_calculate_intervals", lambda: None)
    for (residuals, J), a in zip(_random_problems(), with_sysid, strict=True):
        r = np.concatenate(residuals)
        b = cluster_intervals(J, r, np.arange(r.size) // 5, np.zeros(J.shape[1]))
        assert b.backend == "own"
        np.testing.assert_array_equal(a.unbounded, b.unbounded)
        np.testing.assert_allclose(a.half_width[~a.unbounded], b.half_width[~b.unbounded], rtol=1e-12)
        np.testing.assert_allclose(a.iid_half_width[~a.unbounded], b.iid_half_width[~b.unbounded], rtol=1e-9)
    assert sysid_calculate_intervals([rng.normal(size=20)], rng.normal(size=(20, 2)))[2] == "own"


# ----------------------------------------------------------------------------- on a diagnosis


def _nmsd(seed=0):
    if seed not in _CACHE:
        sc = _experiment().SCENARIOS["nmsd_force_and_spring"]
        _CACHE[seed] = diagnose(measured_like("nmsd", sc["effects"], seed=seed, **sc["log"]), "nmsd")
    return _CACHE[seed]


def test_json_and_table_carry_the_intervals(tmp_path):
    res = _nmsd()
    doc = res.to_json()
    assert doc["schema_version"] == 2
    assert set(doc["parameter_intervals"]) == set(doc["parameters_after"])
    assert doc["parameter_intervals"]["gain"] is None  # the fixed scale anchor is not fitted
    force = next(e for e in doc["effects"] if e["name"] == "constant_torque")
    lo, hi = force["interval"]
    assert lo < force["coefficient"] < hi
    assert all(e["interval"] is None for e in doc["effects"] if not e["significant"])
    assert doc["interval_method"]["level"] == 0.95 and doc["interval_method"]["n_clusters"] >= 10
    table = res.table()
    assert "± 95 %" in table and f"± {0.5 * (hi - lo):.2g}" in table
    # the JSON still reads as a plant (the README's command writes it)
    path = tmp_path / "diag.json"
    path.write_text(json.dumps(doc))
    assert Plant.load(path).lumped == pytest.approx(res.parameters_after)


def test_unbounded_intervals_are_reported_as_such():
    res = _nmsd()
    res = dataclasses.replace(res, intervals=dict(res.intervals, k2=Interval(-np.inf, np.inf, "equation_error")))
    assert res.to_json()["parameter_intervals"]["k2"] == "unbounded"
    assert "± inf" in next(line for line in res.table().splitlines() if line.strip().startswith("k2"))


def test_truth_inside_the_interval_on_a_few_logs():
    """CI's share of the slow coverage test: three N-MSD logs (the nominal values are not the truth
    there: k1 absorbs a spring) and one Furuta log with a cable spring."""
    exp = _experiment()
    rows = [r for seed in (0, 1, 2) for r in exp.run_log("nmsd_force_and_spring", seed)]
    rows += exp.run_log("furuta_cable_spring", 0)
    assert all(r["interval"] is not None for r in rows if r["key"] in ("constant_torque:p", "spring:alpha"))
    assert np.mean([r["covered"] for r in rows]) >= 0.8, [(r["key"], r["covered"]) for r in rows]


def test_output_error_intervals_on_a_log_whose_output_error_fit_is_reported():
    """The output-error path (windows as clusters), on an N-MSD log where the diagnosis keeps the
    output-error refinement: the truth lies inside, and the correlation of the position errors
    within a window makes the intervals wider than mujoco.sysid's iid ones."""
    exp = _experiment()
    res = _nmsd(7)
    assert res.interval_method["source"] == "output_error", res.notes
    assert res.interval_method["clusters"] == "open-loop windows"
    assert res.interval_method["n_clusters"] == res.settings.output_error.oe_max_windows
    base, effects = exp.truths(exp.SCENARIOS["nmsd_force_and_spring"])
    found = {f"{e.name}:{e.joint}": e.interval for e in res.significant}
    out = {**{k: iv for k, iv in res.intervals.items() if iv is not None}, **found}
    truth = dict(base, **effects)
    assert set(out) == {"m", "k1", "k2", "b1", "b2", "constant_torque:p"}
    assert all(iv.contains(truth[k]) for k, iv in out.items()), {k: (iv.lower, iv.upper) for k, iv in out.items()}
    assert min((iv.upper - iv.lower) / (2 * iv.iid_half_width) for iv in out.values()) > 1.5


@pytest.mark.slow
def test_truth_inside_the_interval_in_90_percent_of_logs():
    """The issue's "done when": ≥ 20 simulated logs per scenario, the truth inside the 95 %
    interval in ≥ 90 % of them, for every added effect and every parameter given an interval."""
    exp = _experiment()
    for name in exp.SCENARIOS:
        rows = [r for seed in range(exp.LOGS) for r in exp.run_log(name, seed)]
        _, effects = exp.truths(exp.SCENARIOS[name])
        summary = exp.summary(rows)
        for key, s in summary.items():
            # every added effect on every log; a base parameter only where its fitted value is
            # reported (a kept nominal value has no interval), so on fewer logs: those pooled
            assert s["logs"] >= 20 or key not in effects, (name, key, s)
            assert s["coverage"] >= 0.9 or s["logs"] < 20, (name, key, s)
        assert np.mean([r["covered"] for r in rows]) >= 0.9, (name, summary)
