"""The vendored real QUBE-Servo logs (furuta_gym.datasets) and the .csv.gz reader behind them.

Everything read here ships inside the package (or is written to tmp_path): nothing outside the repo.
"""

import gzip
import math

import numpy as np
import pytest

from furuta_gym.data import DataError, load_trajectories, save_trajectories
from furuta_gym.datasets import (
    QUBE_CLOSED_LOOP_MAPPING,
    QUBE_CLOSED_LOOP_RUNS,
    load_qube_closed_loop,
    qube_closed_loop_files,
)

COUNT = 2 * math.pi / 2048  # one encoder count, rad


@pytest.fixture(scope="module")
def runs():
    return load_qube_closed_loop()


def test_fifteen_files_ship_and_load(runs):
    files = qube_closed_loop_files()
    assert QUBE_CLOSED_LOOP_RUNS == 15
    assert [p.name for p in files] == [f"run{k:02d}.csv.gz" for k in range(1, 16)]
    assert all(p.is_file() for p in files)
    assert [tr.name for tr in runs] == [f"run{k:02d}" for k in range(1, 16)]
    for tr in runs:
        assert tr.q.shape == (len(tr), 2) and tr.u.shape == (len(tr), 1) and tr.qd is None


def test_runs_are_500_hz_and_about_19_5_s_after_the_skip(runs):
    for tr in runs:
        steps = np.diff(tr.t)
        np.testing.assert_allclose(steps, 0.002, atol=1e-9)
        assert tr.t[0] == pytest.approx(0.5, abs=1e-9)  # time stamps kept as in the file
        assert tr.t[-1] - tr.t[0] == pytest.approx(19.5, abs=0.01)
        assert len(tr) == 9750


def test_skip_seconds_zero_keeps_the_whole_run():
    (tr,) = load_qube_closed_loop([4], skip_seconds=0.0)
    assert len(tr) == 10000 and tr.t[0] == 0.0


def test_angles_are_encoder_quantised(runs):
    for tr in runs:
        arm = tr.q[:, 0]
        pend_file = math.pi - tr.q[:, 1]  # undo the mapping: the file's alpha, 0 upright
        for x in (arm, pend_file):
            counts = x / COUNT
            assert np.max(np.abs(counts - np.round(counts))) < 1e-6, tr.name


def test_pendulum_stays_upright_and_voltage_within_limits(runs):
    for tr in runs:
        assert np.max(np.abs(tr.q[:, 1] - math.pi)) < 1.0, tr.name
        assert np.max(np.abs(tr.u)) <= 10.0 + 1e-9, tr.name
        assert np.all(np.isfinite(tr.q)) and np.all(np.isfinite(tr.u))


def test_mapping_is_the_documented_conversion():
    assert QUBE_CLOSED_LOOP_MAPPING == {
        "column_map": {"alpha": "theta", "beta": "alpha", "u": "plant_input"},
        "signs": {"beta": -1.0},
        "offsets": {"beta": math.pi},
    }


def test_a_subset_of_runs_loads_by_number():
    trs = load_qube_closed_loop([1, 3])
    assert [tr.name for tr in trs] == ["run01", "run03"]


@pytest.mark.parametrize("bad", [0, 16, -1])
def test_a_bad_run_number_names_the_valid_range(bad):
    with pytest.raises(ValueError, match=r"runs.*1\.\.15"):
        qube_closed_loop_files([bad])
    with pytest.raises(ValueError, match=r"1\.\.15"):
        load_qube_closed_loop([1, bad])


def test_licence_and_readme_ship_beside_the_data():
    folder = qube_closed_loop_files([1])[0].parent
    assert "MIT License" in (folder / "LICENSE").read_text()
    readme = (folder / "README.md").read_text()
    assert "decargroup/closed_loop_koopman" in readme and "0b64a62e" in readme


TINY_CSV = (
    "t, theta, alpha, plant_input\n"
    "0.000, 0.0030679616, -0.0859029241, -1.5\n"
    "0.002, 0.0061359232, -0.0828349625, 0.25\n"
    "0.004, 0.0092038847, -0.0797670009, 1.125\n"
    "0.006, 0.0122718463, -0.0766990394, -0.5\n"
)


def test_csv_gz_loads_identically_to_the_plain_csv(tmp_path):
    plain = tmp_path / "tiny.csv"
    plain.write_text(TINY_CSV)
    packed = tmp_path / "tiny.csv.gz"
    with gzip.open(packed, "wt", newline="") as fh:
        fh.write(TINY_CSV)
    (a,) = load_trajectories(plain, "furuta", **QUBE_CLOSED_LOOP_MAPPING)
    (b,) = load_trajectories(packed, "furuta", **QUBE_CLOSED_LOOP_MAPPING)
    for field in ("t", "q", "u"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert a.name == b.name
    np.testing.assert_allclose(a.u[:, 0], [-1.5, 0.25, 1.125, -0.5])  # ", " separated values
    np.testing.assert_allclose(a.q[0], [0.0030679616, math.pi + 0.0859029241])


def test_csv_gz_errors_name_the_file(tmp_path):
    broken = tmp_path / "broken.csv.gz"
    broken.write_text(TINY_CSV)  # not actually gzip
    with pytest.raises(DataError, match="broken.csv.gz"):
        load_trajectories(broken, "furuta", **QUBE_CLOSED_LOOP_MAPPING)
    other = tmp_path / "tiny.txt"
    other.write_text(TINY_CSV)
    with pytest.raises(DataError, match=r"expected \.csv, \.csv\.gz, \.npz or \.mat"):
        load_trajectories(other, "furuta")
    (tr,) = load_qube_closed_loop([2])
    with pytest.raises(DataError, match="unsupported output type"):
        save_trajectories(tmp_path / "out.csv.gz", [tr], "furuta")
