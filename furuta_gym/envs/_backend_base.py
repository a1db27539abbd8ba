"""What every dynamics backend is (:class:`AbstractBackend`): a system's state advanced one
control period at a time, rendered through the MuJoCo scene; see :mod:`._backends`."""

from __future__ import annotations

import abc
from typing import Mapping

import mujoco
import numpy as np

from ..systems import get_spec


class AbstractBackend(abc.ABC):
    """Advance a system's state (q, q̇) one control period at a time, input held (zero-order hold).

    The period is ``substeps`` RK4 steps of ``timestep`` seconds. Concrete backends implement
    :meth:`reset`, :meth:`step`, :meth:`step_split` and :meth:`_scene_data`.
    """

    system: str  # "furuta" or "nmsd"
    _parameters: dict[str, float]
    timestep: float  # seconds per RK4 step
    substeps: int  # RK4 steps per control period
    #: whether the backend applies an ``actuator_lag`` effect itself (else the env does)
    native_actuator_lag: bool = False

    @property
    def spec(self):
        return get_spec(self.system)

    @property
    def control_dt(self) -> float:
        """Control period in seconds."""
        return self.timestep * self.substeps

    @property
    def parameters(self) -> dict[str, float]:
        """Physical parameters in use (the pinned ones unless :meth:`set_parameters` changed them)."""
        return dict(self._parameters)

    @abc.abstractmethod
    def reset(self, x: np.ndarray) -> None:
        """Put the system at state ``x`` = (q, q̇), time 0."""

    @abc.abstractmethod
    def step(self, u: np.ndarray) -> np.ndarray:
        """Advance one control period with ``u`` held; return the new state (a fresh float64 array)."""

    @abc.abstractmethod
    def step_split(self, u_first: np.ndarray, n_first: int, u: np.ndarray) -> np.ndarray:
        """Advance one period applying ``u_first`` for the first ``n_first`` substeps, then ``u``
        (an actuation delay that is not a whole number of periods)."""

    @property
    @abc.abstractmethod
    def state(self) -> np.ndarray:
        """Current state (a copy)."""

    def set_parameters(self, values: Mapping[str, float]) -> None:
        """Use these physical parameters from now on (domain randomisation)."""
        raise ValueError(
            f"{type(self).__name__} has no physical parameters to change; domain randomisation "
            "needs dynamics='mujoco' or 'analytic'"
        )

    # -- rendering through the MuJoCo scene --------------------------------------------------
    @abc.abstractmethod
    def _scene_data(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """(model, data) whose qpos is the current configuration."""

    def scene(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The MuJoCo (model, data) posed at the current configuration, kinematics computed."""
        model, data = self._scene_data()
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_tendon(model, data)  # the N-MSD spring is drawn as a tendon
        return model, data
