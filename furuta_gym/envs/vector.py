"""Batched model-backed envs: N copies stepped by one jitted, vmapped JAX call.

:class:`FurutaVectorEnv` and :class:`NMSDVectorEnv` are :class:`gymnasium.vector.VectorEnv`\\ s
over a *model* backend (``dynamics="analytic"``, a checkpoint path, or any
:class:`~furuta_gym.lagrangian.AbstractLagrangianSystem`). Each step integrates all copies at once
with the single env's scheme (RK4 with the input held over the control period) and scores them
with the single env's pure task functions, so copy ``k`` behaves exactly like
``gymnasium.make("furuta_gym/Furuta-v0", dynamics=...)`` reset with ``seed + k`` and given the same
actions — including Gymnasium's next-step autoreset (:class:`gymnasium.vector.AutoresetMode`
``NEXT_STEP``, what :class:`~gymnasium.vector.SyncVectorEnv` does), truncation after
``episode_seconds`` and divergence (``terminated`` with ``info["diverged"]``, last good
observation, never NaN).

:meth:`LagrangianVectorEnv.rollout` runs a jittable policy for many steps with no Python in the
loop (:func:`rollout`, re-exported here from the private ``_jax_rollout``). The MuJoCo backend is
not a JAX function: vectorise it with Gymnasium's Sync/Async vector envs — :func:`make_vector_env`
(the registered ``vector_entry_point``) does that for ``dynamics="mujoco"``.
"""

from __future__ import annotations

import inspect
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, ClassVar, Sequence, cast

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..lagrangian import AbstractLagrangianSystem, energy
from ..models import analytic_model
from ._backends import ModelBackend
from ._base import LagrangianEnv
from ._batched_step import Quantizer, step_function
from ._jax_rollout import Rollout, map_chunks, rollout, scan_closed_loop, stepping_model
from ._parameters import PARAMETER_CLASSES
from ._settings import EnvArgumentError, check_int
from ._sharding import ShardedSteps, resolve_devices
from ._tasks import divergence_bounds
from ._workers import ProcessChunks
from .furuta import FurutaEnv
from .nmsd import NMSDEnv

__all__ = [
    "scan_closed_loop",
    "stepping_model",
    "LagrangianVectorEnv",
    "FurutaVectorEnv",
    "NMSDVectorEnv",
    "make_vector_env",
    "auto_chunks",
    "VECTOR_CLASSES",
    "furuta_vector_entry_point",
    "nmsd_vector_entry_point",
    "rollout",
    "Rollout",
]


