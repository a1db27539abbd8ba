"""furuta-gym: Lagrangian models, Gymnasium envs and controllers for underactuated systems.

Importing this package registers the Gymnasium envs ``furuta_gym/Furuta-v0``,
``furuta_gym/NMSD-v0`` and the RL preset ``furuta_gym/FurutaSwingUp-v0``. It never changes JAX's configuration at import; see
:func:`furuta_gym.ensure_x64` and the README section "Float64".
"""

from ._dispatch import inline_cpu_dispatch
from ._x64 import Float64Warning, enable_x64, ensure_x64
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
    "__version__",
]


def _register_envs() -> None:
    from .envs import register_envs

    register_envs()


_register_envs()
