"""The checkpoints committed under results/ still load into today's model classes, and mean what
they meant: a change to a model's fields (their order is the order of the saved leaves) or to its
forward pass breaks the reproduction's models, the learned controllers' dynamics and ``dynamics=``
for every user's saved file."""

from pathlib import Path

import jax
import numpy as np
import pytest

from furuta_gym.models import analytic_model, load_model

RESULTS = Path(__file__).resolve().parents[1] / "results"
REPRODUCTION = sorted(RESULTS.glob("reproduce/runs/*/*/seed0/model.eqx"))
REAL = sorted(RESULTS.glob("real_models*/runs/*/*.eqx"))


def _states(system: str, rng, count: int = 200):
    """States and inputs in the training data's range (docs/reproduce.md, "Data")."""
    if system == "furuta":
        return (rng.uniform(-np.pi, np.pi, (count, 2)), rng.uniform(-5, 5, (count, 2)), rng.uniform(-3, 3, (count, 1)))
    return rng.uniform(-1, 1, (count, 1)), rng.uniform(-5, 5, (count, 1)), rng.uniform(-5, 5, (count, 1))


def test_the_committed_checkpoints_are_found():
    assert len(REPRODUCTION) == 12, REPRODUCTION
    assert len(REAL) >= 4, REAL


@pytest.mark.parametrize("path", REPRODUCTION + REAL, ids=lambda p: str(p.relative_to(RESULTS)))
def test_a_committed_checkpoint_loads_and_predicts_finite_accelerations(path):
    model = load_model(path)
    q, qd, u = _states(model.spec.name, np.random.default_rng(0), 20)
    assert np.all(np.isfinite(jax.vmap(model.forward_dynamics)(q, qd, u)))


@pytest.mark.parametrize(
    "path", [p for p in REPRODUCTION if "_prop" in p.parts[-3]], ids=lambda p: "/".join(p.parts[-4:-2])
)
def test_a_reproduction_model_trained_with_l_prop_still_matches_the_true_system(path):
    """Measured when they were committed: 0.1–4 % relative RMS error of q̈ per joint; a field out
    of place or a changed forward pass gives errors of order one."""
    model = load_model(path)
    truth = analytic_model(model.spec.name)
    q, qd, u = _states(model.spec.name, np.random.default_rng(0))
    learned = jax.vmap(model.forward_dynamics)(q, qd, u)
    true = jax.vmap(truth.forward_dynamics)(q, qd, u)
    relative = np.sqrt(np.mean((learned - true) ** 2, axis=0) / np.mean(true**2, axis=0))
    assert np.all(relative < 0.1), relative


@pytest.mark.parametrize("path", REPRODUCTION, ids=lambda p: "/".join(p.parts[-4:-2]))
def test_a_committed_reproduction_run_is_todays_recipe(path):
    """The recipe is frozen: each committed reproduction run records the settings it was trained
    with, and they are what ``furuta-gym reproduce`` would train today. A recipe change that was
    not followed by training that model again fails here, not silently in the published tables."""
    import json

    from furuta_gym.training.reproduce import ReproduceSettings, run_settings, same_settings

    system, (kind, loss) = path.parts[-4], path.parts[-3].split("_")
    saved = json.loads((path.parent / "reproduce_config.json").read_text())
    assert same_settings(saved, run_settings(system, kind, loss, 0, ReproduceSettings())), path.parent