def auto_chunks(num_envs: int, cores: int | None = None) -> int:
    """How many sub-batches :class:`LagrangianVectorEnv` steps concurrently in its own process by
    default (``workers=0``).

    One XLA:CPU execution of a few thousand copies does not keep every core busy, and concurrent
    sub-batches of 512–1024 copies raise the rate; from ~8192 copies one execution already
    spreads over the cores itself and splitting it costs (docs/batched.md "Speed").
    """
    cores = cores or os.cpu_count() or 1
    if num_envs >= 8192:
        return 1
    return max(1, min(2 * cores, num_envs // 512))


class _ConcurrentChunks:
    """Call the batched jitted step on contiguous sub-batches, concurrently from a thread pool.

    Why threads: JAX releases the GIL while an XLA computation runs, and XLA:CPU runs separate
    executions side by side. Each copy is computed on its own, so its numbers do not depend on
    the split (tests check it). The first call runs the sub-batches one after the other so each
    shape is compiled once, not raced by several threads.
    """

    def __init__(self, num_envs: int, chunks: int):
        self.num_envs, self.chunks = num_envs, chunks
        self._pool: ThreadPoolExecutor | None = None

    def __call__(self, fn, shared: tuple, *batched: np.ndarray) -> tuple[np.ndarray, ...]:
        if self.chunks == 1:
            return tuple(np.array(a) for a in fn(*shared, *batched))

        def part(a, b):
            return [np.asarray(r) for r in fn(*shared, *(x[a:b] for x in batched))]

        pool = self._pool  # None on the first call: compile in turn
        parts = map_chunks(part, self.num_envs, self.chunks, pool)
        if pool is None:
            self._pool = ThreadPoolExecutor(self.chunks, thread_name_prefix="furuta_gym-vector")
        return tuple(np.concatenate(outs) for outs in zip(*parts, strict=True))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


class LagrangianVectorEnv(VectorEnv):
    """N copies of a model-backed :class:`~furuta_gym.envs.LagrangianEnv`, stepped with ``jax.vmap``.

    Constructor: ``num_envs``, how to split the work (``autoreset_mode``, ``chunks``,
    ``workers``) and the single env's keywords, the same signature (``dynamics`` defaults to
    ``"analytic"`` here): ``plant`` without delay, ``episode``, ``actuation`` (its limit),
    ``sensors`` (``encoder_counts`` / ``position_resolution``), ``task``. Options that need
    per-copy Python state in the single env — ``measurement_noise``, ``velocity="filter"``,
    actuation delays, ``randomize`` — and rendering are rejected with a clear error: use
    ``gymnasium.make_vec(..., vectorization_mode="sync")`` for those.

    Semantics (the same as a :class:`~gymnasium.vector.SyncVectorEnv` of single envs):

    * ``reset(seed=s)`` seeds copy ``k`` with ``s + k`` (or a list of seeds), so its initial state
      is the single env's ``reset(seed=s + k)``; ``options={"state": x}`` starts every copy at ``x``
      (shape ``(2n,)``) or copy ``k`` at ``x[k]`` (shape ``(N, 2n)``); ``options={"reset_mask":
      mask}`` resets only the masked copies.
    * ``step(actions)``: actions of shape ``(N, 1)`` (or ``(N,)``), clipped to the limit; NaN/inf
      raises ``ValueError``. Next-step autoreset (default, Gymnasium's default): a copy whose
      episode ended at the previous step is reset instead of stepped (reward 0,
      ``terminated``/``truncated`` False, its reset info). ``autoreset_mode="SameStep"`` resets
      it within the ending step (its last observation and info in ``info["final_obs"]`` /
      ``info["final_info"]``); ``"Disabled"`` leaves resets to ``reset(options={"reset_mask":
      ...})``. Exactly as :class:`~gymnasium.vector.SyncVectorEnv` with that mode.
    * ``info``: ``time``, ``energy``, ``diverged``, ``state``, ``action`` (and ``target`` for
      N-MSD) as arrays over copies, each with its Gymnasium ``_key`` mask.

    Where the copies are computed (every choice gives each copy the same numbers):

    * ``workers=0`` (default): in this process. ``chunks`` sub-batches are stepped concurrently
      from a thread pool (default :func:`auto_chunks`: 4 at N = 4096 on 2 cores, 1 below 1024
      copies and from 8192 on).
    * ``workers=K``: K worker processes (fresh interpreters, ~3 s to start and compile), each
      stepping a contiguous slice with an XLA thread pool sized for one core; state and actions
      travel through shared memory. For thousands of copies on K cores, faster than the default in
      one process (docs/batched.md "Speed"). The
      model must pickle and be importable by name in a new interpreter; call :meth:`close` (or
      use the env as a context manager) to stop the workers — they also stop when the env is
      garbage-collected or Python exits.
    * ``devices=``: the copies split over JAX devices with :mod:`jax.sharding` (an int ``k``: the
      first ``k`` of :func:`jax.devices`; or a list of devices), one step running on all of them
      at once — several accelerators, or a CPU split into host devices with
      ``XLA_FLAGS=--xla_force_host_platform_device_count=K``. Not with ``chunks`` or ``workers``;
      :meth:`rollout` is not split over devices.
    """

    env_class: ClassVar[type[LagrangianEnv]]
    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int,
        dynamics: Any = "analytic",
        *,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        chunks: int | None = None,
        workers: int = 0,
        devices: Any = None,
        **env_kwargs,
    ):
        if devices is not None and (workers or chunks is not None):
            raise ValueError(
                f"devices= splits the copies over JAX devices; chunks= and workers= split them in "
                f"this process or over worker processes: pass one of them (got chunks={chunks!r}, "
                f"workers={workers!r})"
            )
        devices = resolve_devices(devices)
        chunks = self._check_arguments(num_envs, dynamics, workers, chunks, env_kwargs)
        # The single env is the specification: its validated settings, spaces, task and initial-
        # state distribution are what every copy uses. It never steps: no C kernel to build.
        env_kwargs["kernel"] = "xla"
        self._template = template = self.env_class(dynamics=dynamics, **env_kwargs)
        self._check_supported(template)
        backend = template.backend
        assert isinstance(backend, ModelBackend)
        self.num_envs = int(num_envs)
        self._chunked = (
            _ConcurrentChunks(self.num_envs, int(chunks)) if devices is None else ShardedSteps(self.num_envs, devices)
        )
        self.spec_system = template.system_spec
        self._n = template.system_spec.n_dof
        self.dt = template.dt
        self.frame_skip = template.frame_skip
        self.max_action = template.max_action
        self._max_steps = template.max_episode_steps
        self.system: AbstractLagrangianSystem = backend.model
        parameters = template.physical_parameters()
        analytic_params = PARAMETER_CLASSES[backend.system](**parameters)

        # energy in info is the paper's model at the plant's parameters, as the single env reports
        self._energy_model = eqx.tree_at(lambda m: m.params, analytic_model(backend.system), analytic_params)
        self._quantizer = Quantizer(tuple(float(s) for s in template.encoder_steps))
        self._workers = None
        self._set_task(template.task)
        if workers:
            self._workers = ProcessChunks(
                self.num_envs, int(workers), 2 * self._n, self.spec_system.n_inputs, self._step_settings()
            )

        self._init_spaces(template, autoreset_mode)

        n_state = 2 * self._n
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._x = np.zeros((self.num_envs, n_state))
        self._obs = np.zeros((self.num_envs, n_state))
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._needs_reset = True

    # ------------------------------------------------------------------ set-up helpers
    def _init_spaces(self, template: LagrangianEnv, autoreset_mode) -> None:
        """Batched copies of the template's spaces; the autoreset mode and the metadata."""
        self.single_observation_space = template.observation_space
        self.single_action_space = template.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(
                f"autoreset_mode must be one of {[m.value for m in AutoresetMode]} (or an "
                f"AutoresetMode), got {autoreset_mode!r}"
            ) from None
        self.metadata = {
            **type(self).metadata,
            "autoreset_mode": self.autoreset_mode,
            "render_fps": template.metadata["render_fps"],
        }
        self.render_mode = None

    @classmethod
    def _check_arguments(cls, num_envs, dynamics, workers, chunks, env_kwargs) -> int:
        """Refuse what a batched model env cannot do; returns the number of chunks."""
        check_int("num_envs", num_envs, 1)
        if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or not 0 <= workers <= num_envs:
            raise ValueError(
                f"workers must be an integer from 0 (step in this process) to num_envs = "
                f"{num_envs} (worker processes, each with a one-thread XLA pool), got {workers!r}"
            )
        if chunks is None:
            chunks = auto_chunks(int(num_envs)) if workers == 0 else 1
        elif isinstance(chunks, bool) or not isinstance(chunks, (int, np.integer)) or not 1 <= chunks <= num_envs:
            raise ValueError(
                f"chunks must be an integer from 1 to num_envs = {num_envs} (sub-batches stepped "
                f"concurrently) or None for auto ({auto_chunks(int(num_envs))} here), got {chunks!r}"
            )
        elif workers and chunks != 1:
            raise ValueError(
                f"chunks={chunks} splits the step inside this process; with workers={workers} "
                "each worker process steps its own slice: pass one of the two"
            )
        if isinstance(dynamics, str) and dynamics == "mujoco":
            raise ValueError(
                f"{cls.__name__} batches model backends with jax.vmap; dynamics='mujoco' is "
                f"not a JAX function. Use gymnasium.make_vec({cls._env_id()!r}, num_envs=N, "
                "vectorization_mode='sync' or 'async') for the MuJoCo ground truth, or "
                "dynamics='analytic', a checkpoint path or an AbstractLagrangianSystem here."
            )
        if env_kwargs.get("render_mode") is not None:
            raise ValueError(
                f"{cls.__name__} does not render; render a single env "
                f"(gymnasium.make({cls._env_id()!r}, render_mode=...)) or use "
                "gymnasium.make_vec(..., vectorization_mode='sync')"
            )
        if env_kwargs.get("kernel", "auto") != "auto":
            raise ValueError(
                f"kernel={env_kwargs['kernel']!r} chooses a single env's step kernel; "
                f"{cls.__name__} steps all copies in one vmapped XLA program (chunks= and "
                "workers= set how)"
            )
        return int(chunks)

    @classmethod
    def _env_id(cls) -> str:
        return cls.env_class.env_id

    def _check_supported(self, env: LagrangianEnv) -> None:
        unsupported = _unsupported_options(env)
        if unsupported:
            raise EnvArgumentError(
                f"{type(self).__name__} does not support {', '.join(unsupported)}; these need "
                f"per-copy state of the single env: use gymnasium.make_vec({self._env_id()!r}, "
                "num_envs=N, vectorization_mode='sync', ...) instead"
            )

    def _step_settings(self) -> dict[str, Any]:
        return dict(
            system=self.system,
            energy_model=self._energy_model,
            dt=self.dt,
            substeps=self.frame_skip,
            action_limit=self.max_action,
            task=self.task,
            quantizer=self._quantizer,
        )

    def _set_task(self, task) -> None:
        self.task = task
        self._step_fn, self._step_args = step_function(**self._step_settings())
        if self._workers is not None:
            self._workers.set_task(task)

    # ------------------------------------------------------------------ initial states
    def _seeded_rngs(self, seed) -> list[np.random.Generator]:
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + k for k in range(self.num_envs)]
        elif isinstance(seed, Sequence) and not isinstance(seed, str):
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed: a list of seeds must have num_envs={self.num_envs} entries, got {len(seeds)}")
        else:
            raise ValueError(f"seed must be None, an int or a list of num_envs ints, got {seed!r}")
        return [seeding.np_random(s)[0] for s in seeds]

    def _initial_states(self, idx: np.ndarray) -> np.ndarray:
        """Initial states of copies ``idx`` drawn from their own generators, as the single env."""
        out = np.empty((len(idx), 2 * self._n))
        for i, k in enumerate(idx):
            rng = self._rngs[k]
            if rng is None:  # never seeded: what the single env does on its first reset()
                rng = self._rngs[k] = seeding.np_random(None)[0]
            out[i] = self._template.sample_initial_state(rng)
        return out

    def _observe(self, xs: np.ndarray) -> np.ndarray:
        if not any(self._quantizer.steps):
            return xs.copy()
        return np.asarray(self._quantizer(jnp.asarray(xs)))

    def _energies(self, xs: np.ndarray) -> np.ndarray:
        n = self._n
        fn = _batched_energy(self._energy_model)
        return np.asarray(fn(self._energy_model, jnp.asarray(xs[:, :n]), jnp.asarray(xs[:, n:])))

    def _reset_info(self, idx: np.ndarray, xs: np.ndarray) -> dict[str, Any]:
        mask = np.zeros(self.num_envs, dtype=bool)
        mask[idx] = True
        full = lambda values, dtype: _scatter(self.num_envs, idx, values, dtype)  # noqa: E731
        info = {
            "time": full(np.zeros(len(idx)), np.float64),
            "energy": full(self._energies(xs), np.float64),
            "diverged": full(np.zeros(len(idx), dtype=bool), np.bool_),
            "state": _scatter(self.num_envs, idx, xs, np.float64),
            "action": full(np.zeros(len(idx)), np.float64),
        }
        info.update(self._extra_info(len(idx)))
        return _with_masks(info, mask)

    def _extra_info(self, count: int) -> dict[str, Any]:
        """System-specific constant info entries (N-MSD: the target)."""
        return {}

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed=None, options: dict | None = None):
        """Reset all copies (or ``options["reset_mask"]``); see the class docstring."""
        options = dict(options or {})
        mask = self._reset_mask(options.pop("reset_mask", None))
        allowed = set(self._template.reset_option_names)
        unknown = sorted(set(options) - allowed)
        if unknown:
            raise EnvArgumentError(
                f"reset: unknown option(s) {unknown}; expected any of {sorted(allowed | {'reset_mask'})}"
            )
        idx = np.flatnonzero(mask)
        if seed is not None or self._needs_reset:
            rngs = self._seeded_rngs(seed) if seed is not None else self._rngs
            for k in idx:
                self._rngs[k] = rngs[k]
        self._reset_options(options, partial=len(idx) < self.num_envs)
        state = options.get("state")
        x0 = self._initial_states(idx) if state is None else self._given_states(state, idx)
        if self._needs_reset and len(idx) < self.num_envs:
            raise ValueError("reset: the first reset must reset every copy (no reset_mask)")
        self._needs_reset = False
        self._x[idx] = x0
        obs = self._observe(x0)
        self._obs[idx] = obs
        self._steps[idx] = 0
        self._autoreset[idx] = False
        return self._obs.copy(), self._reset_info(idx, x0)

    def _reset_mask(self, mask) -> np.ndarray:
        """The copies a reset resets: ``options["reset_mask"]``, checked, or all of them."""
        if mask is None:
            return np.ones(self.num_envs, dtype=bool)
        mask = np.asarray(mask)
        if mask.shape != (self.num_envs,) or mask.dtype != np.bool_ or not mask.any():
            raise ValueError(
                f"options['reset_mask'] must be a bool array of shape ({self.num_envs},) with "
                f"at least one True, got {mask!r}"
            )
        return mask

    def _given_states(self, state, idx: np.ndarray) -> np.ndarray:
        """``options["state"]`` for the copies ``idx``: one state for all, or one per copy."""
        n_state = 2 * self._n
        x0 = np.asarray(state, dtype=np.float64)
        if x0.shape == (n_state,):
            x0 = np.broadcast_to(x0, (len(idx), n_state)).copy()
        elif x0.shape == (self.num_envs, n_state):
            x0 = x0[idx].copy()
        else:
            raise EnvArgumentError(
                f"options['state'] must have shape ({n_state},) or ({self.num_envs}, {n_state}) "
                f"= {self.spec_system.state_names} per copy, got shape {x0.shape}"
            )
        if not np.all(np.isfinite(x0)):
            raise EnvArgumentError("options['state'] must be finite")
        return x0

    def _reset_options(self, options: dict, partial: bool) -> None:
        """System-specific reset options (N-MSD: ``target``)."""

    def step(self, actions):
        """Step every copy once (next-step autoreset); returns batched (obs, reward, terminated,
        truncated, info)."""
        if self._needs_reset:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        us = self._checked_actions(actions)
        if self._workers is not None:
            x_next, obs, u, reward, terminated, diverged, e = self._workers.step(self._x, us)
        else:
            x_next, obs, u, reward, terminated, diverged, e = self._chunked(self._step_fn, self._step_args, self._x, us)
        reward = reward.astype(np.float64)
        mode = self.autoreset_mode
        resetting = self._autoreset if mode == AutoresetMode.NEXT_STEP else np.zeros_like(self._autoreset)
        if mode == AutoresetMode.DISABLED and self._autoreset.any():
            raise ValueError(
                f"autoreset_mode=DISABLED: copies {np.flatnonzero(self._autoreset)[:10].tolist()} "
                "ended their episode; reset them with reset(options={'reset_mask': mask}) first"
            )
        stepped = ~resetting
        steps = self._steps + stepped
        truncated = stepped & (self._max_steps is not None) & (steps >= (self._max_steps or 0))
        # a diverged copy keeps its last observation (already the frozen state's observation)
        action = u[:, 0].copy()
        final = final_obs = None
        if mode == AutoresetMode.SAME_STEP:
            resetting = terminated | truncated
            if resetting.any():
                final, final_obs = self._final_entries(steps, e, diverged, x_next, action, obs, resetting)
        if resetting.any():
            idx = np.flatnonzero(resetting)
            x0 = self._initial_states(idx)
            x_next[idx] = x0
            obs[idx] = self._observe(x0)
            diverged[idx] = False
            steps[idx] = 0
            action[idx] = 0.0
            e[idx] = self._energies(x0)
            if mode == AutoresetMode.NEXT_STEP:  # the reset *is* this step: nothing happened
                reward[idx] = 0.0
                terminated[idx] = False
                truncated[idx] = False
        self._x, self._obs, self._steps = x_next, obs, steps
        self._autoreset = terminated | truncated
        if mode == AutoresetMode.SAME_STEP:
            self._autoreset[:] = False
        info = self._step_info(steps, e, diverged, x_next, action, np.ones(self.num_envs, dtype=bool))
        if final is not None:
            info.update(final_obs=final_obs, _final_obs=resetting.copy())
            info.update(final_info=final, _final_info=resetting.copy())
        return obs.copy(), reward, terminated, truncated, info

    def _checked_actions(self, actions) -> np.ndarray:
        """The actions as a finite (num_envs, 1) float64 array (one number per copy also does)."""
        us = np.asarray(actions, dtype=np.float64)
        if us.shape == (self.num_envs,):
            us = us[:, None]
        if us.shape != (self.num_envs, 1):
            raise ValueError(
                f"actions must have shape ({self.num_envs}, 1) (one "
                f"{self.spec_system.input_names[0]} per copy), got shape {us.shape}"
            )
        bad = ~np.isfinite(us[:, 0])
        if bad.any():
            raise ValueError(
                f"actions must be finite (NaN/inf actions are rejected); copies "
                f"{np.flatnonzero(bad)[:10].tolist()} are not"
            )
        return us

    def _final_entries(self, steps, e, diverged, x, action, obs, ending) -> tuple[dict[str, Any], np.ndarray]:
        """SAME_STEP's final info and final observations of the copies ``ending`` this step."""
        final_obs = np.full(self.num_envs, None, dtype=object)
        for k in np.flatnonzero(ending):
            final_obs[k] = obs[k].copy()
        return self._step_info(steps, e, diverged, x, action, ending), final_obs

    def _step_info(self, steps, e, diverged, x, action, mask) -> dict[str, Any]:
        """Batched info (entries outside ``mask`` zeroed, as Gymnasium fills absent copies)."""
        info = {
            "time": steps * self.dt,
            "energy": e.copy(),
            "diverged": diverged.copy(),
            "state": x.copy(),
            "action": action.copy(),
        }
        info.update(self._extra_info(self.num_envs))
        if not mask.all():
            info = {
                k: np.where(mask.reshape((-1,) + (1,) * (v.ndim - 1)), v, 0).astype(v.dtype) for k, v in info.items()
            }
        return _with_masks(info, mask)

    # ------------------------------------------------------------------ pure-JAX rollouts
    def rollout(
        self,
        policy,
        steps: int,
        *,
        x0s=None,
        policy_state: Any = None,
    ) -> Rollout:
        """Run a jittable ``policy`` for ``steps`` control periods from ``x0s`` (default: the
        copies' current states) entirely in JAX, with this env's integration, clipping, task,
        encoder model and divergence handling; no autoreset, no truncation (see :func:`rollout`).
        Does not change the env's state."""
        if x0s is None:
            if self._needs_reset:
                raise gymnasium.error.ResetNeeded("call reset() before rollout() or pass x0s")
            x0s = self._x
        return rollout(
            self.system,
            policy,
            x0s,
            steps,
            dt=self.dt,
            substeps=self.frame_skip,
            action_limit=self.max_action,
            state_bound=divergence_bounds(self.task.state_bound, self.spec_system.angular),
            reward_fn=self.task.reward,
            terminated_fn=self.task.terminated,
            observation_fn=self._quantizer if any(self._quantizer.steps) else None,
            policy_state=policy_state,
        )

    @property
    def states(self) -> np.ndarray:
        """True states of all copies, shape (N, 2n) (a copy)."""
        return self._x.copy()

    def render(self):
        raise ValueError(f"{type(self).__name__} does not render; render a single env instead")

    @property
    def chunks(self) -> int:
        """Sub-batches stepped concurrently in this process (``chunks=``; see :func:`auto_chunks`)."""
        return self._chunked.chunks

    @property
    def devices(self) -> tuple | None:
        """JAX devices the copies are split over (``devices=``; ``None``: not split over devices)."""
        return getattr(self._chunked, "devices", None)

    @property
    def workers(self) -> int:
        """Worker processes stepping the copies (``workers=``; 0 = this process)."""
        return 0 if self._workers is None else self._workers.workers

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> bool:
        self.close()
        return False

    def close_extras(self, **kwargs):
        # also called (from VectorEnv.__del__) on an env whose __init__ refused its arguments
        for part in ("_workers", "_chunked", "_template"):
            if getattr(self, part, None) is not None:
                getattr(self, part).close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(num_envs={self.num_envs}, dynamics={type(self.system).__name__})"


