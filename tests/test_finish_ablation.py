"""furuta_gym.diagnose.finish_ablation: the folds follow the diagnosis' held-out split, and the
friction laws an ablation swaps in behave as named (MuJoCo's soft friction loss lets a loaded
joint creep where the diagnosis' Karnopp law holds it)."""

import types

import jax.numpy as jnp
import numpy as np

import furuta_gym
from furuta_gym.diagnose.finish_ablation import MUJOCO_IMPEDANCE, fold_of, soft_friction_dynamics
from furuta_gym.lagrangian import forward_dynamics, forward_dynamics_with_dry_friction
from furuta_gym.models import Furuta

furuta_gym.enable_x64()


def test_folds_are_every_third_segment_of_a_log():
    names = ["run01[0]", "run01[1]", "run01[2]", "run01[5]", "run02/2[11]"]
    assert [fold_of(types.SimpleNamespace(name=n)) for n in names] == [0, 1, 2, 2, 2]


def test_soft_friction_loss_creeps_where_karnopp_holds():
    model = Furuta()
    q, qd, u = jnp.array([0.0, 0.0]), jnp.zeros(2), jnp.array([0.5])
    limit = jnp.array([1.0, 1.0])  # far above what the input and gravity ask of either joint
    free = np.asarray(forward_dynamics(model, q, qd, u))
    held = np.asarray(forward_dynamics_with_dry_friction(model, limit, q, qd, u, 1e-3))
    soft = np.asarray(soft_friction_dynamics(model, limit, q, qd, u))
    assert abs(free[0]) > 1.0
    assert np.all(np.abs(held) < 1e-6 * abs(free[0]))
    # the constraint supplies only the impedance's share of the holding force: the rest moves it
    assert 0.5 * (1 - MUJOCO_IMPEDANCE) < soft[0] / free[0] < 2.0 * (1 - MUJOCO_IMPEDANCE)
