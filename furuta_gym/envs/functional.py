"""Functional envs: a model-backed env as pure JAX functions under gymnax's ``Environment`` API.

``make(env_id, dynamics=...)`` returns ``(env, params)`` like ``gymnax.make``: ``env.reset(key,
params)`` and ``env.step(key, state, action, params)`` are pure, so a whole training run —
rollouts, autoresets, updates — compiles into one ``jit`` and ``vmap`` batches copies
(PureJaxRL-style loops, :mod:`furuta_gym.rl`). Why gymnax and not brax's ``Env``: gymnax's API
carries explicit ``params`` (domain randomisation and sensor settings vary without recompiling)
and needs only ``flax`` besides JAX; brax would bring its physics engines to wrap a step that is
already a JAX function. Requires the ``[rl]`` extra (``pip install "furuta-gym[rl]"``).

The env is the Gymnasium env's own specification: :func:`make` builds the registered env (its
settings objects, task, spaces, horizon) and reads it; each step is the batched env's
:func:`~furuta_gym.envs._jax_rollout.controlled_step` (fixed-step RK4, input held, divergence
frozen) scored by the same task functions, and the observation is the same quantisation and
presentation (:func:`~furuta_gym.envs._observation.present_components`). The analytic Furuta
(also under a plant's effects) is integrated as :class:`~furuta_gym.models.FurutaSharedTrig`, the
same physics with sin β and cos β evaluated once per RK4 stage (XLA:CPU would otherwise recompute
them in every fused kernel that reads them, most of a step's time). Any JAX backend works:
``"analytic"``, a checkpoint path, a Lagrangian model, and the ``Plant`` variants that a model
backend runs with :class:`~furuta_gym.effects.WithEffects`.

What varies through :class:`EnvParams` (pass another, or ``vmap`` over several): the model's
arrays (a learned model's weights), the horizon, the start noise, the encoder quantisation step
per joint, the measurement noise (if the env was made with some) and the relative spread of each
physical parameter, drawn anew at every reset (domain randomisation; analytic models).
"""

from __future__ import annotations

from typing import Any, cast

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnax.environments import environment, spaces
from jaxtyping import Array, Bool, Float, Int, PyTree

from .._x64 import ensure_x64
from ..effects import WithEffects
from ..signals import quantize_joints
from ._backends import ModelBackend
from ._base import LagrangianEnv
from ._jax_rollout import controlled_step
from ._observation import present_components
from ._parameters import PARAMETER_CLASSES
from ._settings import EnvArgumentError
from ._tasks import divergence_bounds

__all__ = ["make", "FunctionalEnv", "EnvParams", "EnvState"]

#: what the functional env draws itself (through its params) of the single env's per-episode state
_SUPPORTED_FEATURES = ("measurement_noise", "randomize")


class EnvParams(eqx.Module):
    """The functional env's gymnax params: arrays that may change between calls without a new
    compilation (change one with ``dataclasses.replace``)."""

    model: PyTree  # the array half of the dynamics model (eqx.partition); the rest is the env's
    max_steps_in_episode: Int[Array, ""]  # truncation (gymnax's name)
    reset_noise_scale: Float[Array, ""]  # uniform start noise on every state component
    quantization: Float[Array, " n"]  # encoder step per joint (rad or m); 0: exact
    measurement_noise: Float[Array, " 2n"] | None  # Gaussian std per (q, q̇); None: made without
    spreads: PyTree | None  # relative spread per physical parameter; None: the model has none


class EnvState(eqx.Module):
    """One copy's episode: the true state, the step count, this episode's physical parameters."""

    x: Float[Array, " 2n"]
    time: Int[Array, ""]
    physical: PyTree | None  # the analytic model's parameters drawn at reset (None: learned model)
    diverged: Bool[Array, ""]


def _physical_of(model: Any):
    """The analytic parameters inside a model (under a ``WithEffects`` wrapper, its base's)."""
    base: Any = model.base if isinstance(model, WithEffects) else model
    return base.params


def _has_physical(model, system: str) -> bool:
    base = model.base if isinstance(model, WithEffects) else model
    return isinstance(getattr(base, "params", None), PARAMETER_CLASSES[system])


def _unsupported(template: LagrangianEnv) -> list[str]:
    """The template's settings a stateless functional copy does not reproduce."""
    features = [f for f in template.per_episode_state_features() if not f.startswith(_SUPPORTED_FEATURES)]
    if template._extra_observation_size():
        features.append("observation components beyond the state (an observed target)")
    if not isinstance(template.backend, ModelBackend):
        features.append("dynamics='mujoco' (not a JAX function: use 'analytic', a checkpoint or a model)")
    return features