def _with_env_keywords(init):
    """``init``'s signature with the single env's keywords in place of its ``**env_kwargs``: the
    keywords are written once, on :meth:`LagrangianEnv.__init__`."""
    own = [p for p in inspect.signature(init).parameters.values() if p.kind is not p.VAR_KEYWORD]
    names = {p.name for p in own}
    env = [
        p
        for name, p in inspect.signature(LagrangianEnv.__init__).parameters.items()
        if name != "self" and name not in names
    ]
    init.__signature__ = inspect.Signature(own + env)
    return init


_with_env_keywords(LagrangianVectorEnv.__init__)


_ENERGY_CACHE: dict = {}


def _batched_energy(model):
    key = jax.tree_util.tree_structure(model)
    fn = _ENERGY_CACHE.get(key)
    if fn is None:
        fn = _ENERGY_CACHE[key] = jax.jit(jax.vmap(energy, in_axes=(None, 0, 0)))
    return fn


def _scatter(n: int, idx: np.ndarray, values, dtype) -> np.ndarray:
    values = np.asarray(values, dtype=dtype)
    out = np.zeros((n,) + values.shape[1:], dtype=dtype)
    out[idx] = values
    return out


def _with_masks(info: dict[str, Any], mask: np.ndarray) -> dict[str, Any]:
    out = {}
    for key, value in info.items():
        out[key] = value
        out[f"_{key}"] = mask.copy()
    return out


