"""Model-based controllers designed from any Lagrangian-system model (paper, appendix
"Controller Design"): collocated partial feedback linearisation, energy swing-up, LQR about the
upright and the switching swing-up → LQR, each a Gymnasium policy and a pure jittable law.

Quick start::

    from furuta_gym.models import Furuta
    from furuta_gym.controllers import SwingUpLQR

    ctrl = SwingUpLQR.from_model(Furuta())        # or any learned model
    ctrl.reset()
    action = ctrl(obs)                            # np.ndarray (1,), volts
    u, state = ctrl.step(ctrl.init_state(), obs)  # pure, jittable, scan/vmap-able
"""

from ._base import AbstractController, wrap_angle
from ._energy import (
    DEFAULT_PUMP_ACCELERATION,
    EnergySwingUp,
    default_k_e,
    model_state,
    upright_potential,
)
from ._evaluate import EpisodeRecord, evaluate_on_env
from ._lqr import DEFAULT_Q, DEFAULT_R, LQR, UPRIGHT_STATE, LQRDesign, lqr_design
from ._metrics import EpisodeMetrics, episode_metrics
from ._pfl import InputMap, input_map, pfl_torque, pfl_voltage
from ._rollout import ClosedLoop, Sensor, closed_loop
from ._switching import BALANCE, SWING_UP, SwingUpLQR
from ._tuning import GainSweep, near_rest_starts, near_upright_starts, pick_k_e

__all__ = [
    "AbstractController",
    "EnergySwingUp",
    "LQR",
    "LQRDesign",
    "SwingUpLQR",
    "lqr_design",
    "pfl_voltage",
    "pfl_torque",
    "input_map",
    "InputMap",
    "model_state",
    "upright_potential",
    "wrap_angle",
    "closed_loop",
    "ClosedLoop",
    "Sensor",
    "episode_metrics",
    "EpisodeMetrics",
    "evaluate_on_env",
    "EpisodeRecord",
    "pick_k_e",
    "GainSweep",
    "near_rest_starts",
    "near_upright_starts",
    "DEFAULT_Q",
    "DEFAULT_R",
    "DEFAULT_PUMP_ACCELERATION",
    "default_k_e",
    "UPRIGHT_STATE",
    "SWING_UP",
    "BALANCE",
]
