"""Measured logs as training and test data (furuta_gym.measured, `train` / `evaluate` on logs)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import furuta_gym

furuta_gym.enable_x64()

from furuta_gym.data import DataError, Trajectory, load_trajectories  # noqa: E402
from furuta_gym.datasets import QUBE_CLOSED_LOOP_MAPPING, load_qube_closed_loop, qube_closed_loop_files  # noqa: E402
from furuta_gym.measured import (  # noqa: E402
    MIN_MOTION,
    check_log,
    prediction_windows,
    prepare_log,
    split_elementary,
    window_errors,
)
from furuta_gym.signals import derivative_filter, zero_phase_velocity  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run1():
    (tr,) = load_qube_closed_loop([1], skip_seconds=0.0)
    return tr


def test_a_log_becomes_the_papers_elementary_trajectories(run1):
    pieces = prepare_log(run1, "run1", skip=0.5, split=1.0)
    # 500 Hz: 1 s = 500 samples, back to back, the remainder after the last whole second dropped
    kept = run1.t >= run1.t[0] + 0.5 - 1e-9
    assert len(pieces) == int(kept.sum()) // 500 == 19
    assert all(len(p) == 500 for p in pieces)
    assert pieces[0].t[0] == pytest.approx(run1.t[0] + 0.5)
    assert pieces[1].t[0] - pieces[0].t[-1] == pytest.approx(run1.dt)
    assert [p.name for p in pieces[:2]] == ["run01:0", "run01:1"]
    # velocities are estimated on the whole log, then cut: the same numbers as filtering the log
    full = zero_phase_velocity(run1.q, run1.dt, cutoff_hz=25.0)
    np.testing.assert_allclose(pieces[3].qd, full[kept][1500:2000], rtol=0, atol=1e-12)
    causal = prepare_log(run1, "run1", velocity="derivative_filter", skip=0.5, split=1.0)
    np.testing.assert_allclose(causal[0].qd, derivative_filter(run1.q, run1.dt)[kept][:500], atol=1e-12)
    assert split_elementary(pieces[0], None)[0] is pieces[0]


def test_a_log_that_cannot_serve_is_refused_naming_it(run1):
    with pytest.raises(DataError, match=r"logs/a\.csv: trajectory 'run01' is too short: .*expected at least 30 s"):
        prepare_log(run1, "logs/a.csv", split=30.0)
    still = Trajectory(run1.t, np.zeros_like(run1.q) + [0.1, math.pi], run1.u, name="7")
    still.q[::2, 1] += 0.5 * MIN_MOTION  # encoder flicker below five counts
    with pytest.raises(DataError, match=r"logs/b\.csv: trajectory '7' has no excitation"):
        check_log(still, "logs/b.csv")
    check_log(run1, "run1", min_seconds=19.0)  # a real run passes


def test_windows_score_a_model_on_its_own_held_input_data_as_exact():
    from furuta_gym.models import Furuta
    from furuta_gym.simulate import rollout_zoh

    model, dt = Furuta(), 0.002
    rng = np.random.default_rng(0)
    us = np.repeat(rng.uniform(-2, 2, (50, 1)), 10, axis=0)  # a held voltage, steps every 20 ms
    xs = np.asarray(rollout_zoh(model, np.array([0.0, 0.3, 0.0, 0.0]), us, dt, 4))
    tr = Trajectory(np.arange(len(xs)) * dt, xs[:, :2], np.vstack([us, us[-1:]]), xs[:, 2:], name="sim")
    x0, u_win, x_win = prediction_windows([tr], 0.1)
    assert x0.shape == (10, 4) and u_win.shape == (10, 50, 1) and x_win.shape == (10, 51, 4)
    res = window_errors(model, [tr], 0.1)
    assert res["n_windows"] == 10 and res["n_diverged"] == 0
    assert max(res["rmse"].values()) < 1e-12  # the model reproduces its own data: the windows line up
    from furuta_gym.models import FurutaParameters

    other = window_errors(Furuta(FurutaParameters(mp=0.03)), [tr], 0.1)
    assert min(other["log10_rmse"].values()) > -6  # a wrong model is seen


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A DeLaN trained by the CLI on two real runs, a few L_Iτ epochs (seconds, not minutes)."""
    from furuta_gym.cli import main

    out = tmp_path_factory.mktemp("real") / "dln"
    code = main(
        [
            "train",
            "--system",
            "furuta",
            "--model",
            "dln",
            "--loss",
            "itau",
            "--data",
            "qube:1,2",
            "--out",
            str(out),
            "--epochs",
            "5",
            "--no-progress",
        ]
    )
    assert code == 0
    return out