class FurutaVectorEnv(LagrangianVectorEnv):
    """Batched ``furuta_gym/Furuta-v0`` over a model backend (see :class:`LagrangianVectorEnv`)."""

    env_class: ClassVar[type[LagrangianEnv]] = FurutaEnv


class NMSDVectorEnv(LagrangianVectorEnv):
    """Batched ``furuta_gym/NMSD-v0`` over a model backend; one ``target`` for all copies
    (``target=`` keyword, or ``reset(options={"target": ...})`` of every copy)."""

    env_class: ClassVar[type[LagrangianEnv]] = NMSDEnv

    def _reset_options(self, options, partial):
        if options.get("target") is not None:
            if partial:
                raise EnvArgumentError(
                    "options['target'] changes the task of every copy: pass it to a full reset (no reset_mask)"
                )
            self._template.apply_reset_options(options)
            self._set_task(self._template.task)

    def _extra_info(self, count):
        return {"target": np.full(self.num_envs, float(self.task.target))}


#: The batched env of each single env (``make_vector_env`` picks by the env's id).
VECTOR_CLASSES: tuple[type[LagrangianVectorEnv], ...] = (FurutaVectorEnv, NMSDVectorEnv)

#: ``gymnasium.make_vec``'s default for a model backend: Gymnasium's SyncVectorEnv of single envs
#: (each with its compiled step kernel) below this many copies, the batched JAX env from here on —
#: where one vmapped XLA step overtakes N kernel calls (bench/vector_crossover.py).
BATCHED_FROM = 32


