"""A system's declared model written in its lumped parameters: the form the diagnosis fits and a
diagnosed plant carries (:class:`furuta_gym.envs.Plant`), as a Lagrangian system."""

from __future__ import annotations

from typing import ClassVar, Mapping

import equinox as eqx
import jax.numpy as jnp

from ..lagrangian import AbstractLagrangianSystem
from ..systems import get_spec
from ._definitions import system_definition

__all__ = ["LumpedSystem"]


class LumpedSystem(AbstractLagrangianSystem):
    """M, V, τ_NC and τ_u of ``system``'s lumped form (:class:`LumpedForm`) at ``values``, in
    the order of its ``names``. :meth:`of` builds it from a mapping of names to floats."""

    values: jnp.ndarray
    system: str = eqx.field(static=True)

    spec: ClassVar = property(lambda self: get_spec(self.system))  # type: ignore[assignment]

    @classmethod
    def of(cls, system: str, values: Mapping[str, float]) -> "LumpedSystem":
        names = system_definition(system).lumped.names
        missing = sorted(set(names) - set(values))
        if missing:
            raise ValueError(f"lumped parameters of {system}: missing {missing}; expected {list(names)}")
        return cls(values=jnp.asarray([float(values[n]) for n in names]), system=get_spec(system).name)

    def _value(self, name: str):
        return self.values[system_definition(self.system).lumped.names.index(name)]

    def mass_matrix(self, q):
        return system_definition(self.system).lumped.mass_matrix(self._value, q)

    def potential(self, q):
        return system_definition(self.system).lumped.potential(self._value, q)

    def nonconservative_force(self, q, qd):
        return system_definition(self.system).lumped.damping(self._value, qd)

    def input_force(self, q, qd, u):
        definition = system_definition(self.system)
        return definition.input_force(self._value(definition.lumped.gain), u)
