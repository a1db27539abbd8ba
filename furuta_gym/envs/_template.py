"""What a batched copy of an env needs to know about it (read by :mod:`furuta_gym.envs.vector`).

:class:`BatchTemplate` is the read-only half of :class:`~furuta_gym.envs.LagrangianEnv`: the
system, the sensor quantisation, the horizon, the initial-state distribution, and which of its
settings a stateless batched copy cannot reproduce.
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import numpy as np
from gymnasium import spaces

from ..lagrangian import SystemSpec
from ._observation import Observer
from ._settings import EnvArgumentError, Sensors

__all__ = ["BatchTemplate"]


class BatchTemplate:
    """The queries a :class:`~furuta_gym.envs.vector.LagrangianVectorEnv` makes of its template."""

    # set by LagrangianEnv.__init__
    reset_option_names: ClassVar[tuple[str, ...]]
    _spec: SystemSpec
    sensors: Sensors
    _observer: Observer
    _randomize: dict
    _max_steps: int | None
    _has_delay: bool
    _lag_tau: float
    observation: str
    dtype: np.dtype
    normalize_action: bool
    action_space: spaces.Box
    observation_space: spaces.Box

    def _initial_state(self, rng: np.random.Generator | None) -> np.ndarray:
        raise NotImplementedError

    def _options(self, options: Mapping[str, Any]) -> None:
        raise NotImplementedError

    @property
    def system_spec(self):
        """The system's :class:`~furuta_gym.lagrangian.SystemSpec` (joints, state and input names)."""
        return self._spec

    @property
    def encoder_steps(self) -> np.ndarray:
        """Quantisation step of each measured joint position (0: exact), in rad or m."""
        return np.array(self.sensors.quantization(self._spec))

    @property
    def noise_std(self) -> np.ndarray:
        """Gaussian measurement noise std per observed state component (q, q̇); 0: none."""
        return np.array(self.sensors.noise(self._spec))

    @property
    def parameter_spreads(self) -> dict[str, float]:
        """Domain randomisation: relative spread per physical parameter, drawn at each reset."""
        return dict(self._randomize)

    @property
    def observation_bound(self) -> float:
        """The bound the "wrapped" / "trig" layouts clip non-angle components to."""
        return self._observer.state_bound

    @property
    def max_episode_steps(self) -> int | None:
        """env.steps before truncation (None: never truncated)."""
        return self._max_steps

    def presentation_options(self) -> list[str]:
        """The configured non-default observation / action presentation (``Spaces``): what the
        batched JAX env does not reproduce."""
        options = []
        if self.observation != "raw":
            options.append(f"observation={self.observation!r}")
        if self.dtype != np.float64:
            options.append(f"dtype={self.dtype.name!r}")
        if self.normalize_action:
            options.append("normalize_action=True")
        return options

    def per_episode_state_features(self) -> list[str]:
        """The configured sensor / plant options whose effect depends on more than the state and
        the step count (random draws or a signal history): what a stateless batched copy cannot
        reproduce. Empty for a deterministic, memoryless env."""
        features = []
        if np.any(self.noise_std):
            features.append("measurement_noise")
        if self.sensors.velocity == "filter":
            features.append("velocity='filter'")
        if self._has_delay:
            features.append(
                "actuation delay (Actuation(delay=..., delay_steps=...), plant='delay' or an input_delay effect)"
            )
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