def make_vector_env(
    env_id: str, num_envs: int, dynamics: Any = "mujoco", *, batched: bool | None = None, **kwargs
) -> VectorEnv:
    """A vector env for ``env_id`` (the registered ``vector_entry_point`` of ``gymnasium.make_vec``).

    ``batched=True``: the batched JAX env (:class:`FurutaVectorEnv` / :class:`NMSDVectorEnv`, model
    backends only); ``False``: a :class:`~gymnasium.vector.SyncVectorEnv` of single envs. ``None``
    (default) picks the faster one that supports the options: sync for ``dynamics="mujoco"``, for
    fewer than :data:`BATCHED_FROM` copies and for options the batched env does not reproduce
    (sensor noise, delays, ``observation="trig"``, …); batched otherwise, and whenever
    ``chunks=``, ``workers=`` or ``devices=`` is given. Both give each copy the same numbers.
    """
    classes = {cls.env_class.env_id: cls for cls in VECTOR_CLASSES}
    if env_id not in classes:
        raise ValueError(f"env_id must be one of {sorted(classes)}, got {env_id!r}")
    if batched not in (None, True, False):
        raise ValueError(f"batched must be True, False or None (choose by speed), got {batched!r}")
    autoreset_mode = kwargs.pop("autoreset_mode", AutoresetMode.NEXT_STEP)
    if "devices" in kwargs and kwargs["devices"] is None:  # the default: splits nothing
        del kwargs["devices"]
    split = sorted({"chunks", "workers", "devices"} & set(kwargs))
    if batched is None:
        mujoco = isinstance(dynamics, str) and dynamics == "mujoco"
        batched = not mujoco and (bool(split) or _batched_is_faster(env_id, int(num_envs), dynamics, kwargs))
    if batched:
        return classes[env_id](num_envs, dynamics=dynamics, autoreset_mode=autoreset_mode, **kwargs)
    if split:
        raise ValueError(
            f"{', '.join(split)}= split(s) the batched JAX env of a model backend; "
            "a SyncVectorEnv of single envs (dynamics='mujoco' or batched=False) takes neither"
        )
    return gymnasium.vector.SyncVectorEnv(
        [lambda: gymnasium.make(env_id, dynamics=dynamics, **kwargs)] * int(num_envs),
        autoreset_mode=autoreset_mode,
    )


