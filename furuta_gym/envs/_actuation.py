"""Between the action and the plant: an input delay and a first-order actuator lag.

:func:`delay_substeps` turns :class:`~furuta_gym.envs.Actuation` and the plant's ``input_delay``
effects into whole RK4 substeps; :class:`Actuator` holds the input buffer (and, on a backend that
does not integrate the lag itself, the lag) and steps the backend with the delayed input.
"""

from __future__ import annotations

import collections
from typing import Sequence

import numpy as np

from ..effects import ActuatorLag, Effect
from ._settings import Actuation, EnvArgumentError

__all__ = ["Actuator", "delay_substeps"]


def substeps_of_delay(seconds: float, timestep: float, what: str) -> int:
    """Delay in seconds → whole RK4 substeps (it must be a multiple of the timestep)."""
    if not (np.isfinite(seconds) and seconds >= 0):
        raise EnvArgumentError(f"{what} must be a delay in seconds >= 0, got {seconds!r}")
    n = round(seconds / timestep)
    if abs(n * timestep - seconds) > 1e-9:
        raise EnvArgumentError(f"{what} = {seconds} s is not a multiple of the simulation timestep {timestep} s")
    return int(n)


def delay_substeps(actuation: Actuation, effects: Sequence[Effect], timestep: float, frame_skip: int) -> int:
    """The input delay in RK4 substeps: ``actuation``'s delay plus every ``input_delay`` effect."""
    delay = substeps_of_delay(actuation.delay, timestep, "Actuation.delay") + actuation.delay_steps * frame_skip
    for e in effects:
        if e.kind.input_dynamics == "delay":
            delay += substeps_of_delay(e.coefficient, timestep, "effect input_delay")
    return delay


class Actuator:
    """The input's way to the plant over one control period of ``frame_skip`` substeps: delayed
    by ``delay`` substeps (whole periods through a buffer, the rest by splitting the period), then
    lagged with time constant ``lag`` seconds when ``lag > 0`` (0: the backend lags it itself, or
    there is no lag)."""

    def __init__(self, delay: int, frame_skip: int, timestep: float, lag: float, n_inputs: int):
        self.frame_skip, self.timestep = frame_skip, timestep
        self.has_delay = delay > 0
        self.periods, self.substeps = divmod(delay, frame_skip)
        self.lag = ActuatorLag(lag, n_inputs) if lag > 0 else None
        self.zero = np.zeros(n_inputs)
        self.buffer: collections.deque = collections.deque()

    def reset(self) -> None:
        if self.has_delay:
            size = self.periods + 2
            self.buffer = collections.deque([self.zero] * size, maxlen=size)
        if self.lag is not None:
            self.lag.reset()  # u_m = 0, as MuJoCo's reset leaves the activation

    def step(self, backend, u: np.ndarray) -> np.ndarray:
        """Step ``backend`` with the delayed and, here, lagged input.

        The lag is discretised exactly over each piece of the period the input is held
        (:meth:`ActuatorLag.advance`): the backend holds u_m's mean over that piece, so its impulse
        is exact, while MuJoCo integrates u_m per RK4 stage; they agree to O(dt/τ) of what the
        lag changes (tests/test_effects_plants.py measures it).
        """
        if self.has_delay:
            self.buffer.append(u)
            u_now = self.buffer[-1 - self.periods]
            n_first = self.substeps
            u_first = self.buffer[-2 - self.periods]
        else:
            u_now, n_first, u_first = u, 0, None
        if self.lag is not None:
            if n_first:
                u_first = self.lag.advance(u_first, n_first * self.timestep)
            u_now = self.lag.advance(u_now, (self.frame_skip - n_first) * self.timestep)
        if n_first:
            return backend.step_split(u_first, n_first, u_now)
        return backend.step(u_now)
