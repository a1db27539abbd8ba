"""Diagnosing a learned model (``diagnose(..., model=...)``, ``furuta-gym diagnose --model``).

A learned Lagrangian model with only viscous damping cannot express Coulomb friction: on data of
a plant that has it, the diagnosis must find it around the learned model (kept as it is) and
lower the held-out error ≥ 1.4×; on data of the plant the model was trained on, report nothing.
The checkpoints are the reproduction's DeLaN L_prop models (trained on the pinned plant).
"""

from __future__ import annotations

import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym.cli import main
from furuta_gym.data import Trajectory, save_trajectories
from furuta_gym.diagnose import diagnose
from furuta_gym.effects import Effect
from furuta_gym.models import NMSD
from furuta_gym.rigs import measured_like
from furuta_gym.training.checkpoint import load_model

RUNS = Path(__file__).resolve().parents[1] / "results" / "reproduce" / "runs"
NMSD_DLN = RUNS / "nmsd" / "dln_prop" / "seed0" / "model.eqx"
NMSD_LOG = dict(n_trajectories=6, duration=8.0)


def test_coulomb_friction_missing_from_a_learned_model_is_found_via_cli(tmp_path, capsys):
    data = measured_like("nmsd", [Effect("coulomb_friction", "p", 1.0)], seed=3, **NMSD_LOG)
    csv, out = tmp_path / "msd.csv", tmp_path / "diag.json"
    save_trajectories(csv, data, "nmsd")
    assert main(["diagnose", str(csv), "--system", "nmsd", "--model", str(NMSD_DLN), "--json", str(out)]) == 0
    assert "given model is the declared model" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    top = doc["effects"][0]
    assert (top["name"], top["joint"], top["significant"]) == ("coulomb_friction", "p", True)
    assert top["coefficient"] == pytest.approx(1.0, rel=0.35)
    assert [e["name"] for e in doc["effects"] if e["significant"]] == ["coulomb_friction"]
    assert doc["error_before"]["trajectory_rmse"] >= 1.4 * doc["error_after"]["trajectory_rmse"]
    assert doc["parameters_after"] == {"scale": 1.0}


def test_a_learned_model_of_the_plant_itself_gets_nothing_added():
    res = diagnose(measured_like("nmsd", [], seed=3, **NMSD_LOG), "nmsd", model=load_model(NMSD_DLN))
    assert res.found == [], res.table()


def test_model_after_wraps_the_learned_model_and_reproduces_it_at_zero_effects():
    model = load_model(NMSD_DLN)
    res = diagnose(
        measured_like("nmsd", [Effect("coulomb_friction", "p", 1.0)], seed=4, **NMSD_LOG), "nmsd", model=model
    )
    q, qd = jnp.array([0.3]), jnp.array([-0.7])
    before = res.model_before
    # the learned model kept as it is: same mass matrix and potential
    np.testing.assert_allclose(before.mass_matrix(q), model.mass_matrix(q), rtol=1e-12)
    np.testing.assert_allclose(before.potential(q), model.potential(q), rtol=1e-12)
    after = res.model_after
    friction = after.nonconservative_force(q, qd) - before.nonconservative_force(q, qd)
    assert float(friction[0]) == pytest.approx(res.found[0].coefficient, rel=1e-9)  # −F·sgn(−0.7) = +F


class _InputTimesState(NMSD):
    """A model whose input force is not B·u + f(q, q̇): the diagnosis must refuse it clearly."""

    def input_force(self, q, qd, u):
        return u[:1] * (1.0 + q[:1] ** 2)


def test_a_model_whose_input_force_the_fit_cannot_integrate_is_refused():
    data = measured_like("nmsd", [], seed=3, n_trajectories=3, duration=5.0)
    with pytest.raises(ValueError, match="B·u"):
        diagnose(data, "nmsd", model=_InputTimesState())


def test_a_model_of_another_system_is_refused():
    data = [Trajectory(np.arange(5) * 0.01, np.zeros((5, 1)), np.zeros((5, 1)))]
    with pytest.raises(ValueError, match="nmsd model cannot diagnose furuta"):
        diagnose(data, "furuta", model=load_model(NMSD_DLN))


def test_a_model_trained_on_the_coulomb_plant_cannot_express_the_friction_and_gets_it_added():
    """Fine-tuned on data of the plant with Coulomb friction, the DeLaN turns part of it into
    viscous damping (all it can express); the diagnosis adds the rest as Coulomb friction."""
    from furuta_gym.signals import zero_phase_velocity
    from furuta_gym.training.train import TrainSettings, train

    coulomb = [Effect("coulomb_friction", "p", 1.0)]
    data = measured_like("nmsd", coulomb, seed=5, **NMSD_LOG)
    with_v = [Trajectory(tr.t, tr.q, tr.u, zero_phase_velocity(tr.q, tr.dt, cutoff_hz=8.0), tr.name) for tr in data]
    base = load_model(NMSD_DLN)
    config = TrainSettings(epochs=(150,), horizons=(None,), learning_rate=1e-3, progress=False, batch_size=None)
    model, history = train("dln", "nmsd", "prop", with_v, config, model=base)
    assert history[-1]["itau"] < history[0]["itau"]
    assert float(model.damping[0]) > float(base.damping[0])  # friction partly absorbed as viscous
    res = diagnose(measured_like("nmsd", coulomb, seed=6, **NMSD_LOG), "nmsd", model=model)
    top = res.effects[0]
    assert (top.name, top.joint, top.significant) == ("coulomb_friction", "p", True), res.table()
    assert 0.5 < top.coefficient < 1.35, res.table()
    assert res.error_before.trajectory_rmse >= 1.4 * res.error_after.trajectory_rmse, res.table()
