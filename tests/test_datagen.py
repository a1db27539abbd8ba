"""Data generation (issue 3 item 4): the paper's recipes, seeding, sensor options, round trip."""

import json

import numpy as np
import pytest

from furuta_gym.cli import main
from furuta_gym.data import load_trajectories
from furuta_gym.sensors import Sensors
from furuta_gym.signals import ENCODER_COUNTS_PER_REV, chirp
from furuta_gym.training.datagen import (
    DATASET_NAMES,
    AnalyticGroundTruth,
    FurutaRecipe,
    NMSDRecipe,
    generate_datasets,
    read_sensor_record,
    write_datasets,
)

# A tiny Furuta recipe keeps the simulated seconds (and the test time) small.
TINY_FURUTA = FurutaRecipe(
    n_train=4,
    n_test_free=2,
    test_free_duration=2.0,
    n_test_forced=1,
    test_forced_duration=3.0,
    scale_fit_duration=2.0,
)


def _zeros_ground_truth(x0s, t, us):
    """A free-of-cost stand-in ground truth: holds x0 (for shape / recipe checks only)."""
    return np.repeat(np.asarray(x0s)[:, None, :], len(t), axis=1)


@pytest.fixture(scope="module")
def furuta_gt():
    return AnalyticGroundTruth("furuta")


@pytest.fixture(scope="module")
def nmsd_small():
    return generate_datasets("nmsd", small=True, ground_truth="analytic", seed=3)


@pytest.fixture(scope="module")
def furuta_tiny(furuta_gt):
    return generate_datasets("furuta", recipe=TINY_FURUTA, ground_truth=furuta_gt, seed=3)


def test_full_recipes_have_the_papers_shapes_and_rates():
    nmsd = generate_datasets("nmsd", ground_truth=_zeros_ground_truth)
    assert [len(nmsd[k]) for k in DATASET_NAMES["nmsd"]] == [30, 3, 3]
    assert {len(tr) for tr in nmsd["train"]} == {201}  # 2 s at 100 Hz, both ends included
    assert {len(tr) for tr in nmsd["test_chirp"]} == {2501}
    assert {len(tr) for tr in nmsd["test_square"]} == {1501}
    fur = generate_datasets("furuta", ground_truth=_zeros_ground_truth)
    assert [len(fur[k]) for k in DATASET_NAMES["furuta"]] == [64, 6, 3, 1]
    assert {len(tr) for tr in fur["train"]} == {101}
    assert {len(tr) for tr in fur["test_free"]} == {601}
    assert {len(tr) for tr in fur["test_forced"]} == {2001}
    for trajs in [*nmsd.values(), *fur.values()]:
        for tr in trajs:
            np.testing.assert_allclose(np.diff(tr.t), 0.01, atol=1e-9)
            assert tr.t[0] == 0.0
    # initial states drawn from the documented ranges (x0 is held by the stand-in ground truth)
    x0_train = np.stack([tr.x[0] for tr in fur["train"]])
    x0_test = np.stack([tr.x[0] for tr in fur["test_free"] + fur["test_forced"]])
    assert np.all(np.abs(x0_train[:, :2]) <= np.pi) and np.all(np.abs(x0_train[:, 2:]) <= 5)
    assert np.all(np.abs(x0_test[:, 2:]) <= 20) and np.abs(x0_test[:, 2:]).max() > 5
    assert all(np.all(tr.u == 0) for tr in fur["train"] + fur["test_free"])


def test_nmsd_training_segments_are_one_continuous_chirp(nmsd_small):
    r = NMSDRecipe.small()
    segs = nmsd_small["train"]
    assert len(segs) == int(r.train_duration / r.segment_duration) == 10
    for a, b in zip(segs[:-1], segs[1:], strict=True):
        np.testing.assert_array_equal(a.x[-1], b.x[0])  # adjacent segments share the boundary
    u = np.concatenate([s.u[:-1, 0] for s in segs] + [segs[-1].u[-1:, 0]])
    t = np.arange(u.size) * 0.01
    np.testing.assert_allclose(u, chirp(t, 0.1, 1.1, r.train_duration, r.amplitude), atol=1e-12)
    sq = nmsd_small["test_square"][0]
    on = (sq.t >= r.pulse_start) & (sq.t < r.pulse_start + r.pulse_width)
    assert np.all(sq.u[on, 0] == r.amplitude) and np.all(sq.u[~on, 0] == 0)


