"""A learned potential of the wrong shape at an equilibrium is detected and warned about (issue 44):
the analytic models pass, a flipped or flat potential fails, and training records and warns."""

import json
import subprocess
import sys
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym.data import Trajectory
from furuta_gym.lagrangian import AbstractLagrangianSystem, SystemSpec
from furuta_gym.models import NMSD, Furuta, furuta_lumped, make_model, system_definition
from furuta_gym.simulate import simulate
from furuta_gym.training import PotentialShapeWarning, check_potential_shape, warn_potential_shape
from furuta_gym.training.train import TrainSettings, train


class _Scaled(AbstractLagrangianSystem):
    """A model whose potential is ``factor`` times another's (−1: flipped, 0: flat)."""

    base: AbstractLagrangianSystem
    factor: float
    spec: SystemSpec = eqx.field(static=True)

    def __init__(self, base, factor):
        self.base, self.factor, self.spec = base, factor, base.spec

    def mass_matrix(self, q):
        return self.base.mass_matrix(q)

    def potential(self, q):
        return self.factor * self.base.potential(q)

    def nonconservative_force(self, q, qd):
        return self.base.nonconservative_force(q, qd)

    def input_force(self, q, qd, u):
        return self.base.input_force(q, qd, u)


def _no_shape_warning(model):
    with warnings.catch_warnings():
        warnings.simplefilter("error", PotentialShapeWarning)
        return warn_potential_shape(model)


def test_the_analytic_models_have_the_physical_shape_and_do_not_warn():
    g = float(furuta_lumped(Furuta().params)["G"])
    furuta = _no_shape_warning(Furuta())
    assert furuta["physical"] and [r["ok"] for r in furuta["equilibria"]] == [True, True]
    # V = G(1 − cos β): curvature +G hanging, −G upright
    np.testing.assert_allclose([r["curvature"] for r in furuta["equilibria"]], [g, -g], rtol=1e-12)
    nmsd = _no_shape_warning(NMSD())
    assert nmsd["physical"] and nmsd["equilibria"][0]["curvature"] == pytest.approx(float(NMSD().params.k1))


def test_the_equilibria_come_from_the_system_definition():
    assert [(e.joint, e.shape) for e in system_definition("furuta").equilibria] == [
        ("beta", "minimum"),
        ("beta", "maximum"),
    ]
    assert [e.shape for e in system_definition("nmsd").equilibria] == ["minimum"]
    with pytest.raises(ValueError, match="shape must be"):
        type(system_definition("nmsd").equilibria[0])("x", (0.0,), "p", "saddle")


def test_a_flipped_potential_warns_naming_each_equilibrium_and_its_curvature():
    g = float(furuta_lumped(Furuta().params)["G"])
    with pytest.warns(PotentialShapeWarning) as caught:
        result = warn_potential_shape(_Scaled(Furuta(), -1.0))
    assert len(caught) == 1 and not result["physical"]
    message = str(caught[0].message)
    assert "hanging (β = 0) must be a minimum" in message and "upright (β = π) must be a maximum" in message
    assert f"{-g:.3g}" in message and f"{g:.3g}" in message
    with pytest.warns(PotentialShapeWarning, match=r"rest \(p = 0\) must be a minimum"):
        warn_potential_shape(_Scaled(NMSD(), -1.0))
    # a flat potential (no gravity learned) is neither a minimum nor a maximum
    flat = check_potential_shape(_Scaled(Furuta(), 0.0))
    assert [r["ok"] for r in flat["equilibria"]] == [False, False]


def _cosine_delan(sign: float, seed: int = 0):
    """A Furuta DeLaN whose potential is ∓f(cos β) with f increasing: sign −1 physical (V falls
    with cos β: hanging a minimum), +1 flipped. Every other weight of the potential net is zero."""
    model = make_model("furuta", "dln", jax.random.PRNGKey(seed))
    layers = model.lagrangian_nets.potential_net.layers
    new = []
    for k, layer in enumerate(layers):
        w = jnp.zeros_like(layer.weight)
        w = w.at[0, 2].set(1.0) if k == 0 else w.at[0, 0].set(sign if k == len(layers) - 1 else 1.0)
        new.append(eqx.tree_at(lambda l: (l.weight, l.bias), layer, (w, jnp.zeros_like(layer.bias))))
    return eqx.tree_at(lambda m: m.lagrangian_nets.potential_net.layers, model, tuple(new))


