"""The two benchmark systems' identities: names, units and which coordinates are angles.

A :class:`~furuta_gym.lagrangian.SystemSpec` is what data files, checkpoints, envs and models are
checked against ("is this log a Furuta log?"). Physical parameter values live with the analytic
models in :mod:`furuta_gym.models`.
"""

from __future__ import annotations

from .lagrangian import SystemSpec

__all__ = ["FURUTA", "NMSD", "SYSTEMS", "get_spec"]

FURUTA = SystemSpec(
    name="furuta",
    joint_names=("alpha", "beta"),
    angular=(True, True),
    input_names=("u",),
    joint_units=("rad", "rad"),
    input_units=("V",),
)

NMSD = SystemSpec(
    name="nmsd",
    joint_names=("p",),
    angular=(False,),
    input_names=("u",),
    joint_units=("m",),
    input_units=("N",),
)

SYSTEMS = {FURUTA.name: FURUTA, NMSD.name: NMSD}


def get_spec(name: str) -> SystemSpec:
    """The spec for ``"furuta"`` or ``"nmsd"``; a clear error for anything else."""
    try:
        return SYSTEMS[name]
    except KeyError:
        raise ValueError(f"unknown system {name!r}: expected one of {sorted(SYSTEMS)}") from None
