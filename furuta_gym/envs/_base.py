"""The env algorithm shared by every system: a task over a dynamics backend, plus sensors.

:class:`LagrangianEnv` holds no physics and no MuJoCo: it validates the action, applies the
actuation delay, asks its :class:`~furuta_gym.envs._backends.AbstractBackend` for the next state,
checks for divergence, scores the transition with its task's pure reward, and turns the true state
into an observation through the sensor model (encoder quantisation, noise, derivative-filter
velocity). Concrete envs (:mod:`furuta_gym.envs.furuta`, :mod:`furuta_gym.envs.nmsd`) only declare
the system, the task, the defaults and the camera.
"""

from __future__ import annotations

import collections
import math
import os
import sys
from typing import Any, ClassVar, Mapping, Sequence

import gymnasium
import numpy as np
from gymnasium import spaces

from ..effects import ActuatorLag, Effect
from ..models import system_definition
from ..signals import DerivativeFilter, quantize_joints
from ..systems import get_spec
from ._backends import AbstractBackend, make_backend
from ._config import Actuation, EnvArgumentError, Sensors, check_int
from ._parameters import (
    default_parameters,
    parse_randomization,
    randomize_parameters,
    resolve_effects,
)
from ._tasks import divergence_bounds, wrap_angle

#: the accepted ``observation=`` values (see :meth:`LagrangianEnv._present`)
OBSERVATIONS = ("raw", "wrapped", "trig")

__all__ = ["LagrangianEnv", "EnvArgumentError"]


def _check_observation(observation: str, angular: Sequence[bool], system: str) -> str:
    if observation not in OBSERVATIONS:
        raise EnvArgumentError(f"observation must be one of {list(OBSERVATIONS)}, got {observation!r}")
    if observation != "raw" and not any(angular):
        raise EnvArgumentError(
            f"observation={observation!r} wraps angles, but {system} has no angular joint; "
            "use observation='raw'"
        )
    return observation


def _check_dtype(dtype: Any) -> np.dtype:
    try:
        value = np.dtype(dtype)
    except TypeError:
        value = None
    if value not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise EnvArgumentError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    return value


def env_arguments(local_variables: dict) -> dict:
    """A subclass ``__init__``'s ``locals()`` as the keywords of :meth:`LagrangianEnv.__init__`."""
    return {k: v for k, v in local_variables.items() if k not in ("self", "__class__")}


