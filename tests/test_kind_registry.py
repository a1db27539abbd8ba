"""Losses and model kinds are types, registered once (furuta_gym.training.loss_kinds,
furuta_gym.models.MODEL_KINDS): each carries what differs between kinds and no code outside
the loss registry compares their names — adding a loss is one class plus tests."""

import argparse
import ast
from pathlib import Path

import jax
import jax.numpy as jnp
import pytest

import furuta_gym
from _simulated import nmsd_chirp_segments
from furuta_gym.cli import train as cli_train
from furuta_gym.models import MODEL_KINDS, AbstractLearnedSystem, make_model, model_kind
from furuta_gym.training import TrainSettings, make_windows, training_step
from furuta_gym.training.loss_kinds import INTEGRAL_ONLY, LOSS_KINDS, PROPOSED_LOSS, LossKind, loss_kind
from furuta_gym.training.train import LOSSES

ROOT = Path(furuta_gym.__file__).resolve().parent
REGISTRY = ROOT / "training" / "loss_kinds.py"
SOURCES = [
    p
    for folder in (ROOT, ROOT.parent / "models", ROOT.parent / "controllers")
    for p in folder.rglob("*.py")
    if p != REGISTRY
]
NAMES = set(LOSS_KINDS) | set(MODEL_KINDS)


def _names_in(node) -> set[str]:
    """Kind names among a node's string constants (itself, or a tuple/list/set of them)."""
    elts = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else [node]
    return {e.value for e in elts if isinstance(e, ast.Constant) and e.value in NAMES}


def _comparisons(tree) -> list[tuple[int, str]]:
    """(line, name): loss or model kind names compared (==, !=, in, not in) or matched (case)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for side in [node.left, *node.comparators]:
                found += [(node.lineno, n) for n in _names_in(side)]
        elif isinstance(node, ast.MatchValue):
            found += [(node.lineno, n) for n in _names_in(node.value)]
    return found


def test_no_kind_name_comparisons_outside_the_registry():
    offenders = [
        f"{p.relative_to(ROOT.parent)}:{line}: {name!r}"
        for p in SOURCES
        for line, name in _comparisons(ast.parse(p.read_text()))
    ]
    assert not offenders, (
        "loss or model kind names compared outside furuta_gym/training/loss_kinds.py "
        "(ask loss_kind(name) / model_kind(name) instead):\n" + "\n".join(offenders)
    )


def test_the_scan_finds_a_comparison():
    tree = ast.parse(
        'if loss == "prop" or kind in ("aph", "x"):\n    pass\n'
        'if (kind, "itau") not in pairs:\n    pass\n'
        'match k:\n    case "adln":\n        pass\n'
        'rows = {"dln": 1}\n'  # a table keyed by kind is data, not a comparison
    )
    assert sorted(n for _, n in _comparisons(tree)) == ["adln", "aph", "itau", "prop"]


def test_every_kind_is_complete():
    assert LOSSES == tuple(LOSS_KINDS) == ("traj", "aph", "prop", "itau")
    for name, kind in LOSS_KINDS.items():
        assert kind.name == name and isinstance(kind, LossKind) and kind.label
        assert kind.uses_trajectory or kind.uses_integral, f"{name}: a loss of nothing"
        assert kind.uses_trajectory or not (kind.weighs_trajectory_by_lambda or kind.penalises_augmentation), name
        assert kind.dual_ascent_step == 0.0 or kind.weighs_trajectory_by_lambda, f"{name}: steps a λ it has not"
    assert not INTEGRAL_ONLY.uses_trajectory and INTEGRAL_ONLY.uses_integral
    assert [k.name for k in LOSS_KINDS.values() if k.proposed] == [PROPOSED_LOSS]
    for name, cls in MODEL_KINDS.items():
        assert cls.kind == name and issubclass(cls, AbstractLearnedSystem) and cls.label
    with pytest.raises(ValueError, match="unknown loss 'props'"):
        loss_kind("props")
    with pytest.raises(ValueError, match="model kind must be one of .* got 'delan'"):
        model_kind("delan")


def test_the_cli_offers_every_kind():
    """The parser is built without importing training (fast --help), so it lists the names
    itself; they must be the registries'."""
    parser = argparse.ArgumentParser()
    cli_train.add_arguments(parser)
    choices = {a.dest: a.choices for a in parser._actions if a.choices is not None}
    assert list(choices["loss"]) == list(LOSS_KINDS)
    assert list(choices["model"]) == list(MODEL_KINDS)


def test_a_new_loss_is_one_class():
    """A loss registered by subclassing is a loss of the public step (and of train()), with its own
    objective: here L_traj counted twice, so its total is twice its trajectory term."""

    class _Twice(LossKind):
        name, label, uses_trajectory = "test_twice", "2·L_traj", True

        def objective(self, model, traj_b, int_b, lam, settings):
            total, terms = loss_kind("traj").objective(model, traj_b, int_b, lam, settings)
            terms["total"] = 2.0 * total
            return terms["total"], terms

    try:
        model = make_model("nmsd", "dln", jax.random.PRNGKey(0), hidden=(8, 8))
        config = TrainSettings(progress=False, fast_compile=True)
        step, params, opt_state = training_step(model, config, "test_twice")
        windows = make_windows(nmsd_chirp_segments(1.0)[:2], 3)
        _, _, terms, ok = step(params, opt_state, windows, None, jnp.asarray(0.0), jnp.asarray(1e-3))
        assert bool(ok) and float(terms["traj"]) > 0
        assert float(terms["total"]) == 2.0 * float(terms["traj"])
        with pytest.raises(ValueError, match="registered twice"):
            type("_Again", (LossKind,), {"name": "test_twice", "label": "x"})
    finally:
        del LOSS_KINDS["test_twice"]
    assert LOSSES == tuple(LOSS_KINDS)
