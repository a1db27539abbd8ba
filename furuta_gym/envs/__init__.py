"""Gymnasium envs over interchangeable dynamics backends.

``import furuta_gym`` registers ``furuta_gym/Furuta-v0`` (:class:`FurutaEnv`) and
``furuta_gym/NMSD-v0`` (:class:`NMSDEnv`). The world is a backend (:class:`MujocoBackend`,
:class:`ModelBackend`, chosen by ``dynamics=``); the goal is a task (:class:`FurutaSwingUp`,
:class:`NMSDReach`) whose reward/termination are pure functions usable on NumPy and JAX arrays.
See docs/envs.md.
"""

from ._backends import AbstractBackend, ModelBackend, MujocoBackend, load_checkpoint, make_backend
from ._base import EnvArgumentError, LagrangianEnv
from ._parameters import PLANT_PRESETS, default_parameters
from ._tasks import DEFAULT_STATE_BOUND, FurutaSwingUp, NMSDReach, is_diverged, tolerance
from .furuta import FurutaEnv
from .nmsd import NMSDEnv

__all__ = [
    "AbstractBackend",
    "MujocoBackend",
    "ModelBackend",
    "make_backend",
    "load_checkpoint",
    "LagrangianEnv",
    "EnvArgumentError",
    "FurutaEnv",
    "NMSDEnv",
    "FurutaSwingUp",
    "NMSDReach",
    "tolerance",
    "is_diverged",
    "DEFAULT_STATE_BOUND",
    "PLANT_PRESETS",
    "default_parameters",
    "register_envs",
    "ENV_IDS",
]

ENV_IDS = {"furuta": "furuta_gym/Furuta-v0", "nmsd": "furuta_gym/NMSD-v0"}


def register_envs() -> None:
    """Register the envs with Gymnasium (idempotent; called by ``import furuta_gym``)."""
    import gymnasium

    for env_id, entry, vector_entry in (
        (
            ENV_IDS["furuta"],
            "furuta_gym.envs.furuta:FurutaEnv",
            "furuta_gym.envs.vector:furuta_vector_entry_point",
        ),
        (
            ENV_IDS["nmsd"],
            "furuta_gym.envs.nmsd:NMSDEnv",
            "furuta_gym.envs.vector:nmsd_vector_entry_point",
        ),
    ):
        if env_id not in gymnasium.registry:
            # no max_episode_steps: the env truncates itself after `episode_seconds`, so the
            # episode length follows the control rate (frame_skip). gymnasium.make_vec goes to
            # the batched JAX env for model backends, Sync/Async vector envs for MuJoCo.
            gymnasium.register(id=env_id, entry_point=entry, vector_entry_point=vector_entry)