class FunctionalEnv(environment.Environment[EnvState, EnvParams]):
    """A model-backed :class:`~furuta_gym.envs.LagrangianEnv` as a gymnax ``Environment``.

    Build it with :func:`make`. ``step`` (gymnax's) autoresets a copy whose episode ended and
    returns ``(obs, state, reward, terminated, truncated, info)``; ``terminated`` is the task's
    termination or a divergence (``info["diverged"]``: the state stays at the last good one, as
    the Gymnasium env does), ``truncated`` is ``time >= params.max_steps_in_episode``. Actions:
    the Gymnasium env's action space, clipped to it (a non-finite action is a divergence: a
    jitted policy cannot raise).
    """

    def __init__(self, template: LagrangianEnv, max_steps: int | None = None, name: str | None = None):
        unsupported = _unsupported(template)
        if unsupported:
            raise EnvArgumentError(f"the functional env does not support {', '.join(unsupported)}")
        ensure_x64()
        assert isinstance(template.backend, ModelBackend)  # _unsupported refuses MuJoCo
        model = template.backend.model
        dynamic, self._static = eqx.partition(model, eqx.is_array)
        self.system = template.system_spec.name
        self.angular = tuple(template.system_spec.angular)
        self.n = template.system_spec.n_dof
        self.dt, self.substeps = float(template.dt), int(template.frame_skip)
        self.task = template.task
        self.max_action = float(template.max_action)
        self.action_high = float(template.action_space.high[0])
        self.observation_layout = template.observation
        self.obs_dtype = np.dtype(template.dtype)
        self.bound = float(template.observation_bound)
        self.state_bounds = divergence_bounds(self.task.state_bound, self.angular)
        self._gym_observation_space = template.observation_space
        self._name = name or type(template).env_id
        self._default_params = self._params(template, dynamic, max_steps, model)

    def _params(self, template, dynamic, max_steps, model) -> EnvParams:
        """The template's settings as params."""
        horizon = template.max_episode_steps if max_steps is None else max_steps
        spreads = template.parameter_spreads
        physical = _has_physical(model, self.system)
        if spreads and not physical:
            raise EnvArgumentError("Plant.randomize draws an analytic model's physical parameters; this model has none")
        noise = template.noise_std
        return EnvParams(
            model=dynamic,
            max_steps_in_episode=jnp.asarray(np.iinfo(np.int32).max if horizon is None else horizon, jnp.int32),
            reset_noise_scale=jnp.asarray(template.reset_noise_scale, float),
            quantization=jnp.asarray(template.encoder_steps, float),
            measurement_noise=jnp.asarray(noise, float) if noise.any() else None,
            spreads=PARAMETER_CLASSES[self.system](**{k: spreads.get(k, 0.0) for k in template.physical_parameters()})
            if physical
            else None,
        )

    # ------------------------------------------------------------------ gymnax API
    @property
    def default_params(self) -> EnvParams:
        return self._default_params

    @property
    def name(self) -> str:
        return self._name

    @property
    def num_actions(self) -> int:
        return 1

    def action_space(self, params: EnvParams | None = None) -> spaces.Box:
        return spaces.Box(-self.action_high, self.action_high, (1,), self.obs_dtype)

    def observation_space(self, params: EnvParams | None = None) -> spaces.Box:
        box = self._gym_observation_space
        return spaces.Box(jnp.asarray(box.low), jnp.asarray(box.high), box.shape, self.obs_dtype)

    def reset_env(self, key: jax.Array, params: EnvParams) -> tuple[Array, EnvState]:
        """Near rest with uniform noise of ``params.reset_noise_scale``; new physical parameters."""
        key_x, key_physical, key_obs = jax.random.split(key, 3)
        scale = params.reset_noise_scale
        x0 = jax.random.uniform(key_x, (2 * self.n,), float, -scale, scale)
        state = EnvState(x0, jnp.zeros((), jnp.int32), self._draw_physical(key_physical, params), jnp.zeros((), bool))
        return self.get_obs(state, params, key_obs), state

    def step_env(self, key: jax.Array, state: EnvState, action, params: EnvParams):
        """One control period of the Gymnasium env's step (without its time limit)."""
        action = jnp.reshape(jnp.asarray(action, float), (1,))
        volts = jnp.clip(action, -self.action_high, self.action_high) * (self.max_action / self.action_high)
        out = controlled_step(
            self.plant(params, state),
            state.x,
            volts,
            dt=self.dt,
            substeps=self.substeps,
            action_limit=self.max_action,
            state_bound=self.state_bounds,
            reward_fn=self.task.reward,
            terminated_fn=self.task.terminated,
        )
        new = EnvState(out.state, state.time + 1, state.physical, out.diverged)
        info = {"diverged": out.diverged, "action": out.action[0]}
        return self.get_obs(new, params, key), new, out.reward, out.terminated, info

    def get_obs(self, state: EnvState, params: EnvParams | None = None, key: jax.Array | None = None) -> Array:
        """The Gymnasium env's observation of ``state.x``: quantised (and noisy) measurement,
        then its layout and dtype."""
        params = self.default_params if params is None else params
        x = state.x
        z = jnp.concatenate([quantize_joints(x[: self.n], params.quantization), x[self.n :]])
        if params.measurement_noise is not None and key is not None:
            z = z + params.measurement_noise * jax.random.normal(key, z.shape, z.dtype)
        if self.observation_layout == "raw":
            return z.astype(self.obs_dtype)
        parts = present_components(list(z), self.angular, self.observation_layout, self.bound, jnp)
        return jnp.stack(parts).astype(self.obs_dtype)

    def state_at(self, x, params: EnvParams | None = None) -> EnvState:
        """An episode's start at ``x`` with the nominal plant (the Gymnasium env's
        ``reset(options={"state": x})``)."""
        params = self.default_params if params is None else params
        physical = None if params.spreads is None else _physical_of(self.plant(params))
        return EnvState(jnp.asarray(x, float), jnp.zeros((), jnp.int32), physical, jnp.zeros((), bool))

    def is_terminated(self, state: EnvState, params: EnvParams) -> Array:
        return jnp.asarray(self.task.terminated(state.x), bool) | state.diverged

    # ------------------------------------------------------------------ the plant
    def plant(self, params: EnvParams, state: EnvState | None = None):
        """The dynamics model of ``params``, with ``state``'s physical parameters if it has some."""
        model = eqx.combine(params.model, self._static)
        if state is not None and state.physical is not None:
            model = eqx.tree_at(_physical_of, model, state.physical)
        return model

    def _draw_physical(self, key: jax.Array, params: EnvParams):
        """Each physical parameter p drawn uniformly in [(1 − s)·p, (1 + s)·p]."""
        if params.spreads is None:
            return None
        nominal = _physical_of(eqx.combine(params.model, self._static))
        leaves, treedef = jax.tree_util.tree_flatten(nominal)
        spreads = jax.tree_util.tree_leaves(params.spreads)
        draws = jax.random.uniform(key, (len(leaves),), float, -1.0, 1.0)
        drawn = [p * (1.0 + s * draws[i]) for i, (p, s) in enumerate(zip(leaves, spreads, strict=True))]
        return jax.tree_util.tree_unflatten(treedef, drawn)


