"""Models implementing the Lagrangian-system protocol (:mod:`furuta_gym.lagrangian`).

Analytic: :class:`Furuta`, :class:`NMSD`. Learned (issue 3): DeLaN, APHYNITY, augmented DeLaN.
"""

from ._analytic import NMSD, Furuta, FurutaParameters, NMSDParameters

__all__ = ["Furuta", "FurutaParameters", "NMSD", "NMSDParameters", "analytic_model"]


def analytic_model(system: str):
    """The analytic model of ``"furuta"`` or ``"nmsd"`` with the pinned parameters."""
    from ..systems import get_spec

    name = get_spec(system).name
    return Furuta() if name == "furuta" else NMSD()
