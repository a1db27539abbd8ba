"""The paper's protocol on a calibrated rig: the datasets generated on a plant (a diagnosis) as the
QUBE measures them, and ``reproduce --plant --sensor experiment`` scoring beside the paper's
experimental columns."""

import csv
import json

import numpy as np
import pytest

from furuta_gym.effects import Effect
from furuta_gym.envs import Plant
from furuta_gym.training.datagen import MujocoGroundTruth
from furuta_gym.training.reproduce import ReproduceSettings, load_paper_table, reproduce, truth_model

CHIRP_T = np.arange(0, 0.5 + 1e-9, 0.01)


def _chirp(t):
    return (2.0 * np.sin(2 * np.pi * (1.0 + 4.0 * t) * t))[:, None]


def test_the_nominal_plant_generates_what_the_shipped_model_does():
    x0 = np.array([[0.3, 2.0, -1.0, 4.0]])
    us = _chirp(CHIRP_T)[None]
    shipped = MujocoGroundTruth("furuta")(x0, CHIRP_T, us)
    plant = MujocoGroundTruth("furuta", plant=Plant.nominal("furuta"))(x0, CHIRP_T, us)
    assert np.max(np.abs(plant - shipped)) < 1e-9
    assert MujocoGroundTruth("furuta").name == "mujoco"


def test_a_plant_input_delay_is_the_input_seen_late():
    delay = 0.02  # two samples: the delayed run is the undelayed one driven by the shifted input
    x0 = np.zeros((1, 4))
    u = _chirp(CHIRP_T)
    late = np.concatenate([np.full((2, 1), u[0, 0]), u[:-2]])
    nominal = Plant.nominal("furuta")
    delayed = Plant.nominal("furuta", effects=(Effect("input_delay", "u", delay),))
    got = MujocoGroundTruth("furuta", plant=delayed)(x0, CHIRP_T, u[None])
    want = MujocoGroundTruth("furuta", plant=nominal)(x0, CHIRP_T, late[None])
    undelayed = MujocoGroundTruth("furuta", plant=nominal)(x0, CHIRP_T, u[None])
    assert np.max(np.abs(got - want)) < 1e-9 < np.max(np.abs(got - undelayed))


@pytest.fixture(scope="module")
def rig_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("rig")
    plant = Plant.nominal(
        "furuta", effects=(Effect("coulomb_friction", "alpha", 5e-4), Effect("spring", "alpha", 8e-4))
    )
    path = root / "diagnosis.json"
    path.write_text(json.dumps({"plant": plant.to_json()}))
    config = ReproduceSettings(
        quick=True,
        systems=("furuta",),
        pairs=(("dln", "traj"),),
        epochs={"furuta": (1, 0)},
        progress=False,
        figures=False,
        plant=str(path),
        sensor="experiment",
    )
    paths = reproduce(root / "out", config, log=lambda msg: None)
    return root, config, paths


def test_a_calibrated_rig_run_is_measured_as_the_qube_and_scored_beside_the_experiment(rig_run):
    root, config, paths = rig_run
    manifest = json.loads((root / "out" / "data" / "furuta" / "manifest.json").read_text())
    assert manifest["sensor_name"] == "experiment" and manifest["ground_truth"].startswith("mujoco plant")
    assert manifest["plant"]["effects"][1]["name"] == "spring"
    with open(root / "out" / "data" / "furuta" / "train.csv") as fh:
        alpha = np.array([float(r["alpha"]) for r in csv.DictReader(fh)])
    counts = alpha / (2 * np.pi / 2048)
    assert np.max(np.abs(counts - np.round(counts))) < 1e-6  # encoder counts
    paper = load_paper_table()
    with open(paths["tables.csv"]) as fh:
        rows = list(csv.DictReader(fh))
    states = [r for r in rows if r["metric"] in ("alpha", "beta", "alpha_dot", "beta_dot")]
    assert len(states) == 8 and all(
        r["paper"] == paper[("furuta", r["test_set"], "DLN", "traj", "exp_" + r["metric"])] for r in states
    )
    assert all(r["paper"] == "" for r in rows if r["metric"] == "energy")


def test_a_rig_run_refuses_data_of_another_sensor_and_compares_physics_with_the_plant(rig_run):
    root, config, _ = rig_run
    import dataclasses

    with pytest.raises(ValueError, match="sensor='experiment' .this run: 'exact'"):
        reproduce(root / "out", dataclasses.replace(config, sensor="exact"), log=lambda msg: None)
    truth = truth_model("furuta", config)
    q = np.array([0.5, 0.2])
    # the cable spring is in the truth's potential, so the physics columns see it
    assert (
        abs(
            float(truth.potential(q))
            - float(truth_model("furuta", ReproduceSettings()).potential(q))
            - 0.5 * 8e-4 * 0.5**2
        )
        < 1e-12
    )


