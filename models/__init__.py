"""Models implementing the Lagrangian-system protocol (:mod:`furuta_gym.lagrangian`).

Analytic: :class:`Furuta`, :class:`NMSD`. Learned (issue 3): DeLaN, APHYNITY, augmented DeLaN.
"""

from ._analytic import (ANALYTIC, NMSD, Furuta, FurutaParameters, NMSDParameters, furuta_lumped, furuta_mass_matrix,
                        furuta_potential, nmsd_potential)
from ._aphynity import Aphynity
from ._augmented import AugmentedDeLaN
from ._delan import DeLaN
from ._factory import MODEL_KINDS, make_model
from ._learned import SYSTEM_DEFAULTS, AbstractLearnedSystem
from .checkpoint import CheckpointError, load_model, read_header, save_model

__all__ = [
    "Furuta",
    "FurutaParameters",
    "NMSD",
    "NMSDParameters",
    "analytic_model",
    # the analytic physics in lumped parameters (the diagnosis fits these)
    "furuta_lumped",
    "furuta_mass_matrix",
    "furuta_potential",
    "nmsd_potential",
    # learned (issue 3)
    "AbstractLearnedSystem",
    "DeLaN",
    "Aphynity",
    "AugmentedDeLaN",
    "MODEL_KINDS",
    "SYSTEM_DEFAULTS",
    "make_model",
    "save_model",
    "load_model",
    "read_header",
    "CheckpointError",
]


def analytic_model(system: str):
    """The analytic model of ``"furuta"`` or ``"nmsd"`` with the pinned parameters."""
    from ..systems import get_spec

    return ANALYTIC[get_spec(system).name][0]()
