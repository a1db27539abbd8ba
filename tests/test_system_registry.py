"""Every system is complete in every layer (issue 26: "a third system would be one new module" per
layer, registered in one place each): a system added to ``furuta_gym.systems.SYSTEMS`` but
missing its definition, its data, its env, its MJCF or its recipe rows fails here, naming the
part; and each layer's per-system tables are views of its registry, never a second list."""

import dataclasses

import pytest

import furuta_gym
from furuta_gym.assets import asset_path
from furuta_gym.envs import ENV_CLASSES, ENV_IDS, PLANT_PRESETS, LagrangianEnv
from furuta_gym.envs.vector import VECTOR_CLASSES
from furuta_gym.measured import SPLIT_SECONDS
from furuta_gym.models import SYSTEM_DEFINITIONS
from furuta_gym.systems import SYSTEMS
from furuta_gym.training.datagen import DATASET_NAMES, SYSTEM_DATA, VALIDATION_NAMES, recipe_for
from furuta_gym.training.recipe import PAPER_SCHEDULE, QUICK_EPOCHS, QUICK_PROP_EPOCHS, SYSTEM_ROWS
from furuta_gym.training.reproduce import METRIC_COLUMNS, TEST_SETS, VALIDATION_SETS

furuta_gym.enable_x64()


def test_every_registry_lists_exactly_the_systems():
    registries = {
        "models SYSTEM_DEFINITIONS": set(SYSTEM_DEFINITIONS),
        "training SYSTEM_DATA": set(SYSTEM_DATA),
        "envs ENV_CLASSES": {cls.system for cls in ENV_CLASSES},
        "recipe SYSTEM_ROWS": set(SYSTEM_ROWS),
        "recipe PAPER_SCHEDULE": set(PAPER_SCHEDULE),
        "recipe QUICK_EPOCHS": set(QUICK_EPOCHS),
        "recipe QUICK_PROP_EPOCHS": set(QUICK_PROP_EPOCHS),
    }
    wrong = {where: sorted(names ^ set(SYSTEMS)) for where, names in registries.items() if names != set(SYSTEMS)}
    assert not wrong, f"systems missing or extra (vs {sorted(SYSTEMS)}): {wrong}"
    assert len(SYSTEMS) == 2


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_each_system_is_complete_in_every_layer(name):
    spec = SYSTEMS[name]
    definition, data = SYSTEM_DEFINITIONS[name], SYSTEM_DATA[name]
    assert definition.spec is spec and data.system == name
    assert asset_path(f"{name}.xml").is_file()
    envs = [cls for cls in ENV_CLASSES if cls.system == name]
    assert len(envs) == 1, f"{name}: {len(envs)} env classes in ENV_CLASSES, expected one"
    env_class = envs[0]
    assert issubclass(env_class, LagrangianEnv) and "nominal" in env_class.plant_presets
    assert [v.env_class for v in VECTOR_CLASSES if v.env_class.system == name] == [env_class]
    # the data recipe makes every dataset it names, and the reproduction evaluates some of them
    recipe = recipe_for(name, small=True)
    assert isinstance(recipe, data.recipe) and dataclasses.is_dataclass(recipe)
    assert data.test_names[0] == "train"
    assert set(data.test_labels.values()) <= set(data.test_names)
    assert set(data.validation_labels.values()) <= set(data.validation_names)
    assert {data.forced_set, data.energy_set} <= set(data.test_names)
    assert len(data.state_labels) == 2 * spec.n_dof
    # a recipe row for the baseline and for L_prop
    assert set(SYSTEM_ROWS[name]) == {"baseline", "prop"}


def test_per_system_tables_are_views_of_the_registries():
    assert ENV_IDS == {cls.system: cls.env_id for cls in ENV_CLASSES}
    assert PLANT_PRESETS == {cls.system: dict(cls.plant_presets) for cls in ENV_CLASSES}
    assert DATASET_NAMES == {n: d.test_names for n, d in SYSTEM_DATA.items()}
    assert VALIDATION_NAMES == {n: d.validation_names for n, d in SYSTEM_DATA.items()}
    assert TEST_SETS == {n: dict(d.test_labels) for n, d in SYSTEM_DATA.items()}
    assert VALIDATION_SETS == {n: dict(d.validation_labels) for n, d in SYSTEM_DATA.items()}
    assert SPLIT_SECONDS == {n: d.elementary_seconds for n, d in SYSTEM_DEFINITIONS.items()}
    # metrics: each state variable's error, then the physics terms
    assert METRIC_COLUMNS["furuta"][:4] == ("alpha", "beta", "alpha_dot", "beta_dot")
    assert METRIC_COLUMNS["nmsd"][:2] == ("p", "p_dot")


def test_a_registered_env_makes_and_steps_under_its_id():
    import gymnasium as gym
    import numpy as np

    for cls in ENV_CLASSES:
        env = gym.make(cls.env_id, dynamics="analytic")
        assert isinstance(env.unwrapped, cls)
        obs, _ = env.reset(seed=0)
        obs2, *_ = env.step(np.zeros(env.action_space.shape))
        assert obs2.shape == obs.shape and np.all(np.isfinite(obs2))
        assert gym.spec(cls.env_id).vector_entry_point == cls.vector_entry_point
        env.close()
