"""Linear-in-parameters ("lumped") forms of the declared models and the candidate-effect library.

The integral inverse residual Z̄ − Ā (Laiche et al. 2026, eq. 8-10) is linear in the *base* (lumped)
parameters of both benchmark systems and in the coefficient of every candidate effect of
:mod:`furuta_gym.effects`. :class:`LumpedModel` is a Lagrangian system whose M, V, τ_NC, τ_u are
written in those parameters, one flat vector ``theta`` = base parameters followed by one
coefficient per library effect. Because the residual is linear in ``theta``, its Jacobian (taken by
autodiff, through :func:`furuta_gym.lagrangian.momentum` and friends) *is* the regressor matrix of
the equation-error fit, and the same model simulated open loop is the output-error model.

Furuta lumped parameters (DEVELOPERS.md conventions):

=============  =====================================  ==============
``J1``         Jr + mp·Lr²                            kg m²
``J1b``        ¼·mp·Lp²   (the sin²β term of M11)     kg m²
``Jc``         ½·mp·Lr·Lp (the coupling, cos β)       kg m²
``J2``         Jp + ¼·mp·Lp²                          kg m²
``G``          ½·mp·g·Lp  (V = G(1 − cos β))          N m
``c_alpha``    c_r + kt·km/Rm (friction + back-EMF)   N m s/rad
``c_beta``     c_p                                    N m s/rad
``K``          kt/Rm      (τ_u,α = K·u)                N m/V
=============  =====================================  ==============

Rotor viscous friction and back-EMF are the same regressor (−α̇) on any data, so they are one
parameter here. N-MSD: ``m, k1, k2, b1, b2`` and the input gain ``gain`` (τ_u = gain·u, 1 for a
force in newtons).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..effects import EFFECT_UNITS, INPUT_EFFECTS, JOINT_EFFECTS, STATEFUL_EFFECTS, Effect
from ..lagrangian import AbstractLagrangianSystem, SystemSpec
from ..models import FurutaParameters, NMSDParameters
from ..systems import get_spec

__all__ = ["Candidate", "ParameterLayout", "LumpedModel", "layout_for", "nominal_base"]


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One library effect: ``name`` from :mod:`furuta_gym.effects` on ``joint`` (or ``"u"``)."""

    name: str
    joint: str

    @property
    def key(self) -> str:
        return f"{self.name}:{self.joint}"

    def unit(self, spec: SystemSpec) -> str:
        angular = self.joint == "u" or spec.angular[spec.joint_names.index(self.joint)]
        return EFFECT_UNITS[self.name][0 if angular else 1]


BASE = {
    "furuta": ("J1", "J1b", "Jc", "J2", "G", "c_alpha", "c_beta", "K"),
    "nmsd": ("m", "k1", "k2", "b1", "b2", "gain"),
}
BASE_UNITS = {
    "furuta": ("kg m^2", "kg m^2", "kg m^2", "kg m^2", "N m", "N m s/rad", "N m s/rad", "N m/V"),
    "nmsd": ("kg", "N/m", "N/m^3", "N s/m", "N s^3/m^3", "1"),
}
# The base parameter that *is* the input gain, and the default mechanical scale anchor used
# when the data carry no input excitation (free data leave the gain unidentifiable).
GAIN_PARAMETER = {"furuta": "K", "nmsd": "gain"}
# Joints whose declared potential is gravity: a centre-of-mass offset (``com_offset``) shifts it.
# Elsewhere a shifted potential is a spring's neutral (``spring`` + ``constant_torque``).
GRAVITY_JOINTS = {"furuta": ("beta",), "nmsd": ()}
MECHANICAL_ANCHOR = {"furuta": "G", "nmsd": "m"}


def nominal_base(system: str) -> dict[str, float]:
    """The pinned analytic model's values of the lumped parameters."""
    if system == "furuta":
        p = FurutaParameters()
        f = lambda x: float(x)  # noqa: E731
        return {
            "J1": f(p.J1),
            "J1b": f(0.25 * p.mp * p.Lp**2),
            "Jc": f(0.5 * p.mp * p.Lr * p.Lp),
            "J2": f(p.J2),
            "G": f(0.5 * p.mp * p.g * p.Lp),
            "c_alpha": f(p.c_r + p.kt * p.km / p.Rm),
            "c_beta": f(p.c_p),
            "K": f(p.kt / p.Rm),
        }
    p = NMSDParameters()
    return {"m": float(p.m), "k1": float(p.k1), "k2": float(p.k2), "b1": float(p.b1),
            "b2": float(p.b2), "gain": 1.0}


