"""The env algorithm shared by every system: a task over a dynamics backend, plus sensors.

:class:`LagrangianEnv` holds no physics and no MuJoCo: it validates the action, applies the
actuation delay (:mod:`._actuation`), asks its :class:`~furuta_gym.envs.AbstractBackend` for the
next state, checks for divergence, scores the transition with its task's pure reward, and turns
the true state into an observation (:mod:`._observation`). Its settings are a few objects
(:mod:`._settings`); its constructor, written once here, is every system's. Concrete envs
(:mod:`furuta_gym.envs.furuta`, :mod:`furuta_gym.envs.nmsd`) declare the system, the task, the
defaults and the camera.
"""

from __future__ import annotations

import math
import os
from typing import Any, ClassVar, Mapping, Sequence

import gymnasium
import numpy as np
from gymnasium.spaces import Box

from ..effects import Effect, actuator_lag_time
from ..lagrangian import AbstractLagrangianSystem
from ..models import system_definition
from ..systems import get_spec
from ._actuation import Actuator, delay_substeps
from ._backends import AbstractBackend, make_backend
from ._observation import Observer
from ._parameters import default_parameters, parse_randomization, randomize_parameters, resolve_effects
from ._pickling import episode_state, restore_episode
from ._rendering import SceneRenderer, check_render_mode
from ._settings import (
    LEGACY_KEYWORDS,
    SETTINGS_TYPES,
    Actuation,
    Camera,
    EnvArgumentError,
    Episode,
    Plant,
    Sensors,
    Spaces,
    settings_from_keywords,
)
from ._tasks import divergence_bounds
from ._template import BatchTemplate

__all__ = ["LagrangianEnv", "EnvArgumentError"]


def _start_state(state: Any, names: Sequence[str]) -> np.ndarray:
    """``reset(options={"state": ...})`` as a finite float64 state of the system's shape."""
    x0 = np.asarray(state, dtype=np.float64)
    if x0.shape != (len(names),):
        raise EnvArgumentError(f"options['state'] must have shape ({len(names)},) = {names}, got shape {x0.shape}")
    if not np.all(np.isfinite(x0)):
        raise EnvArgumentError(f"options['state'] must be finite, got {x0}")
    return x0


def _as_action(action: Any, name: str) -> tuple[np.ndarray, float]:
    """Any one-value action as a float64 array of shape (1,) and its value."""
    u = np.asarray(action, dtype=np.float64)
    if u.size != 1:
        raise ValueError(f"action must be a single {name} value (shape (1,)), got shape {u.shape}")
    u = u.reshape(1)
    return u, float(u[0])


def _clipped(value: float, limit: float) -> float:
    """An action beyond ±limit clipped to it; NaN or infinite is an error."""
    if not math.isfinite(value):
        raise ValueError(f"action must be finite, got {value} (NaN/inf actions are rejected)")
    return limit if value > 0 else -limit


def _env_settings(cls: type[LagrangianEnv], given: dict[str, Any], legacy: dict[str, Any]) -> dict[str, Any]:
    """The settings objects of a ``cls`` env from its keywords, the plain ones of before mapped in."""
    types = {**SETTINGS_TYPES, "task": cls.task_settings_type}
    table = {**cls.legacy_keywords, cls.action_limit_name: ("actuation", "max_action")}
    return settings_from_keywords(cls.__name__, given, types, legacy, table)


