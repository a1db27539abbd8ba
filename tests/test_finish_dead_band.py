"""The prediction-first finish tries an input dead band (issue 66): a dead band of 50 mV planted
in the MuJoCo plant that logs the runs is found by the finish and kept by the diagnosis' rule for
a gain on its held-out windows; a plant without one gets none. The diagnosis' report does not name
it (it is no library candidate), and ``--mjcf`` writes the refit without it, which plain MuJoCo
can run."""

import argparse
import json

import numpy as np
import pytest

import furuta_gym
from furuta_gym.cli.diagnose import _write_outputs
from furuta_gym.diagnose import diagnose
from furuta_gym.effects import Effect
from furuta_gym.envs import Plant, plant_mjcf
from furuta_gym.rigs import measured_like

furuta_gym.enable_x64()

SPRING = Effect("spring", "alpha", 5e-3)
BAND = Effect("input_dead_band", "u", 0.05)
CANDIDATES = ["spring:alpha", "coulomb_friction:alpha"]


def _diagnosed(effects):
    log = measured_like("furuta", list(effects), seed=3, n_trajectories=4, duration=5.0, quantize=False)
    return diagnose(log, "furuta", candidates=CANDIDATES, finish="prediction")


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_the_finish_finds_a_planted_dead_band_and_adds_none_where_there_is_none(tmp_path):
    res = _diagnosed([SPRING, BAND])
    finish = res.prediction
    assert finish.kept and finish.dead_band is not None and finish.dead_band.kept, finish.summary()
    assert finish.dead_band.width == pytest.approx(0.05, rel=0.35) and finish.dead_band.unit == "V"
    assert finish.dead_band.improvement >= 0.03 and finish.dead_band.z_score >= 3.0
    bands = [e for e in finish.plant.effects if e.name == "input_dead_band"]
    assert len(bands) == 1 and bands[0].coefficient == finish.dead_band.width
    assert res.plant(prediction_first=True) == finish.plant and "input_dead_band:u" in finish.added
    assert "input_dead_band" not in {e.name for e in res.effects} | {e.name for e in res.plant().effects}
    assert "input dead band: kept" in finish.summary()
    doc = json.loads(json.dumps(res.to_json()))["prediction_finish"]
    assert doc["dead_band"]["kept"] is True and doc["dead_band"]["width"] == finish.dead_band.width
    assert doc["dead_band"]["z_score"] == pytest.approx(finish.dead_band.z_score)
    assert Plant.from_json(doc["plant"]) == finish.plant
    # the spring is refitted as well as without a dead band
    spring = next(e for e in finish.plant.effects if e.name == "spring")
    assert spring.coefficient == pytest.approx(5e-3, rel=0.05)
    # plain MuJoCo gets the refit without the band (it cannot run one), not the plant minus it
    mujoco_plant = finish.mujoco_plant
    assert mujoco_plant is finish.mujoco_refit and "input_dead_band" not in {e.name for e in mujoco_plant.effects}
    assert {e.name for e in mujoco_plant.effects} >= {"spring"} and mujoco_plant.lumped != finish.plant.lumped
    assert Plant.from_json(doc["mujoco_plant"]) == mujoco_plant
    args = argparse.Namespace(json=None, report=None, mjcf=str(tmp_path / "rig.xml"), overwrite=False)
    _write_outputs(res, argparse.Namespace(**vars(args), prediction_first=True, with_inconsistent=False))
    xml = (tmp_path / "rig.xml").read_text()
    assert "without its input dead band (0.05 V), which MJCF cannot express" in xml
    assert xml == plant_mjcf(mujoco_plant)

    plain = _diagnosed([SPRING]).prediction
    assert plain.dead_band is not None and not plain.dead_band.kept, plain.summary()
    assert "input_dead_band" not in {e.name for e in plain.plant.effects}
    assert plain.mujoco_refit is None and plain.mujoco_plant is plain.plant
    assert np.isfinite(plain.heldout_rmse["refit"])


def test_with_an_actuator_lag_the_finish_does_not_try_a_dead_band():
    """The MuJoCo plant lags the dead-banded control, the model dead-bands the lagged input: the
    finish does not fit what the two would simulate differently."""
    from types import SimpleNamespace

    from furuta_gym.diagnose import InputDynamics
    from furuta_gym.diagnose._finish import _dead_band_trial
    from furuta_gym.systems import get_spec

    fit, sums, lag = (np.zeros(3), [], [], True), np.ones(4), InputDynamics("lag", 0.005)
    out = _dead_band_trial(SimpleNamespace(spec=get_spec("furuta")), None, fit, lag, sums)
    assert out[0] is fit and out[1] is lag and out[2] is sums
    assert not out[3].kept and out[3].width == 0.0 and out[3].reason.startswith("not tried")
    assert out[3].to_json()["z_score"] is None
