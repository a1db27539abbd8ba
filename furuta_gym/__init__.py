"""furuta-gym: Lagrangian models, Gymnasium envs and controllers for underactuated systems.

Importing this package registers the Gymnasium envs ``furuta_gym/Furuta-v0``,
``furuta_gym/NMSD-v0`` and the RL preset ``furuta_gym/FurutaSwingUp-v0``, configured by the
settings objects exported here (:class:`Plant`, :class:`Episode`, :class:`Actuation`,
:class:`Sensors`, :class:`Spaces`, :class:`Camera`, :class:`Target`; see :mod:`furuta_gym.envs`).
It never changes JAX's configuration at import; see :func:`furuta_gym.ensure_x64` and the README
section "Float64". Its first act is to pin XLA's CPU code generation through ``XLA_FLAGS``, so that
every x86-64 machine computes the same bits (:mod:`furuta_gym._numerics`, :func:`numerics`).
"""

from ._numerics import NumericsWarning, numerics  # first: it pins XLA_FLAGS before JAX starts

# isort: split
from ._dispatch import inline_cpu_dispatch
from ._x64 import Float64Warning, enable_x64, ensure_x64
from .envs import Actuation, Camera, Episode, Plant, Sensors, Spaces, Target, register_envs
from .lagrangian import AbstractLagrangianSystem, SystemSpec
from .systems import FURUTA, NMSD

__version__ = "0.1.0"

__all__ = [
    "AbstractLagrangianSystem",
    "SystemSpec",
    "FURUTA",
    "NMSD",
    "Float64Warning",
    "enable_x64",
    "ensure_x64",
    "inline_cpu_dispatch",
    "NumericsWarning",
    "numerics",
    "Plant",
    "Episode",
    "Actuation",
    "Sensors",
    "Spaces",
    "Camera",
    "Target",
    "__version__",
]


register_envs()