@dataclasses.dataclass(frozen=True)
class ParameterLayout:
    """Where each base parameter and each library effect lives in the flat ``theta``."""

    system: str
    base: tuple[str, ...]
    base_units: tuple[str, ...]
    candidates: tuple[Candidate, ...]  # memoryless library effects (delay is handled apart)

    @property
    def size(self) -> int:
        return len(self.base) + len(self.candidates)

    def index(self, name: str) -> int:
        """Index of a base parameter name or a candidate key ``"effect:joint"``."""
        if name in self.base:
            return self.base.index(name)
        keys = [c.key for c in self.candidates]
        if name in keys:
            return len(self.base) + keys.index(name)
        raise ValueError(
            f"unknown parameter {name!r} for {self.system}; base parameters are "
            f"{list(self.base)}, effects are {keys}"
        )

    def nominal(self) -> np.ndarray:
        nom = nominal_base(self.system)
        return np.array([nom[b] for b in self.base] + [0.0] * len(self.candidates))

    def typical_scale(self) -> np.ndarray:
        """Magnitudes used to scale the fits (base: nominal values; effects: typical sizes)."""
        spec = get_spec(self.system)
        out = list(np.abs(self.nominal()[: len(self.base)]))
        for c in self.candidates:
            if c.name == "input_gain":
                out.append(0.1)
                continue
            angular = spec.angular[spec.joint_names.index(c.joint)]
            typical = {
                "spring": 1e-3 if angular else 1.0,
                "coulomb_friction": 1e-4 if angular else 0.1,
                "stiction": 1e-4 if angular else 0.1,
                "com_offset": 1e-3,
                "viscous_friction": 1e-5 if angular else 0.1,
                "quadratic_drag": 1e-6 if angular else 0.01,
                "constant_torque": 1e-4 if angular else 0.1,
            }[c.name]
            out.append(typical)
        return np.array(out)


def layout_for(system: str) -> ParameterLayout:
    """The lumped base parameters of ``system`` plus every memoryless library effect."""
    spec = get_spec(system)
    # library order breaks ties between effects the data cannot tell apart: the catch-all
    # constant torque comes after the specific mechanisms
    # constant torque comes after the specific mechanisms, and on a joint loaded by gravity a
    # shifted potential (a centre-of-mass offset) comes first
    generic = [n for n in JOINT_EFFECTS if n not in ("constant_torque", "com_offset")] + ["constant_torque"]
    cands = []
    for j in spec.joint_names:
        gravity = j in GRAVITY_JOINTS[spec.name]
        cands += [Candidate(n, j) for n in (["com_offset"] if gravity else []) + generic]
    cands += [Candidate(n, "u") for n in INPUT_EFFECTS if n not in STATEFUL_EFFECTS]
    return ParameterLayout(
        system=spec.name,
        base=BASE[spec.name],
        base_units=BASE_UNITS[spec.name],
        candidates=tuple(cands),
    )


class LumpedModel(AbstractLagrangianSystem):
    """The declared model written in its lumped parameters, plus every library effect.

    ``theta`` follows :func:`layout_for`; effects with a zero coefficient are absent. Springs go
    into V (rest position 0), the other joint effects into τ_NC, the input gain into τ_u (as
    :class:`furuta_gym.effects.WithEffects` does). Coulomb friction uses sgn(q̇) when
    ``coulomb_smoothing`` is 0 (the equation-error fit) and tanh(q̇/ε) otherwise (simulation).
    """

    theta: jnp.ndarray
    system: str = eqx.field(static=True)
    coulomb_smoothing: float = eqx.field(static=True, default=0.0)

    spec: ClassVar = property(lambda self: get_spec(self.system))  # type: ignore[assignment]

    def _base(self, name):
        return self.theta[BASE[self.system].index(name)]

    def _effect(self, name, joint):
        layout = layout_for(self.system)
        return self.theta[layout.index(f"{name}:{joint}")]

    def _effects(self, names) -> list[Effect]:
        """The library effects ``names`` on every joint, coefficients from ``theta`` (traced)."""
        keys = {c.key for c in layout_for(self.system).candidates}
        return [Effect(n, j, self._effect(n, j)) for j in self.spec.joint_names for n in names
                if f"{n}:{j}" in keys]

    def mass_matrix(self, q):
        if self.system == "furuta":
            b = self._base
            sb, cb = jnp.sin(q[1]), jnp.cos(q[1])
            m11 = b("J1") + b("J1b") * sb**2
            m12 = b("Jc") * cb
            return jnp.stack([jnp.stack([m11, m12]), jnp.stack([m12, b("J2") + 0.0 * m11])])
        return jnp.reshape(self._base("m"), (1, 1))

    def _declared_potential(self, q):
        b = self._base
        if self.system == "furuta":
            return b("G") * (1.0 - jnp.cos(q[1]))
        return 0.5 * b("k1") * q[0] ** 2 + 0.25 * b("k2") * q[0] ** 4

    def potential(self, q):
        # a com_offset shifts the declared potential's zero (linear in δ at δ = 0, which is where
        # the equation-error regressors are taken); springs add ½k·q²
        shift = sum((e.shift(self.spec) for e in self._effects(["com_offset"])), jnp.zeros_like(q))
        v = self._declared_potential(q - shift)
        for j, name in enumerate(self.spec.joint_names):
            v = v + 0.5 * self._effect("spring", name) * q[j] ** 2
        return v

    def nonconservative_force(self, q, qd):
        b = self._base
        if self.system == "furuta":
            tau = jnp.stack([-b("c_alpha") * qd[0], -b("c_beta") * qd[1]])
        else:
            tau = -b("b1") * qd - b("b2") * qd**3
        names = ("coulomb_friction", "stiction", "viscous_friction", "quadratic_drag", "constant_torque")
        extra = []
        for j, name in enumerate(self.spec.joint_names):
            forces = [e.generalized_force(q[j], qd[j], self.coulomb_smoothing)
                      for e in self._effects(names) if e.joint == name]
            extra.append(sum(forces, 0.0 * qd[j]))
        return tau + jnp.stack(extra)

    def input_force(self, q, qd, u):
        gain = self._base(GAIN_PARAMETER[self.system]) * (1.0 + self._effect("input_gain", "u"))
        if self.system == "furuta":
            return jnp.stack([gain * u[0], 0.0 * u[0]])
        return gain * u[:1]