def _batched_is_faster(env_id: str, num_envs: int, dynamics: Any, kwargs: dict) -> bool:
    """Whether the batched env is the default for a model backend: enough copies, options it supports."""
    if num_envs < BATCHED_FROM:
        return False
    if kwargs.get("render_mode") is not None or kwargs.get("kernel", "auto") != "auto":
        return False
    template = gymnasium.make(env_id, dynamics=dynamics, **kwargs).unwrapped
    return not _unsupported_options(cast(LagrangianEnv, template))


def _unsupported_options(env: LagrangianEnv) -> list[str]:
    """What of a single env's configuration the batched env cannot reproduce (empty: all of it)."""
    unsupported = env.per_episode_state_features() + env.presentation_options()
    if not isinstance(env.backend, ModelBackend):
        unsupported.append(f"backend {type(env.backend).__name__}")
    return unsupported


def furuta_vector_entry_point(num_envs: int = 1, **kwargs) -> VectorEnv:
    """``vector_entry_point`` of ``furuta_gym/Furuta-v0`` (see :func:`make_vector_env`)."""
    return make_vector_env(FurutaEnv.env_id, num_envs, **kwargs)


def nmsd_vector_entry_point(num_envs: int = 1, **kwargs) -> VectorEnv:
    """``vector_entry_point`` of ``furuta_gym/NMSD-v0`` (see :func:`make_vector_env`)."""
    return make_vector_env(NMSDEnv.env_id, num_envs, **kwargs)
