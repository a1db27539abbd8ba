"""The batched env's jitted step, shared by the env's own process and its worker processes.

:func:`step_function` builds (and caches) one jitted, vmapped step over a model structure and a
task; with ``packed=True`` it takes and returns one contiguous array (the workers' shared-memory
layout, :func:`packed_output_width` / :func:`unpack_outputs`).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..lagrangian import energy
from ..signals import quantize_joints
from ..simulate import small_kernel_compiler_options
from ._jax_rollout import controlled_step
from ._tasks import divergence_bounds

__all__ = ["Quantizer", "step_function", "packed_output_width", "unpack_outputs"]


@dataclasses.dataclass(frozen=True)
class Quantizer:
    """The env's encoder model as a hashable, jittable observation function (exact when 0)."""

    steps: tuple[float, ...]  # quantisation step per joint, 0 = exact

    def __call__(self, x):
        n = len(self.steps)
        return jnp.concatenate([quantize_joints(x[..., :n], self.steps), x[..., n:]], axis=-1)


_STEP_CACHE: dict = {}


def _batched_step(static, treedef, energy_treedef, *, dt, substeps, action_limit, task, quantizer, packed=False):
    """One jitted ``(model leaves, energy-model leaves, xs, us) -> outputs`` for a model structure
    and task; cached so a second vector env of the same model and settings does not recompile.
    Taking flat lists of arrays (not the Equinox modules) keeps the per-call dispatch cheap.

    ``packed=True`` (the worker processes' form): ``(leaves, energy leaves, [xs | us]) -> one
    float64 array`` of the outputs side by side (booleans as 0/1), one contiguous array in and one
    out instead of two strided inputs and seven outputs to copy every step."""
    key = (treedef, static, energy_treedef, dt, substeps, action_limit, task, quantizer, packed)
    try:
        return _STEP_CACHE[key]
    except (KeyError, TypeError):
        pass
    n_dof = len(quantizer.steps)

    def one(system, energy_model, x, u):
        out = controlled_step(
            system,
            x,
            u,
            dt=dt,
            substeps=substeps,
            action_limit=action_limit,
            state_bound=divergence_bounds(task.state_bound, system.spec.angular),
            reward_fn=task.reward,
            terminated_fn=task.terminated,
        )
        e = energy(energy_model, out.state[:n_dof], out.state[n_dof:])
        return out.state, quantizer(out.state), out.action, out.reward, out.terminated, out.diverged, e

    def step(leaves, energy_leaves, xs, us):
        system = eqx.combine(jax.tree_util.tree_unflatten(treedef, leaves), static)
        energy_model = jax.tree_util.tree_unflatten(energy_treedef, energy_leaves)
        return jax.vmap(one, in_axes=(None, None, 0, 0))(system, energy_model, xs, us)

    def packed_step(leaves, energy_leaves, block):  # layout: packed_output_width / unpack_outputs
        n_state = 2 * n_dof
        outs = step(leaves, energy_leaves, block[:, :n_state], block[:, n_state:])
        return jnp.concatenate([jnp.reshape(o, (block.shape[0], -1)).astype(block.dtype) for o in outs], axis=1)

    fn = jax.jit(packed_step if packed else step, compiler_options=small_kernel_compiler_options())
    try:
        _STEP_CACHE[key] = fn
    except TypeError:  # unhashable static structure: no sharing, still correct
        pass
    return fn


def packed_output_width(n_state: int, n_input: int) -> int:
    """Columns of the packed step's output: x_next, obs, u, reward, terminated, diverged, energy."""
    return 2 * n_state + n_input + 4


def unpack_outputs(block: np.ndarray, n_state: int, n_input: int) -> tuple[np.ndarray, ...]:
    """The packed step's output block as the unpacked step's seven arrays (copies)."""
    s, m = n_state, n_input
    return (
        block[:, :s].copy(),
        block[:, s : 2 * s].copy(),
        block[:, 2 * s : 2 * s + m].copy(),
        block[:, 2 * s + m].copy(),
        block[:, 2 * s + m + 1] != 0.0,
        block[:, 2 * s + m + 2] != 0.0,
        block[:, 2 * s + m + 3].copy(),
    )


def step_function(*, system, energy_model, dt, substeps, action_limit, task, quantizer, packed=False):
    """The jitted batched step ``(model leaves, energy leaves, xs, us) -> outputs`` of a vector env
    (``packed``: see :func:`_batched_step`) and its first two arguments. One function for the
    env's own process and its workers, so both compute the same thing."""
    dynamic, static = eqx.partition(system, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dynamic)
    energy_leaves, energy_treedef = jax.tree_util.tree_flatten(energy_model)
    fn = _batched_step(
        static,
        treedef,
        energy_treedef,
        dt=dt,
        substeps=substeps,
        action_limit=action_limit,
        task=task,
        quantizer=quantizer,
        packed=packed,
    )
    return fn, (leaves, energy_leaves)
