"""Gymnasium envs over interchangeable dynamics backends.

``import furuta_gym`` registers ``furuta_gym/Furuta-v0`` (:class:`FurutaEnv`),
``furuta_gym/NMSD-v0`` (:class:`NMSDEnv`) and the RL preset ``furuta_gym/FurutaSwingUp-v0``
(:data:`SWINGUP_PRESET`). Their settings are a few objects, the same for every system
(:class:`Plant`, :class:`Episode`, :class:`Actuation`, :class:`Sensors`, :class:`Spaces`,
:class:`Camera`, and the N-MSD's :class:`Target`). The world is a backend (:class:`MujocoBackend`,
:class:`ModelBackend`, chosen by ``dynamics=``); the goal is a task (:class:`FurutaSwingUp`,
:class:`NMSDReach`) whose reward/termination are pure functions usable on NumPy and JAX arrays.
See docs/envs.md.
"""

import gymnasium

from ._backends import AbstractBackend, ModelBackend, MujocoBackend, load_checkpoint, make_backend
from ._base import LagrangianEnv
from ._mjcf_out import PlainForms, plain_forms, plant_mjcf, save_mjcf
from ._parameters import default_parameters
from ._settings import Actuation, Camera, EnvArgumentError, Episode, Plant, Sensors, Spaces
from ._tasks import DEFAULT_STATE_BOUND, FurutaSwingUp, NMSDReach, is_diverged, tolerance
from .furuta import FurutaEnv
from .nmsd import NMSDEnv, Target

__all__ = [
    "AbstractBackend",
    "MujocoBackend",
    "ModelBackend",
    "make_backend",
    "load_checkpoint",
    "LagrangianEnv",
    "EnvArgumentError",
    "Plant",
    "Episode",
    "Actuation",
    "Sensors",
    "Spaces",
    "Camera",
    "Target",
    "save_mjcf",
    "plant_mjcf",
    "plain_forms",
    "PlainForms",
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
    "ENV_CLASSES",
    "ENV_IDS",
    "SWINGUP_ID",
    "SWINGUP_PRESET",
    "SWINGUP_EPISODE_STEPS",
]

#: The envs, one per system: a third system's env is one module and one entry here.
ENV_CLASSES: tuple[type[LagrangianEnv], ...] = (FurutaEnv, NMSDEnv)
ENV_IDS = {cls.system: cls.env_id for cls in ENV_CLASSES}
#: Each system's named plant variants (``plant=``), as its env declares them.
PLANT_PRESETS = {cls.system: dict(cls.plant_presets) for cls in ENV_CLASSES}

#: The RL preset: Furuta-v0 at 50 Hz (10 RK4 steps of 2 ms per action), observations
#: (cos α, sin α, cos β, sin β, α̇, β̇) in float32, actions in [−1, 1] scaled to ±max_voltage,
#: 500 steps (10 s) per episode through Gymnasium's TimeLimit (``env.spec.max_episode_steps``).
SWINGUP_ID = "furuta_gym/FurutaSwingUp-v0"
SWINGUP_PRESET = dict(
    episode=Episode(frame_skip=10, seconds=None),
    spaces=Spaces(observation="trig", dtype="float32", normalize_action=True),
)
SWINGUP_EPISODE_STEPS = 500


def register_envs() -> None:
    """Register the envs with Gymnasium (idempotent; called by ``import furuta_gym``)."""
    for cls in ENV_CLASSES:
        if cls.env_id not in gymnasium.registry:
            # no max_episode_steps: the env truncates itself after `episode_seconds`, so the
            # episode length follows the control rate (frame_skip). gymnasium.make_vec goes to
            # make_vector_env: batched JAX or SyncVectorEnv, whichever is faster and supports
            # the options.
            gymnasium.register(
                id=cls.env_id, entry_point=f"{cls.__module__}:{cls.__name__}", vector_entry_point=cls.vector_entry_point
            )
    if SWINGUP_ID not in gymnasium.registry:
        # no vector entry point: the batched JAX env keeps the raw float64 layout, so make_vec of
        # the preset steps copies of the single env (Gymnasium's sync/async vector envs)
        gymnasium.register(
            id=SWINGUP_ID,
            entry_point=f"{FurutaEnv.__module__}:{FurutaEnv.__name__}",
            max_episode_steps=SWINGUP_EPISODE_STEPS,
            kwargs=dict(SWINGUP_PRESET),
        )