def test_generated_data_follow_the_true_dynamics(nmsd_small):
    """The true model's integral residual (Simpson) on the data is at the quadrature floor, far
    below that of a model with a 10 % stiffer spring."""
    import jax.numpy as jnp

    from furuta_gym.lagrangian import integral_residual
    from furuta_gym.models import NMSD, NMSDParameters, analytic_model

    tr = nmsd_small["test_chirp"][0]
    args = (jnp.asarray(tr.q), jnp.asarray(tr.qd), jnp.asarray(tr.u), tr.dt, "simpson")
    true = np.asarray(integral_residual(analytic_model("nmsd"), *args))
    wrong = np.asarray(integral_residual(NMSD(params=NMSDParameters(k1=11.0)), *args))
    impulse = np.sqrt(np.mean(np.diff(tr.qd[::2], axis=0) ** 2))  # rms Δp over the intervals
    assert np.sqrt(np.mean(true**2)) < 1e-3 * impulse
    assert np.sqrt(np.mean(wrong**2)) > 100 * np.sqrt(np.mean(true**2))


def test_mujoco_ground_truth_agrees_with_the_analytic_one(nmsd_small):
    mj = generate_datasets("nmsd", small=True, ground_truth="mujoco", seed=3)
    for name in DATASET_NAMES["nmsd"]:
        for a, b in zip(mj[name], nmsd_small[name], strict=True):
            assert np.max(np.abs(a.x - b.x)) < 1e-5


def test_seeded(furuta_gt):
    a = generate_datasets("furuta", recipe=TINY_FURUTA, ground_truth=_zeros_ground_truth, seed=1)
    b = generate_datasets("furuta", recipe=TINY_FURUTA, ground_truth=_zeros_ground_truth, seed=1)
    c = generate_datasets("furuta", recipe=TINY_FURUTA, ground_truth=_zeros_ground_truth, seed=2)
    for name in DATASET_NAMES["furuta"]:
        np.testing.assert_array_equal(a[name][0].x, b[name][0].x)
        assert not np.allclose(a[name][0].x, c[name][0].x)


def test_round_trip_through_the_loader(tmp_path, furuta_tiny):
    paths = write_datasets(tmp_path, furuta_tiny, "furuta", metadata={"seed": 3})
    for name, trajs in furuta_tiny.items():
        loaded = load_trajectories(paths[name], "furuta", require_velocities=True)
        assert [tr.name for tr in loaded] == [tr.name for tr in trajs]
        for a, b in zip(loaded, trajs, strict=True):
            np.testing.assert_array_equal(a.q, b.q)
            np.testing.assert_array_equal(a.qd, b.qd)
            np.testing.assert_array_equal(a.u, b.u)
            np.testing.assert_allclose(a.t, b.t, atol=1e-12)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["files"]["train"]["n_trajectories"] == 4
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_datasets(tmp_path, furuta_tiny, "furuta")


