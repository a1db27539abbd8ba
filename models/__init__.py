"""Models implementing the Lagrangian-system protocol (:mod:`furuta_gym.lagrangian`).

Analytic: :class:`Furuta`, :class:`NMSD`. Learned: DeLaN, APHYNITY, augmented DeLaN.
"""

from ..lagrangian import AbstractLagrangianSystem
from ._aphynity import Aphynity
from ._augmented import AbstractAugmentedSystem, AugmentedDeLaN
from ._definitions import SYSTEM_DEFINITIONS, system_definition
from ._delan import DeLaN
from ._factory import MODEL_KINDS, make_model, model_kind
from ._furuta import Furuta, FurutaParameters, FurutaSharedTrig, furuta_lumped, furuta_mass_matrix, furuta_potential
from ._learned import SYSTEM_DEFAULTS, AbstractLearnedSystem
from ._lumped import LumpedSystem
from ._nmsd import NMSD, NMSDParameters, nmsd_potential
from ._system import Equilibrium, LumpedForm, SystemDefinition, first_joint_input, parameter_defaults
from .checkpoint import CheckpointError, load_model, read_header, save_model

__all__ = [
    "Furuta",
    "FurutaParameters",
    "FurutaSharedTrig",
    "NMSD",
    "NMSDParameters",
    "analytic_model",
    # one object per system
    "SystemDefinition",
    "Equilibrium",
    "LumpedForm",
    "LumpedSystem",
    "SYSTEM_DEFINITIONS",
    "system_definition",
    "first_joint_input",
    "parameter_defaults",
    # the analytic physics in lumped parameters (the diagnosis fits these)
    "furuta_lumped",
    "furuta_mass_matrix",
    "furuta_potential",
    "nmsd_potential",
    # learned
    "AbstractLearnedSystem",
    "AbstractAugmentedSystem",
    "DeLaN",
    "Aphynity",
    "AugmentedDeLaN",
    "MODEL_KINDS",
    "model_kind",
    "SYSTEM_DEFAULTS",
    "make_model",
    "save_model",
    "load_model",
    "read_header",
    "CheckpointError",
]


def analytic_model(system: str) -> AbstractLagrangianSystem:
    """The analytic model of ``"furuta"`` or ``"nmsd"`` with the pinned parameters."""
    return system_definition(system).model()