class LagrangianEnv(gymnasium.Env):
    """Base of the furuta_gym envs (see :class:`furuta_gym.envs.FurutaEnv` for the user docs).

    Subclasses set :attr:`system`, :attr:`env_id` and :attr:`plant_presets`, declare their
    keywords in ``__init__`` and implement :meth:`_make_task`, :meth:`_initial_state`,
    :meth:`_energy` and optionally :meth:`_update_scene`.
    """

    metadata: ClassVar[dict] = {"render_modes": ["human", "rgb_array"], "render_fps": 50}

    system: ClassVar[str]
    #: its Gymnasium id (``register_envs`` registers every class of ``ENV_CLASSES`` under it)
    env_id: ClassVar[str]
    #: ``gymnasium.make_vec``'s entry point ("module:function"; the string Gymnasium can
    #: serialise), ``None`` for Gymnasium's own vector envs of single envs
    vector_entry_point: ClassVar[str | None] = None
    #: named plant variants (``plant=``): the ground truth plus effects the textbook model lacks
    plant_presets: ClassVar[Mapping[str, tuple[Effect, ...]]] = {"nominal": ()}
    #: the keyword of the action limit (volts or newtons)
    action_limit_name: ClassVar[str]
    #: task-specific keywords, handed to :meth:`_make_task`
    task_keywords: ClassVar[tuple[str, ...]] = ()
    #: other system-specific keywords, handed to :meth:`_configure`
    extra_keywords: ClassVar[tuple[str, ...]] = ()
    default_camera_config: ClassVar[dict[str, Any]] = {}

    def __init__(self, **kwargs):
        """Subclasses declare every keyword with its type and default in their own ``__init__``
        (what ``help()`` and IDEs show) and hand them all here with :func:`env_arguments`."""
        unexpected = kwargs.pop("unexpected", {})
        if unexpected:
            raise EnvArgumentError(
                f"{type(self).__name__}: unknown keyword argument(s) {sorted(unexpected)}; expected any of "
                f"{sorted(kwargs)}"
            )
        cfg = kwargs
        self._init_kwargs = dict(kwargs)  # for pickling: rebuilt from the constructor keywords
        self._spec = get_spec(self.system)
        self._definition = system_definition(self.system)
        self._n = self._spec.n_dof
        self._init_control(cfg)
        self._init_physics(cfg)
        self._init_actuation(cfg)
        self._init_sensors(cfg)
        self._init_presentation(cfg)
        self._task_kwargs = {k: cfg[k] for k in self.task_keywords}
        self.task = self._make_task(**self._task_kwargs)
        self.action_space = spaces.Box(-self._action_high, self._action_high, (1,), dtype=self.dtype)
        self.observation_space = self._observation_space()
        self._init_episode(cfg)
        self._init_rendering(cfg)
        self._zero_action = np.zeros(1)
        self._on_parameters(self.physical_parameters())
        self._reset_episode(self._initial_state(None))

    def _init_control(self, cfg) -> None:
        """Control rate and limits."""
        self.frame_skip = check_int("frame_skip", cfg["frame_skip"], 1)
        self.max_action = float(cfg[self.action_limit_name])
        if not (np.isfinite(self.max_action) and self.max_action > 0):
            raise EnvArgumentError(
                f"{self.action_limit_name} must be a positive finite number, got {self.max_action!r}"
            )
        self.reset_noise_scale = float(cfg["reset_noise_scale"])
        if not (np.isfinite(self.reset_noise_scale) and self.reset_noise_scale >= 0):
            raise EnvArgumentError(
                f"reset_noise_scale must be >= 0, got {cfg['reset_noise_scale']!r}"
            )

    def _init_physics(self, cfg) -> None:
        """The plant's effects, its randomisation and the dynamics backend."""
        self.effects: tuple[Effect, ...] = resolve_effects(
            self.system, cfg["plant"], cfg["effects"], self.plant_presets)
        self._randomize = parse_randomization(self.system, cfg["randomize"])
        self.backend: AbstractBackend = make_backend(
            self.system, cfg["dynamics"], substeps=self.frame_skip, effects=self.effects, kernel=cfg["kernel"]
        )
        if self._randomize:
            self.backend.set_parameters(self.backend.parameters)  # fail now, not at reset
        self._nominal_parameters = self.backend.parameters
        self.dt = self.backend.control_dt
        self.timestep = self.backend.timestep

    def _init_actuation(self, cfg) -> None:
        """Actuation delay (whole RK4 substeps) and actuator lag."""
        self.actuation = Actuation.from_arguments(self.effects, self.timestep, self.frame_skip,
                                                  cfg["actuation_delay"], cfg["actuation_delay_steps"])
        self._delay_periods, self._delay_substeps = divmod(self.actuation.delay_substeps, self.frame_skip)
        self._has_delay = self.actuation.delay_substeps > 0
        # MuJoCo integrates the lag (actuator dynamics); for a model backend this env applies it
        # after the delay, exactly per (part of a) period: see _actuate
        self._lag_tau = self.actuation.lag
        self._lag = (
            ActuatorLag(self._lag_tau, len(self._spec.input_names))
            if self._lag_tau > 0 and not self.backend.native_actuator_lag
            else None
        )

    def _init_sensors(self, cfg) -> None:
        """Encoder quantisation, measurement noise and the velocity the observation carries."""
        self.sensors = Sensors.from_arguments(self._spec, cfg["encoder_counts"], cfg["position_resolution"],
                                              cfg["measurement_noise"], cfg["velocity"])
        self._quant = np.array(self.sensors.quantization)
        self._noise = np.array(self.sensors.noise)
        self.velocity = self.sensors.velocity
        self._filter = DerivativeFilter(self.dt, self._n) if self.velocity == "filter" else None
        self._exact_sensors = self.sensors.exact

    def _init_presentation(self, cfg) -> None:
        """Observation layout, dtype, action scale and the system's own keywords."""
        self.observation = _check_observation(cfg["observation"], self._spec.angular, self.system)
        self.dtype = _check_dtype(cfg["dtype"])
        if not isinstance(cfg["normalize_action"], (bool, np.bool_)):
            raise EnvArgumentError(f"normalize_action must be a bool, got {cfg['normalize_action']!r}")
        self.normalize_action = bool(cfg["normalize_action"])
        self._action_high = 1.0 if self.normalize_action else self.max_action
        self._configure(**{k: cfg[k] for k in self.extra_keywords})
        # obs is the backend's state array itself: no sensor model, raw, float64
        self._exact_observation = (
            self._exact_sensors
            and self.observation == "raw"
            and self.dtype == np.float64
            and not self._extra_observation_size()
        )

    def _init_episode(self, cfg) -> None:
        seconds = cfg["episode_seconds"]
        if seconds is not None and not (np.isfinite(seconds) and seconds > 0):
            raise EnvArgumentError(f"episode_seconds must be > 0 or None, got {seconds!r}")
        self.episode_seconds = seconds
        self._max_steps = None if seconds is None else int(round(seconds / self.dt))

    def _init_rendering(self, cfg) -> None:
        render_mode = cfg["render_mode"]
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvArgumentError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        if (
            render_mode == "human"
            and sys.platform.startswith("linux")
            and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
        ):
            # GLFW would abort the whole process (an assertion in C) without a display
            raise EnvArgumentError(
                "render_mode='human' opens a window and needs a display (DISPLAY/WAYLAND_DISPLAY "
                "are unset); use render_mode='rgb_array' on a headless machine"
            )
        self.render_mode = render_mode
        self.width, self.height = int(cfg["width"]), int(cfg["height"])
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self.dt))}
        self._renderer = None

    @property
    def task(self):
        """The task (reward and termination as pure functions); see :mod:`._tasks`."""
        return self._task

    @task.setter
    def task(self, task) -> None:
        self._task = task
        # bound once: the step calls them without attribute lookups
        self._reward, self._terminated = task.reward, task.terminated
        self._state_bound = float(task.state_bound)
        # angles are never bounded: a rotor may turn for ever (only a non-finite angle diverges)
        self._bounds = divergence_bounds(task.state_bound, self._spec.angular)

    # ------------------------------------------------------------------ read-only settings
    # (what a batched copy of this env needs to know; see vector.py)
    @property
    def system_spec(self):
        """The system's :class:`~furuta_gym.lagrangian.SystemSpec` (joints, state and input names)."""
        return self._spec

    @property
    def encoder_steps(self) -> np.ndarray:
        """Quantisation step of each measured joint position (0: exact), in rad or m."""
        return self._quant.copy()

    def presentation_options(self) -> list[str]:
        """The configured non-default observation / action presentation (``observation``,
        ``dtype``, ``normalize_action``): what the batched JAX env does not reproduce."""
        options = []
        if self.observation != "raw":
            options.append(f"observation={self.observation!r}")
        if self.dtype != np.float64:
            options.append(f"dtype={self.dtype.name!r}")
        if self.normalize_action:
            options.append("normalize_action=True")
        return options

    @property
    def max_episode_steps(self) -> int | None:
        """env.steps before truncation (None: never truncated)."""
        return self._max_steps

    def per_episode_state_features(self) -> list[str]:
        """The configured sensor / plant options whose effect depends on more than the state and
        the step count (random draws or a signal history): what a stateless batched copy cannot
        reproduce. Empty for a deterministic, memoryless env."""
        features = []
        if np.any(self._noise):
            features.append("measurement_noise")
        if self._filter is not None:
            features.append("velocity='filter'")
        if self._has_delay:
            features.append("actuation delay (actuation_delay, actuation_delay_steps, "
                            "plant='delay' or an input_delay effect)")
        if self._lag_tau > 0:
            features.append("actuator_lag (the lagged input is a state)")
        if self._randomize:
            features.append("randomize")
        return features

    def sample_initial_state(self, rng: np.random.Generator | None) -> np.ndarray:
        """A start state drawn from this env's initial-state distribution with ``rng`` (what
        :meth:`reset` draws with its own generator; the nominal start without ``rng``)."""
        return self._initial_state(rng)

    def apply_reset_options(self, options: Mapping[str, Any]) -> None:
        """Apply the system-specific reset options (``reset_option_names`` other than ``state``,
        e.g. N-MSD's ``target``) to the task without starting an episode; unknown keys are an
        error."""
        unknown = sorted(set(options) - set(self.reset_option_names))
        if unknown:
            raise EnvArgumentError(
                f"unknown reset option(s) {unknown}; expected any of {sorted(self.reset_option_names)}"
            )
        self._options(options)

    # ------------------------------------------------------------------ subclass hooks
    def _make_task(self, **task_kwargs):
        raise NotImplementedError

    def _initial_state(self, rng: np.random.Generator | None) -> np.ndarray:
        """Nominal start plus uniform noise of ``reset_noise_scale`` (no noise without rng)."""
        x0 = np.zeros(2 * self._n)
        if rng is not None and self.reset_noise_scale > 0:
            x0 += rng.uniform(-self.reset_noise_scale, self.reset_noise_scale, x0.shape)
        return x0

    def _energy(self, x: Sequence[float]) -> float:
        """T + V of the system's model at the plant's physical parameters (``info["energy"]``)."""
        return self._definition.energy(self._energy_values, x)

    def _configure(self, **extra) -> None:
        """Validate and apply the :attr:`extra_keywords` (none by default)."""

    def _extra_observation_size(self) -> int:
        """Components appended to the observation after the state (e.g. N-MSD's target)."""
        return 0

    def _extra_observation(self) -> list[float]:
        return []

    def _update_scene(self, model, data) -> None:
        """Move purely visual elements (e.g. a target marker) before rendering."""

    def _options(self, options: Mapping[str, Any]) -> None:
        """Handle system-specific reset options (keys already validated)."""

    reset_option_names: ClassVar[tuple[str, ...]] = ("state",)

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode: near rest with ``reset_noise_scale`` noise, or at ``options["state"]``.

        Draws new physical parameters when ``randomize`` is set (seeded by ``seed``).
        """
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, Mapping):
            raise EnvArgumentError(f"options must be a dict, got {type(options).__name__}")
        unknown = sorted(set(options) - set(self.reset_option_names))
        if unknown:
            raise EnvArgumentError(
                f"reset: unknown option(s) {unknown}; expected any of {list(self.reset_option_names)}"
            )
        self._options(options)
        if self._randomize:
            self.backend.set_parameters(
                randomize_parameters(self._nominal_parameters, self._randomize, self.np_random)
            )
            self._on_parameters(self.physical_parameters())
        if "state" in options and options["state"] is not None:
            x0 = np.asarray(options["state"], dtype=np.float64)
            if x0.shape != (2 * self._n,):
                raise EnvArgumentError(
                    f"options['state'] must have shape ({2 * self._n},) = {self._spec.state_names}, "
                    f"got shape {x0.shape}"
                )
            if not np.all(np.isfinite(x0)):
                raise EnvArgumentError(f"options['state'] must be finite, got {x0}")
        else:
            x0 = self._initial_state(self.np_random)
        self._reset_episode(x0)
        obs = self._observe(self._x)
        self._last_obs = obs
        if self.render_mode == "human":
            self.render()
        return obs.copy(), self._info(False)

    def _on_parameters(self, parameters: Mapping[str, float]) -> None:
        """Physical parameters changed (domain randomisation): a subclass that overrides this
        calls ``super()._on_parameters``."""
        self._energy_values = self._definition.lumped_values(parameters)

    def physical_parameters(self) -> dict[str, float]:
        """The plant's physical parameters (for a learned model: the pinned nominal ones, which
        ``info["energy"]`` then uses)."""
        return self.backend.parameters or default_parameters(self.system)

    def _reset_episode(self, x0: np.ndarray) -> None:
        self.backend.reset(x0)
        self._x = np.array(x0, dtype=np.float64)
        self._xl = self._x.tolist()
        self._steps = 0
        self._diverged = False
        self._u = 0.0
        if self._has_delay:
            self._buffer = collections.deque(
                [self._zero_action] * (self._delay_periods + 2), maxlen=self._delay_periods + 2
            )
        if self._lag is not None:
            self._lag.reset()  # u_m = 0, as MuJoCo's reset leaves the activation
        if self._filter is not None:
            self._filter.reset(self._measure_positions(self._x))
        self._last_obs = self._present(self._x.copy())

    def step(self, action):
        """Apply ``action`` (clipped to the limit) for one control period; see the class docs."""
        # Lean path: this runs at 500 Hz inside RL loops, so the common case (a float64 array of
        # shape (1,) within the limits) costs a few attribute reads and no allocation.
        limit = self._action_high
        if type(action) is np.ndarray and action.shape == (1,) and action.dtype == np.float64:
            u = action
            value = float(action[0])
        else:
            u = np.asarray(action, dtype=np.float64)
            if u.size != 1:
                raise ValueError(
                    f"action must be a single {self._spec.input_names[0]} value (shape (1,)), "
                    f"got shape {u.shape}"
                )
            u = u.reshape(1)
            value = float(u[0])
        if not -limit <= value <= limit:  # also catches NaN
            if not math.isfinite(value):
                raise ValueError(
                    f"action must be finite, got {value} (NaN/inf actions are rejected)"
                )
            value = limit if value > 0 else -limit
            u = np.array([value])
        if self.normalize_action:
            value *= self.max_action
            u = np.array([value])
        self._u = value

        x_prev = self._xl
        if self._diverged:
            # stepping past a divergence: nothing moves, the episode stays terminated
            reward = float(self._reward(x_prev, [value], x_prev))
            return self._last_obs.copy(), reward, True, self._truncated(), self._info(True)

        if self._has_delay or self._lag is not None:
            x = self._actuate(u)
        else:
            x = self.backend.step(u)
        self._steps += 1
        xl = x.tolist()
        # fast accept: Σ|x| ≤ bound (False for NaN/inf); otherwise the exact per-component test,
        # which leaves the angles unbounded (finite is enough)
        if not sum(map(abs, xl)) <= self._state_bound and not all(
            math.isfinite(v) and -b <= v <= b for v, b in zip(xl, self._bounds)
        ):
            # a blown-up model: end the episode at the last good state, never leak NaN
            self._diverged = True
            self.backend.reset(self._x)
            reward = float(self._reward(x_prev, [value], x_prev))
            return self._last_obs.copy(), reward, True, self._truncated(), self._info(True)

        self._x, self._xl = x, xl
        # the backend returns a fresh array each step: hand it out without another copy
        obs = x if self._exact_observation else self._observe(x)
        self._last_obs = obs
        reward = float(self._reward(x_prev, [value], xl))
        terminated = bool(self._terminated(xl))
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, self._truncated(), self._info(False)

    def _actuate(self, u: np.ndarray) -> np.ndarray:
        """Step the backend with the delayed (input buffer) and, on a model backend, lagged input.

        The lag is discretised exactly over each piece of the period the input is held
        (:meth:`ActuatorLag.advance`): the backend holds u_m's mean over that piece, so its impulse
        is exact, while MuJoCo integrates u_m per RK4 stage; they agree to O(dt/τ) of what the
        lag changes (~0.3 % at τ = 5 ms and 500 Hz; tests/test_effects_plants.py measures it).
        """
        if self._has_delay:
            self._buffer.append(u)
            u_now = self._buffer[-1 - self._delay_periods]
            n_first = self._delay_substeps
            u_first = self._buffer[-2 - self._delay_periods]
        else:
            u_now, n_first, u_first = u, 0, None
        if self._lag is not None:
            if n_first:
                u_first = self._lag.advance(u_first, n_first * self.timestep)
            u_now = self._lag.advance(u_now, (self.frame_skip - n_first) * self.timestep)
        if n_first:
            return self.backend.step_split(u_first, n_first, u_now)
        return self.backend.step(u_now)

    def _lag_state(self):
        if self._lag is not None:
            return self._lag.state.copy()
        return getattr(self.backend, "lagged_input", None)

    def _set_lag_state(self, u_m) -> None:
        if self._lag is not None:
            self._lag.state = np.array(u_m, dtype=np.float64)
        elif getattr(self.backend, "lagged_input", None) is not None:
            self.backend.lagged_input = u_m

    def _truncated(self) -> bool:
        return self._max_steps is not None and self._steps >= self._max_steps

    def _info(self, diverged: bool) -> dict[str, Any]:
        return {
            "time": self._steps * self.dt,
            "energy": self._energy(self._xl),
            "diverged": diverged,
            "state": self._x.copy(),  # obs may be this very array: keep the true state apart
            "action": self._u,
        }

    # ------------------------------------------------------------------ sensors
    def _measure_positions(self, x: np.ndarray) -> np.ndarray:
        q = x[: self._n].copy()
        quant = self._quant
        if quant.any():
            q = quantize_joints(q, quant)
        if self._noise[: self._n].any():
            q = q + self._noise[: self._n] * self.np_random.standard_normal(self._n)
        return q

    def _observe(self, x: np.ndarray) -> np.ndarray:
        """The observation of the true state ``x``: the sensor model, then the presentation."""
        if self._exact_observation:
            return x.copy()
        return self._present(self._measure(x))

    def _measure(self, x: np.ndarray) -> np.ndarray:
        """Sensor model: quantised, noisy positions; exact or derivative-filtered velocities
        (from the measured positions), plus velocity noise."""
        if self._exact_sensors:
            return x.copy()
        n = self._n
        q = self._measure_positions(x)
        qd = self._filter(q) if self._filter is not None else x[n:].copy()
        if self._noise[n:].any():
            qd = qd + self._noise[n:] * self.np_random.standard_normal(n)
        return np.concatenate((q, qd))

    def _present(self, z: np.ndarray) -> np.ndarray:
        """The measured state ``z`` = (q, q̇) in the ``observation`` layout and ``dtype``: "raw"
        as is; "wrapped" with angles in (−π, π]; "trig" with each angle as (cos, sin). In the
        last two, the other components are clipped to ±state_bound (beyond it the env diverges;
        only sensor noise can reach it), so the observation is always in the bounded space."""
        if self.observation == "raw":
            if self._extra_observation_size():
                z = np.concatenate((z, self._extra_observation()))
            return z.astype(self.dtype, copy=False)
        n, bound = self._n, self._state_bound
        parts = []
        for j, angular in enumerate(self._spec.angular):
            if angular and self.observation == "trig":
                parts += [math.cos(z[j]), math.sin(z[j])]
            elif angular:
                parts.append(wrap_angle(float(z[j])))
            else:
                parts.append(min(max(float(z[j]), -bound), bound))
        parts += np.clip(z[n:], -bound, bound).tolist()
        return np.array(parts + self._extra_observation(), dtype=self.dtype)

    def _observation_space(self) -> spaces.Box:
        """The Box of :meth:`_present`'s output."""
        extra = self._extra_observation_size()
        if self.observation == "raw":
            return spaces.Box(-np.inf, np.inf, (2 * self._n + extra,), dtype=self.dtype)
        bound, high = self._state_bound, []
        for angular in self._spec.angular:
            if angular and self.observation == "trig":
                high += [1.0, 1.0]
            else:
                high.append(math.pi if angular else bound)
        high = np.array(high + [bound] * self._n + [np.inf] * extra, dtype=self.dtype)
        return spaces.Box(-high, high, dtype=self.dtype)

    # ------------------------------------------------------------------ rendering
    def render(self):
        """An (height, width, 3) uint8 frame ("rgb_array") or a window ("human"); the scene is the
        system's MJCF model posed at the backend's state, whatever the backend."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' "
                "to gymnasium.make"
            )
            return None
        model, data = self.backend.scene()
        self._update_scene(model, data)
        if self._renderer is None or self._renderer.model is not model:
            from gymnasium.envs.mujoco.mujoco_rendering import MujocoRenderer

            if self._renderer is not None:
                self._renderer.close()
            self._renderer = MujocoRenderer(
                model, data, dict(self.default_camera_config), self.width, self.height
            )
        return self._renderer.render(self.render_mode)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------ pickling
    def __getstate__(self):
        # rebuild from the constructor keywords, then restore the episode (state, RNG, params)
        return {
            "kwargs": self._init_kwargs,
            "x": self._x,
            "steps": self._steps,
            "diverged": self._diverged,
            "parameters": self.backend.parameters,
            "np_random": self._np_random,
            "task_kwargs": self._task_kwargs,
            # per-episode memory of the sensors and the actuator
            "u": self._u,
            "last_obs": self._last_obs,
            "buffer": list(self._buffer) if self._has_delay else None,
            "lag": self._lag_state(),
            "filter_z": None if self._filter is None else np.array(self._filter._z),
        }

    def __setstate__(self, state):
        self.__init__(**state["kwargs"])
        self._task_kwargs = state["task_kwargs"]
        self.task = self._make_task(**self._task_kwargs)
        if state["parameters"] != self.backend.parameters:
            self.backend.set_parameters(state["parameters"])
            self._on_parameters(self.physical_parameters())
        self._reset_episode(state["x"])  # (may draw sensor noise: restore the RNG after it)
        self._np_random = state["np_random"]
        self._steps = state["steps"]
        self._diverged = state["diverged"]
        self._u = state.get("u", 0.0)
        self._last_obs = state.get("last_obs", self._last_obs)
        if state.get("buffer") is not None:
            self._buffer.extend(state["buffer"])
        if state.get("lag") is not None:
            self._set_lag_state(state["lag"])
        if state.get("filter_z") is not None:
            self._filter._z = np.array(state["filter_z"])