def test_quantisation_and_noise(furuta_gt, furuta_tiny):
    step = 2 * np.pi / ENCODER_COUNTS_PER_REV
    quant = generate_datasets(
        "furuta",
        recipe=TINY_FURUTA,
        ground_truth=furuta_gt,
        seed=3,
        sensor=Sensors(encoder_counts=ENCODER_COUNTS_PER_REV),
    )
    noisy = generate_datasets(
        "furuta", recipe=TINY_FURUTA, ground_truth=furuta_gt, seed=3, sensor=Sensors(measurement_noise=(0.01, 0.0))
    )
    q_exact = np.concatenate([tr.q for tr in furuta_tiny["test_free"]])
    q_quant = np.concatenate([tr.q for tr in quant["test_free"]])
    counts = q_quant / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)  # on the encoder grid
    assert np.max(np.abs(q_quant - q_exact)) <= step / 2 + 1e-12
    assert np.std(q_quant - q_exact) > step / 10  # and actually rounded
    # exact velocities are untouched by position quantisation
    np.testing.assert_array_equal(quant["test_free"][0].qd, furuta_tiny["test_free"][0].qd)
    err = np.concatenate([tr.q for tr in noisy["train"]]) - np.concatenate([tr.q for tr in furuta_tiny["train"]])
    assert 0.009 < np.std(err) < 0.011 and abs(np.mean(err)) < 0.002
    with pytest.raises(ValueError, match="no angular joint"):
        generate_datasets("nmsd", small=True, ground_truth=_zeros_ground_truth, sensor=Sensors(encoder_counts=2048))


def test_filtered_velocities_lag_like_the_papers_filter(furuta_gt, furuta_tiny):
    filt = generate_datasets(
        "furuta", recipe=TINY_FURUTA, ground_truth=furuta_gt, seed=3, sensor=Sensors(velocity="filter")
    )
    for a, b in zip(filt["test_free"], furuta_tiny["test_free"], strict=True):
        np.testing.assert_array_equal(a.q, b.q)  # positions unchanged
        # warmed up on a constant-velocity history: starts on the true velocity, no transient
        np.testing.assert_allclose(a.qd[0], b.qd[0], rtol=0.02, atol=0.05)
        rel = np.sqrt(np.mean((a.qd - b.qd) ** 2)) / np.sqrt(np.mean(b.qd**2))
        assert 1e-3 < rel < 0.4  # velocities up to 20 rad/s with a 16 ms lag
    # the error is a lag of ≈ 2ξ/ω0 = 16 ms: the estimate matches the exact velocity 0.01-0.02 s
    # earlier far better than at the same instant
    a, b = filt["test_forced"][0], furuta_tiny["test_forced"][0]
    same = np.mean((a.qd[2:] - b.qd[2:]) ** 2)
    shifted = min(np.mean((a.qd[2:] - b.qd[1:-1]) ** 2), np.mean((a.qd[2:] - b.qd[:-2]) ** 2))
    assert shifted < 0.5 * same


def test_bad_options_are_clear_errors():
    with pytest.raises(ValueError, match="velocity"):
        Sensors(velocity="magic")
    with pytest.raises(ValueError, match="sensor_rate_hz"):
        generate_datasets("nmsd", small=True, ground_truth=_zeros_ground_truth, sensor_rate_hz=250.0)
    with pytest.raises(ValueError, match="recipe for nmsd"):
        generate_datasets("nmsd", recipe=TINY_FURUTA, ground_truth=_zeros_ground_truth)
    with pytest.raises(ValueError, match="unknown system"):
        generate_datasets("cartpole")


def test_generate_cli_writes_loader_ready_files_and_never_overwrites(tmp_path, capsys):
    out = tmp_path / "nmsd"
    argv = [
        "generate",
        "--system",
        "nmsd",
        "--out",
        str(out),
        "--small",
        "--ground-truth",
        "analytic",
        "--noise",
        "0.001",
    ]
    assert main(argv) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["ground_truth"] == "analytic" and manifest["sensor"]["measurement_noise"] == [0.001, 0.0]
    assert read_sensor_record(manifest["sensor"]) == (Sensors(measurement_noise=(0.001, 0.0)), 500.0)
    for name in DATASET_NAMES["nmsd"]:
        trajs = load_trajectories(out / f"{name}.csv", "nmsd", require_velocities=True)
        assert trajs and all(len(tr) > 100 for tr in trajs)
    before = (out / "train.csv").read_bytes()
    assert main(argv) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert (out / "train.csv").read_bytes() == before
