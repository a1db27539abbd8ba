"""The registry of system definitions: a third system is one module and one entry here."""

from __future__ import annotations

from ..lagrangian import SystemSpec
from ..systems import get_spec
from ._furuta import FURUTA_DEFINITION
from ._nmsd import NMSD_DEFINITION
from ._system import SystemDefinition

__all__ = ["SYSTEM_DEFINITIONS", "system_definition"]

SYSTEM_DEFINITIONS: dict[str, SystemDefinition] = {d.name: d for d in (FURUTA_DEFINITION, NMSD_DEFINITION)}


def system_definition(system: str | SystemSpec) -> SystemDefinition:
    """The definition of ``"furuta"`` or ``"nmsd"`` (a name or a spec); a clear error otherwise."""
    name = system.name if isinstance(system, SystemSpec) else system
    return SYSTEM_DEFINITIONS[get_spec(name).name]