def make(
    env_id: str = "furuta_gym/FurutaSwingUp-v0", dynamics: Any = "analytic", **kwargs
) -> tuple[FunctionalEnv, EnvParams]:
    """``(env, params)`` of the registered Gymnasium env ``env_id`` made with ``dynamics`` and
    ``kwargs`` (the same keywords as ``gymnasium.make``), as ``gymnax.make`` returns them.

    The horizon is the registration's ``max_episode_steps`` (the preset's 500) or the env's own
    ``Episode.seconds``. ``plant=Plant(randomize=...)`` and ``sensors=Sensors(...)`` set the
    default params' spreads, quantisation and noise.
    """
    if kernel := kwargs.pop("kernel", None):
        raise EnvArgumentError(
            f"kernel={kernel!r} chooses a single env's step kernel; the functional env is traced JAX"
        )
    if isinstance(dynamics, str) and dynamics == "mujoco":
        raise EnvArgumentError(
            "dynamics='mujoco' is not a JAX function: the functional env runs 'analytic', "
            "a checkpoint path or a Lagrangian model"
        )
    gym_env = gymnasium.make(env_id, dynamics=dynamics, kernel="xla", disable_env_checker=True, **kwargs)
    template = cast(LagrangianEnv, gym_env.unwrapped)
    env = FunctionalEnv(template, max_steps=gym_env.spec.max_episode_steps, name=env_id)
    return env, env.default_params
