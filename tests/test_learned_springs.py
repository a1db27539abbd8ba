"""A learned spring in DeLaN's and augmented DeLaN's potential (issue 44, ``springs=``).

Their potential network sees an angle through (cos, sin), so it is periodic and cannot hold a
rotor cable that winds up over several turns. ``springs=("alpha",)`` adds the effect registry's
spring ½k(α − α_ref)² with k and α_ref learned; without it the model is what it was, leaf for leaf.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym
from furuta_gym.cli import build_parser
from furuta_gym.cli.reproduce import config_from_args
from furuta_gym.models import make_model
from furuta_gym.training import checkpoint as ckpt

furuta_gym.enable_x64()


def _with_spring(model, log_k: float, reference: float):
    import equinox as eqx

    nets = lambda m: (m.lagrangian_nets.spring_log_stiffness, m.lagrangian_nets.spring_reference)  # noqa: E731
    return eqx.tree_at(nets, model, (jnp.array([log_k]), jnp.array([reference])))


@pytest.mark.parametrize("kind", ["dln", "adln"])
def test_the_spring_adds_the_registry_law_to_the_potential_and_nothing_else(kind):
    plain = make_model("furuta", kind, 3)
    sprung = _with_spring(make_model("furuta", kind, 3, springs=("alpha",)), np.log(0.8), 0.3)
    k = 0.8e-3  # the registry's typical rotor spring (1e-3 N·m/rad) times e^z
    for q in ([2.0, 0.3], [-7.5, 3.1], [0.0, 0.0]):
        q = jnp.array(q)
        extra = float(sprung.potential(q) - plain.potential(q))
        assert extra == pytest.approx(0.5 * k * (float(q[0]) - 0.3) ** 2, rel=1e-9, abs=1e-15)
        force = jax.grad(sprung.potential)(q) - jax.grad(plain.potential)(q)
        np.testing.assert_allclose(np.asarray(force), [k * (float(q[0]) - 0.3), 0.0], rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(np.asarray(sprung.mass_matrix(q)), np.asarray(plain.mass_matrix(q)))
    # the overall scale multiplies the spring with the rest of the Lagrangian (free data leave it open)
    q = jnp.array([2.0, 0.3])
    assert float(sprung.with_scale(2.5).potential(q)) == pytest.approx(2.5 * float(sprung.potential(q)), rel=1e-12)


def test_a_linear_joint_takes_the_linear_unit_and_bad_joints_are_named():
    m = _with_spring(make_model("nmsd", "dln", 0, springs=("p",)), 0.0, 0.0)
    plain = make_model("nmsd", "dln", 0)
    q = jnp.array([0.2])
    assert float(m.potential(q) - plain.potential(q)) == pytest.approx(0.5 * 1.0 * 0.04, rel=1e-9)  # 1 N/m
    with pytest.raises(ValueError, match="springs: 'gamma' is not a joint of furuta"):
        make_model("furuta", "dln", 0, springs=("gamma",))
    with pytest.raises(ValueError, match="each joint at most once"):
        make_model("furuta", "dln", 0, springs=("alpha", "alpha"))
    with pytest.raises(ValueError, match=r"unknown APHYNITY hyper-parameters \[.springs.\]"):
        make_model("furuta", "aph", 0, springs=("alpha",))


def test_without_springs_the_model_has_its_old_leaves_and_a_sprung_one_round_trips(tmp_path):
    plain, sprung = make_model("furuta", "dln", 1), make_model("furuta", "dln", 1, springs=("alpha",))
    assert len(jax.tree_util.tree_leaves(sprung)) == len(jax.tree_util.tree_leaves(plain)) + 2
    assert "springs" not in plain.hyperparameters  # checkpoints saved before the option rebuild as they were
    sprung = _with_spring(sprung, 0.4, -0.2)
    loaded = ckpt.load_model(ckpt.save_model(tmp_path / "m.eqx", sprung))
    assert loaded.hyperparameters["springs"] == ("alpha",)
    q = jnp.array([5.0, 1.0])
    assert float(loaded.potential(q)) == float(sprung.potential(q))


def test_training_moves_the_spring():
    """Its parameters are trainable: L_Iτ steps change them (and not the frozen scale)."""
    from furuta_gym.effects import Effect
    from furuta_gym.rigs import measured_like
    from furuta_gym.training.losses import make_windows
    from furuta_gym.training.train import TrainSettings, training_step

    data = measured_like(
        "furuta",
        [Effect("spring", "alpha", 2e-3)],
        forced=False,
        n_trajectories=3,
        duration=1.0,
        seed=0,
        quantize=False,
        true_velocities=True,
    )
    windows = make_windows(data, 21, stride=20, cover_end=True)
    model = make_model("furuta", "dln", 0, hidden=(8, 8), springs=("alpha",))
    step, params, opt_state = training_step(model, TrainSettings(progress=False), "itau")
    for _ in range(5):
        params, opt_state, losses, ok = step(params, opt_state, None, windows, jnp.asarray(0.0), jnp.asarray(1e-2))
        assert bool(ok)
    nets = params.lagrangian_nets
    assert abs(float(nets.spring_log_stiffness[0])) > 1e-3 and abs(float(nets.spring_reference[0])) > 1e-3


def test_the_command_line_names_the_springs():
    args = build_parser().parse_args(["reproduce", "--learned-spring", "alpha", "--pair", "dln:prop"])
    _, config = config_from_args(args)
    assert config.model_overrides == {"springs": ("alpha",)}
    _, default = config_from_args(build_parser().parse_args(["reproduce"]))
    assert default.model_overrides is None
    from furuta_gym.cli.train import model_hparams, run

    train = ["train", "--system", "furuta", "--model", "dln", "--loss", "prop", "--data", "qube:1", "--out", "x"]
    args = build_parser().parse_args([*train, "--learned-spring", "alpha", "--hidden", "8,8"])
    assert model_hparams(args) == {"springs": ("alpha",), "hidden": (8, 8)}
    aph = build_parser().parse_args([*train[:4], "aph", *train[5:], "--learned-spring", "alpha"])
    with pytest.raises(ValueError, match="--learned-spring: APHYNITY's potential"):
        run(aph)  # refused before any data is read or folder made