@pytest.mark.parametrize("script", ["calibrated_protocol_table.py", "calibrated_row_shrink_table.py"])
def test_the_calibrated_rig_docs_match_their_results(script):
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, str(root / "studies" / script), "--check"],
        capture_output=True,
        text=True,
        cwd=root / "studies",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_the_row_shrink_results_say_what_the_docs_read_from_them():
    """docs/learning.md's prose above the row-shrink block: without the spring and Coulomb friction
    the rotor's equation holds most of the residual and little of the momentum changes, the joint
    normaliser's scan is least below s = 1 and the per-joint one's at it, as both are with the full
    model; the joint normaliser's best fit has a far lighter rotor than the plant's."""
    from pathlib import Path

    doc = json.loads((Path(__file__).resolve().parents[1] / "results/calibrated_protocol/row_shrink.json").read_text())
    a, b = doc["models"]["no_spring_coulomb"], doc["models"]["full"]
    assert a["at_plant"]["rotor_share_of_residual"] > 0.9 and a["at_plant"]["rotor_share_of_momentum_changes"] < 0.1

    def least(model, normalize):
        return min(model["scan"], key=lambda row: row[normalize])["s"]

    assert least(a, "momentum") < 1 == least(a, "joint_momentum") == least(b, "momentum") == least(b, "joint_momentum")
    fits = a["best_fit"]
    assert fits["momentum"]["M11_over_M22"] < 0.5 * a["plant_M11_over_M22"] < fits["joint_momentum"]["M11_over_M22"]


def test_the_row_shrink_results_point_at_the_spring():
    """docs/learning.md: with the cable spring alone the loss's best fit keeps the plant's mass
    ratio under both normalisers; with the Coulomb friction alone the rotor shrinks as without both."""
    from pathlib import Path

    doc = json.loads((Path(__file__).resolve().parents[1] / "results/calibrated_protocol/row_shrink.json").read_text())
    spring, coulomb = doc["models"]["spring_only"], doc["models"]["coulomb_only"]
    for n in ("momentum", "joint_momentum"):
        assert spring["best_fit"][n]["M11_over_M22"] == pytest.approx(spring["plant_M11_over_M22"], rel=0.2)
    assert coulomb["best_fit"]["momentum"]["M11_over_M22"] < 0.5 * coulomb["plant_M11_over_M22"]


def test_the_control_results_say_what_the_docs_read_from_them():
    """The protocol's control table as docs/learning.md reads it: both spring L_prop designs meet
    the bar (x0 = 0, ≥ 90 % of the starts) with k_e picked on the model and not with the default
    gain; the L_traj / L_aph designs without the spring fail the picked gain, with it they pass."""
    from pathlib import Path

    doc = json.loads((Path(__file__).resolve().parents[1] / "results/calibrated_protocol/control.json").read_text())

    def bar(run):
        return "design_error" not in run and run["from_rest"] and run["seeded_successes"] >= 0.9 * run["seeded"]

    rows = doc["models"]
    for name in ("dln_prop_spring", "adln_prop_spring"):
        assert (
            rows[name]["shape"]["curvature_at_top_Nm_per_rad"]
            < 0
            < rows[name]["shape"]["curvature_at_hanging_Nm_per_rad"]
        )
        assert bar(rows[name]["gain_picked_on_model"]) and not bar(rows[name]) and rows[name]["from_rest"]
    for name in ("dln_traj", "adln_aph"):
        assert not bar(rows[name]["gain_picked_on_model"]) and bar(rows[name])
        assert bar(rows[f"{name}_spring"]) and bar(rows[f"{name}_spring"]["gain_picked_on_model"])


def test_the_spring_l_prop_design_swings_the_rig_up_from_rest():
    """End to end with today's code: the committed DeLaN L_prop checkpoint with a learned rotor
    spring, k_e picked on it alone, swings up the calibrated rig's MuJoCo plant from x0 = 0 through
    the QUBE's sensors, and holds it."""
    from pathlib import Path

    import gymnasium as gym

    from furuta_gym.controllers import SwingUpLQR, evaluate_on_env
    from furuta_gym.envs import Episode, Sensors
    from furuta_gym.training.checkpoint import load_model

    out = Path(__file__).resolve().parents[1] / "results/calibrated_protocol"
    model = load_model(out / "reproduce_spring/runs/furuta/dln_prop/seed0/model.eqx", expected_system="furuta")
    assert model.hyperparameters["springs"] == ("alpha",)
    ctrl = SwingUpLQR.from_model(model, auto_gain=True, seed=0)
    plant = Plant.load(out / "diagnosis.json")

    def make_env():
        return gym.make(
            "furuta_gym/Furuta-v0",
            episode=Episode(seconds=None),
            plant=plant,
            sensors=Sensors(encoder_counts=2048, velocity="filter"),
        )

    (record,) = evaluate_on_env(ctrl, make_env, np.zeros((1, 4)), 8.0, seed=0)
    assert record.metrics.success and record.metrics.time_to_upright < 6.0