class LagrangianEnv(BatchTemplate, gymnasium.Env):
    """Base of the furuta_gym envs (see :class:`furuta_gym.envs.FurutaEnv` for the user docs).

    Subclasses set :attr:`system`, :attr:`env_id`, :attr:`plant_presets` and
    :attr:`default_max_action`, and implement :meth:`_make_task` (and optionally the other hooks).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 50}

    system: ClassVar[str]
    #: its Gymnasium id (``register_envs`` registers every class of ``ENV_CLASSES`` under it)
    env_id: ClassVar[str]
    #: ``gymnasium.make_vec``'s entry point ("module:function"), ``None`` for Gymnasium's own
    vector_entry_point: ClassVar[str | None] = None
    #: named plant variants (``Plant(presets=...)``): the ground truth plus effects it lacks
    plant_presets: ClassVar[Mapping[str, tuple[Effect, ...]]] = {"nominal": ()}
    #: the action limit when ``Actuation.max_action`` is None, and its former plain keyword
    default_max_action: ClassVar[float]
    action_limit_name: ClassVar[str]
    #: the type of the ``task=`` settings (None: the system's task has none)
    task_settings_type: ClassVar[type | None] = None
    #: the plain keywords this env took before its settings were objects (see ``_settings``),
    #: besides its ``action_limit_name``
    legacy_keywords: ClassVar[Mapping[str, tuple[str, str]]] = LEGACY_KEYWORDS
    reset_option_names: ClassVar[tuple[str, ...]] = ("state",)
    default_camera_config: ClassVar[dict[str, Any]] = {}

    def __init__(
        self,
        *,
        dynamics: str | os.PathLike | AbstractLagrangianSystem = "mujoco",
        kernel: str = "auto",
        plant: Plant | str | Sequence[str] | None = None,
        task: Any = None,
        episode: Episode = Episode(),
        actuation: Actuation = Actuation(),
        sensors: Sensors = Sensors(),
        spaces: Spaces = Spaces(),
        camera: Camera = Camera(),
        render_mode: str | None = None,
        **legacy: Any,
    ):
        """See the class docs of :class:`~furuta_gym.envs.FurutaEnv` (the same keywords for
        every system and for the batched :class:`~furuta_gym.envs.vector.LagrangianVectorEnv`)."""
        given = dict(
            plant=plant, task=task, episode=episode, actuation=actuation, sensors=sensors, spaces=spaces, camera=camera
        )
        settings = _env_settings(type(self), given, legacy)
        # for pickling: rebuilt from the settings objects
        self._init_kwargs = dict(dynamics=dynamics, kernel=kernel, render_mode=render_mode, **settings)
        self.plant, self.task_settings = settings["plant"], settings["task"]
        self.episode, self.actuation, self.sensors = settings["episode"], settings["actuation"], settings["sensors"]
        self.spaces, self.camera = settings["spaces"], settings["camera"]
        self._spec = get_spec(self.system)
        self._definition = system_definition(self.system)
        self._n = self._spec.n_dof
        self._init_physics(dynamics, kernel)
        self._init_actuation()
        self._init_observation()
        self.task = self._make_task()
        self.action_space = Box(-self._action_high, self._action_high, (1,), dtype=self.dtype)
        self.observation_space = self._observer.space(self._extra_observation_size())
        self.render_mode = check_render_mode(render_mode, self.metadata["render_modes"])
        self.width, self.height = self.camera.width, self.camera.height
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self.dt))}
        self._renderer = SceneRenderer(self.camera, self.default_camera_config)
        self._on_parameters(self.physical_parameters())
        self._reset_episode(self._initial_state(None))

    def _init_physics(self, dynamics, kernel) -> None:
        """Control rate, the plant's effects and randomisation, the dynamics backend, the horizon."""
        if self.plant.lumped is not None and self.plant.system != self.system:
            raise EnvArgumentError(f"plant: a {self.plant.system} plant ({self.plant.source}) for a {self.system} env")
        self.frame_skip = self.episode.frame_skip
        self.reset_noise_scale = self.episode.reset_noise_scale
        self.effects: tuple[Effect, ...] = resolve_effects(
            self.system, self.plant.presets, self.plant.effects, self.plant_presets
        )
        self._randomize = parse_randomization(self.system, self.plant.randomize)
        lumped = self.plant.lumped
        self.backend: AbstractBackend = make_backend(
            self.system, dynamics, substeps=self.frame_skip, effects=self.effects, kernel=kernel, lumped=lumped
        )
        if self._randomize:
            self.backend.set_parameters(self.backend.parameters)  # fail now, not at reset
        self._nominal_parameters = self.backend.parameters
        self.dt = self.backend.control_dt
        self.timestep = self.backend.timestep
        self.episode_seconds = seconds = self.episode.seconds
        self._max_steps = None if seconds is None else int(round(seconds / self.dt))

    def _init_actuation(self) -> None:
        """The action limit, the delay in whole RK4 substeps and the actuator lag."""
        limit = self.actuation.max_action
        self.max_action = float(self.default_max_action if limit is None else limit)
        delay = delay_substeps(self.actuation, self.effects, self.timestep, self.frame_skip)
        self._has_delay = delay > 0
        # MuJoCo integrates the lag (actuator dynamics); for a model backend this env applies it
        self._lag_tau = actuator_lag_time(self.effects)
        env_lag = self._lag_tau if not self.backend.native_actuator_lag else 0.0
        self._actuator = (
            Actuator(delay, self.frame_skip, self.timestep, env_lag, len(self._spec.input_names))
            if self._has_delay or env_lag > 0
            else None
        )

    def _init_observation(self) -> None:
        """The sensor model, the observation layout, dtype and action scale, the system's own."""
        self._observer = Observer(self._spec, self.sensors, self.spaces, self.dt, lambda: self.np_random)
        self.velocity = self.sensors.velocity
        self.observation = self.spaces.observation
        self.dtype = np.dtype(self.spaces.dtype)
        self.normalize_action = self.spaces.normalize_action
        self._action_high = 1.0 if self.normalize_action else self.max_action
        self._configure()
        # obs is the backend's state array itself: no sensor model, raw, float64
        self._exact_observation = self._observer.is_the_state(self._extra_observation_size())

    @property
    def task(self):
        """The task (reward and termination as pure functions); see :mod:`._tasks`."""
        return self._task

    @task.setter
    def task(self, task) -> None:
        self._task = task
        # bound once: the step calls them without attribute lookups
        self._reward, self._terminated = task.reward, task.terminated
        self._state_bound = self._observer.state_bound = float(task.state_bound)
        # angles are never bounded: a rotor may turn for ever (only a non-finite angle diverges)
        self._bounds = divergence_bounds(task.state_bound, self._spec.angular)

    # ------------------------------------------------------------------ subclass hooks
    def _make_task(self):
        """The task at the start (from :attr:`task_settings` and the action limit)."""
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

    def _configure(self) -> None:
        """Apply the system's own settings (:attr:`task_settings`) before the task is made."""

    def _extra_observation_size(self) -> int:
        """Components appended to the observation after the state (e.g. N-MSD's target)."""
        return 0

    def _extra_observation(self) -> list[float]:
        return []

    def _update_scene(self, model, data) -> None:
        """Move purely visual elements (e.g. a target marker) before rendering."""

    def _options(self, options: Mapping[str, Any]) -> None:
        """Handle system-specific reset options (keys already validated)."""

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
            self.backend.set_parameters(randomize_parameters(self._nominal_parameters, self._randomize, self.np_random))
            self._on_parameters(self.physical_parameters())
        if options.get("state") is not None:
            x0 = _start_state(options["state"], self._spec.state_names)
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
        self._energy_values = self.plant.lumped or self._definition.lumped_values(parameters)

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
        if self._actuator is not None:
            self._actuator.reset()
        self._observer.reset(self._x)
        self._last_obs = self._present(self._x.copy())

    def step(self, action):
        """Apply ``action`` (clipped to the limit) for one control period; see the class docs."""
        # Lean path: this runs at the control rate inside RL loops, so the common case (a float64
        # array of shape (1,) within the limits) costs a few attribute reads and no allocation.
        limit = self._action_high
        if type(action) is np.ndarray and action.shape == (1,) and action.dtype == np.float64:
            u = action
            value = float(action[0])
        else:
            u, value = _as_action(action, self._spec.input_names[0])
        if not -limit <= value <= limit:  # also catches NaN
            value = _clipped(value, limit)
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

        x = self.backend.step(u) if self._actuator is None else self._actuator.step(self.backend, u)
        self._steps += 1
        xl = x.tolist()
        # fast accept: Σ|x| ≤ bound (False for NaN/inf); otherwise the exact per-component test,
        # which leaves the angles unbounded (finite is enough)
        if not sum(map(abs, xl)) <= self._state_bound and not all(
            math.isfinite(v) and -b <= v <= b for v, b in zip(xl, self._bounds, strict=True)
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

    def _observe(self, x: np.ndarray) -> np.ndarray:
        """The observation of the true state ``x``: the sensor model, then the presentation."""
        if self._exact_observation:
            return x.copy()
        return self._present(self._observer.measure(x))

    def _present(self, z: np.ndarray) -> np.ndarray:
        return self._observer.present(z, self._extra_observation())

    def render(self):
        """An (height, width, 3) uint8 frame ("rgb_array") or a window ("human"); the scene is the
        system's MJCF model posed at the backend's state, whatever the backend."""
        return self._renderer.render(self.backend, self.render_mode, self._update_scene)

    def close(self):
        self._renderer.close()

    # ------------------------------------------------------------------ pickling
    def __getstate__(self):
        return episode_state(self)

    def __setstate__(self, state):
        restore_episode(self, state)
