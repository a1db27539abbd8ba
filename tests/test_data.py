"""The measured-data loader/writer: formats, column maps, and one clear error per bad input."""

import numpy as np
import pytest

from furuta_gym.data import DataError, Trajectory, load_trajectories, save_trajectories


def _trajs(n=2, T=50, dof=2, vel=True):
    rng = np.random.default_rng(0)
    t = np.arange(T) * 0.002
    return [
        Trajectory(
            t=t,
            q=rng.normal(size=(T, dof)),
            u=rng.normal(size=(T, 1)),
            qd=rng.normal(size=(T, dof)) if vel else None,
            name=f"run{k}",
        )
        for k in range(n)
    ]


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_round_trip_is_exact(tmp_path, suffix):
    trajs = _trajs()
    path = save_trajectories(tmp_path / f"d{suffix}", trajs, "furuta")
    back = load_trajectories(path, "furuta")
    assert [b.name for b in back] == ["run0", "run1"]
    for a, b in zip(trajs, back, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.qd, b.qd)
        np.testing.assert_array_equal(a.u, b.u)


def test_mat_files_load_with_the_same_columns(tmp_path):
    from scipy.io import savemat

    t = np.arange(40) * 0.01
    savemat(tmp_path / "d.mat", {"t": t, "p": np.sin(t), "u": np.cos(t)})
    (tr,) = load_trajectories(tmp_path / "d.mat", "nmsd")
    np.testing.assert_allclose(tr.q[:, 0], np.sin(t))
    assert tr.qd is None and tr.dt == pytest.approx(0.01)


def test_saving_never_overwrites_unless_asked(tmp_path):
    path = save_trajectories(tmp_path / "d.csv", _trajs(), "furuta")
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        save_trajectories(path, _trajs(n=1), "furuta")
    assert path.read_bytes() == before


def _write(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_missing_column_names_file_column_and_expectation(tmp_path):
    p = _write(tmp_path, "traj,t,alpha,u\n0,0,0,0\n0,1,0,0\n0,2,0,0\n")
    with pytest.raises(DataError, match=r"d\.csv.*missing column\(s\) \['beta'\]"):
        load_trajectories(p, "furuta")


def test_nan_rows_leaving_no_trajectory_are_refused_naming_the_column(tmp_path):
    p = _write(tmp_path, "traj,t,p,u\n0,0,0.1,0\n0,0.01,nan,0\n0,0.02,0.3,0\n")
    with pytest.raises(DataError, match=r"expected at least 3.*missing values \(NaN/inf: 'p' 1\).*data row 2"):
        load_trajectories(p, "nmsd")


def test_non_monotonic_and_non_uniform_time_are_refused(tmp_path):
    p = _write(tmp_path, "t,p,u\n0,0,0\n0.02,0,0\n0.01,0,0\n")
    with pytest.raises(DataError, match="not strictly increasing"):
        load_trajectories(p, "nmsd")
    # a step of 1.3 periods is neither the period nor a gap (samples dropped): refused
    p = _write(tmp_path, "t,p,u\n0,0,0\n0.01,0,0\n0.023,0,0\n0.033,0,0\n", name="e.csv")
    with pytest.raises(DataError, match=r"column 't' is not uniformly sampled.*step 0.013 s vs median 0.01 s"):
        load_trajectories(p, "nmsd")


def test_wrong_system_is_named(tmp_path):
    path = save_trajectories(tmp_path / "f.csv", _trajs(), "furuta")
    with pytest.raises(DataError, match="looks like a furuta file"):
        load_trajectories(path, "nmsd")


def test_too_short_and_unknown_map_keys(tmp_path):
    p = _write(tmp_path, "t,p,u\n0,0,0\n0.01,0,0\n")
    with pytest.raises(DataError, match="expected at least 3"):
        load_trajectories(p, "nmsd")
    p = _write(tmp_path, "t,p,u\n0,0,0\n0.01,0,0\n0.02,0,0\n", name="g.csv")
    with pytest.raises(DataError, match="unknown column 'theta'"):
        load_trajectories(p, "nmsd", column_map={"theta": "x"})
    with pytest.raises(FileNotFoundError, match="no such data file"):
        load_trajectories(tmp_path / "absent.csv", "nmsd")


def test_text_in_a_numeric_column_is_named(tmp_path):
    p = _write(tmp_path, "t,p,u\n0,0,0\n0.01,abc,0\n0.02,0,0\n")
    with pytest.raises(DataError, match=r"column 'p' holds 'abc'"):
        load_trajectories(p, "nmsd")


def test_real_qube_log_loads_through_a_column_map_with_sign_and_offset():
    from furuta_gym.datasets import qube_closed_loop_files

    path = qube_closed_loop_files([1])[0]  # a vendored real run, as the user's own file
    (tr,) = load_trajectories(
        path,
        "furuta",
        column_map={"alpha": "theta", "beta": "alpha", "u": "plant_input"},
        offsets={"beta": np.pi},
    )
    assert len(tr) == 10000 and tr.dt == pytest.approx(0.002)
    # balanced upright: β stays near π; the encoder step is 2π/2048
    assert np.all(np.abs(tr.q[:, 1] - np.pi) < 0.5)
    steps = np.unique(np.round(np.diff(tr.q[:, 0]) / (2 * np.pi / 2048), 6))
    assert np.allclose(steps, np.round(steps))