def test_cli_trains_on_real_runs(trained, capsys):
    from furuta_gym.training.checkpoint import load_model, read_header

    load_model(trained / "model.eqx", expected_system="furuta")
    assert read_header(trained / "model.eqx")["meta"]["epoch"] == 5
    data = json.loads((trained / "data.json").read_text())
    # 2 runs of 19.5 s, 0.5 s skipped: 19 elementary trajectories of 1 s each
    assert data["n_trajectories"] == 38 and data["data"] == ["qube:1,2"]
    assert "velocities estimated (zero_phase)" in data["notes"][0]


def test_cli_train_reads_a_plain_log_like_the_shipped_runs(tmp_path, capsys):
    """A raw file with its own column names, signs and offsets gives the same training data."""
    import gzip
    import shutil

    from furuta_gym.cli import main

    raw = tmp_path / "run02.csv"
    with gzip.open(qube_closed_loop_files([2])[0], "rb") as src, raw.open("wb") as dst:
        shutil.copyfileobj(src, dst)
    m = QUBE_CLOSED_LOOP_MAPPING
    opts = [
        "--column-map",
        ",".join(f"{k}={v}" for k, v in m["column_map"].items()),
        "--sign",
        "beta=-1",
        "--offset",
        f"beta={math.pi!r}",
    ]
    base = ["train", "--system", "furuta", "--model", "dln", "--loss", "itau", "--epochs", "1", "--no-progress"]
    assert main(base + ["--data", str(raw), "--out", str(tmp_path / "a"), "--skip", "0.5", *opts]) == 0
    assert main(base + ["--data", "qube:2", "--out", str(tmp_path / "b")]) == 0
    hashes = [json.loads((tmp_path / d / "history.json").read_text())["meta"]["data_hash"] for d in "ab"]
    assert hashes[0] == hashes[1]
    # too short for the asked split, and a log where nothing moves: one error naming the file
    assert main(base + ["--data", str(raw), "--out", str(tmp_path / "c"), "--split", "30", *opts]) == 2
    err = capsys.readouterr().err
    assert "run02.csv" in err and "too short" in err and "--split" in err
    (tr,) = load_trajectories(raw, "furuta", column_map=m["column_map"], signs=m["signs"], offsets=m["offsets"])
    flat = tmp_path / "flat.csv"
    from furuta_gym.data import save_trajectories

    save_trajectories(flat, [Trajectory(tr.t, np.zeros_like(tr.q), tr.u)], "furuta")
    assert main(base + ["--data", str(flat), "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert "flat.csv" in err and "no excitation" in err
    assert not (tmp_path / "d" / "model.eqx").exists()


def test_cli_evaluates_on_real_runs_in_short_windows(trained, tmp_path, capsys):
    from furuta_gym.cli import main

    js = tmp_path / "m.json"
    assert main(["evaluate", str(trained / "model.eqx"), "--data", "qube:3", "--window", "0.1", "--json", str(js)]) == 0
    (m,) = json.loads(js.read_text())["results"].values()
    # run 3: 19 s after the skipped 0.5 s, back-to-back windows of 50 periods
    assert m["n_windows"] == 194 and m["n_diverged"] == 0
    for k in ("alpha", "beta", "alpha_dot", "beta_dot"):
        assert math.isfinite(m[k]) and m[k] == pytest.approx(math.log10(m["rmse"][k]))
    assert "inertial" not in m and "no ground truth" in m["note"]  # no truth on a real rig
    assert "qube:3: alpha=" in capsys.readouterr().out


def test_diagnose_reads_logs_through_the_shared_helper():
    """`diagnose`'s reading is the one train/evaluate use (moved, not copied)."""
    from furuta_gym.cli import _logs, diagnose

    assert diagnose._load is _logs.load_logs and diagnose._qube_runs is _logs.qube_runs
    assert _logs.qube_runs("qube:2,7,9-11") == [2, 7, 9, 10, 11] and _logs.qube_runs("qube") is None


@pytest.mark.parametrize("folder,block", [("real_models", "real-models"), ("real_models_1to10", "real-models-1to10")])
def test_real_models_docs_table_matches_its_results(folder, block):
    if not (ROOT / "results" / folder / "summary.json").is_file():
        pytest.skip(f"results/{folder} not generated")
    script = ROOT / "studies" / "real_models_table.py"
    args = ["--check", "--results", str(ROOT / "results" / folder), "--block", block]
    proc = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