def test_a_delan_potential_is_checked_through_its_own_networks():
    physical, flipped = check_potential_shape(_cosine_delan(-1.0)), check_potential_shape(_cosine_delan(1.0))
    assert physical["physical"] and not flipped["physical"]
    np.testing.assert_allclose(
        [r["curvature"] for r in flipped["equilibria"]], [-r["curvature"] for r in physical["equilibria"]], rtol=1e-12
    )


@pytest.fixture(scope="module")
def furuta_free():
    """Six free 1 s swings of the analytic Furuta at 100 Hz."""
    t = np.arange(0.0, 1.0 + 0.005, 0.01)
    rng = np.random.default_rng(0)
    out = []
    for k in range(6):
        x0 = np.array([rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi), *rng.uniform(-3, 3, 2)])
        xs = np.asarray(simulate(Furuta(), x0, t, np.zeros((len(t), 1)), rtol=1e-9, atol=1e-11))
        out.append(Trajectory(t, xs[:, :2], np.zeros((len(t), 1)), xs[:, 2:], name=str(k)))
    return out


def _train_briefly(model, data, out):
    config = TrainSettings(epochs=(2,), horizons=(None,), learning_rate=1e-9, progress=False, checkpoint_every=1)
    return train("dln", "furuta", "prop", data, config, out, model=model)


def test_training_warns_and_records_a_nonphysical_potential(furuta_free, tmp_path):
    with pytest.warns(PotentialShapeWarning, match="upright"):
        _train_briefly(_cosine_delan(1.0), furuta_free, tmp_path / "flipped")
    doc = json.loads((tmp_path / "flipped" / "history.json").read_text())
    assert doc["meta"]["potential_shape"]["physical"] is False
    assert doc["history"][-1]["potential_shape"] == doc["meta"]["potential_shape"]
    upright = doc["meta"]["potential_shape"]["equilibria"][1]
    assert upright["expected"] == "maximum" and upright["curvature"] > 0 and not upright["ok"]
    # every snapshot's history line carries the shape at that epoch
    assert all("potential_shape" in r for r in doc["history"])


def test_training_a_physical_potential_does_not_warn(furuta_free, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", PotentialShapeWarning)
        _, history = _train_briefly(_cosine_delan(-1.0), furuta_free, tmp_path / "physical")
    assert history[-1]["potential_shape"]["physical"] is True


def test_data_that_never_visit_an_equilibrium_are_named_and_warned_about(furuta_free, tmp_path):
    from furuta_gym.datasets import load_qube_closed_loop
    from furuta_gym.training import DataCoverageWarning, check_data_coverage, warn_data_coverage

    # the shipped runs balance the pendulum: the hanging rest is never near, the top always
    with pytest.warns(DataCoverageWarning, match=r"hanging.*LQR catch"):
        real = warn_data_coverage(load_qube_closed_loop(range(1, 6)), "furuta")
    share = {r["name"].split()[0]: r["share"] for r in real["equilibria"]}
    assert share["hanging"] == 0.0 and share["upright"] > 0.99
    # free swings over the circle visit both; the count is the samples within the radius
    free = check_data_coverage(furuta_free, "furuta")
    beta = np.concatenate([tr.q[:, 1] for tr in furuta_free])
    near_top = np.mean(np.abs(np.angle(np.exp(1j * (beta - np.pi)))) <= free["radius"])
    assert free["equilibria"][1]["share"] == pytest.approx(near_top) and near_top > 0
    assert free["equilibria"][0]["share"] > 0
    # training on swings that stay near the top warns and records the coverage in the checkpoint
    t = np.arange(0.0, 0.15 + 0.005, 0.01)
    top = []
    for k, db in enumerate((-0.05, 0.03, 0.06)):
        xs = np.asarray(simulate(Furuta(), np.array([0.0, np.pi + db, 0.0, 0.0]), t, np.zeros((len(t), 1))))
        assert np.all(np.abs(xs[:, 1] - np.pi) < 0.5)
        top.append(Trajectory(t, xs[:, :2], np.zeros((len(t), 1)), xs[:, 2:], name=f"top{k}"))
    with pytest.warns(DataCoverageWarning, match="hanging"):
        _train_briefly(_cosine_delan(-1.0), top, tmp_path / "top")
    doc = json.loads((tmp_path / "top" / "history.json").read_text())
    assert doc["meta"]["data_coverage"]["equilibria"][0]["share"] == 0.0


def test_lprop_ablation_docs_table_matches_its_results():
    root = Path(__file__).resolve().parents[1]
    if not any((root / "results" / "lprop_ablation").glob("*_s*.json")):
        pytest.skip("results/lprop_ablation not generated")
    proc = subprocess.run(
        [sys.executable, str(root / "studies" / "lprop_ablation_table.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
