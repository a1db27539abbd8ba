"""Closed-form models of the two benchmark systems (the paper's "nominal models", section 5).

Physical parameters are Equinox pytrees of float64 scalars, so they can be fitted with the same
machinery as network weights (``eqx.filter(model, eqx.is_inexact_array)``).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from .._x64 import ensure_x64
from ..lagrangian import AbstractLagrangianSystem, SystemSpec
from ..systems import FURUTA, NMSD

__all__ = ["ANALYTIC", "FurutaParameters", "Furuta", "NMSDParameters", "NMSD", "furuta_lumped", "furuta_mass_matrix",
           "furuta_potential", "nmsd_potential"]


def _scalar(x) -> jnp.ndarray:
    ensure_x64()
    return jnp.asarray(x, dtype=float)


class FurutaParameters(eqx.Module):
    """Quanser QUBE-Servo 2 rotary pendulum (DEVELOPERS.md "Conventions"; SI units, volts)."""

    mr: jnp.ndarray = eqx.field(default=0.095, converter=_scalar)  # rotor arm mass, kg
    Lr: jnp.ndarray = eqx.field(default=0.085, converter=_scalar)  # rotor arm length, m
    mp: jnp.ndarray = eqx.field(default=0.024, converter=_scalar)  # pendulum mass, kg
    Lp: jnp.ndarray = eqx.field(default=0.129, converter=_scalar)  # pendulum length, m
    g: jnp.ndarray = eqx.field(default=9.81, converter=_scalar)  # gravity, m/s²
    c_r: jnp.ndarray = eqx.field(default=3e-4, converter=_scalar)  # rotor viscous friction, N·m·s/rad
    c_p: jnp.ndarray = eqx.field(default=1.5e-5, converter=_scalar)  # pendulum viscous friction
    kt: jnp.ndarray = eqx.field(default=0.042, converter=_scalar)  # motor torque constant, N·m/A
    km: jnp.ndarray = eqx.field(default=0.042, converter=_scalar)  # back-EMF constant, V·s/rad
    Rm: jnp.ndarray = eqx.field(default=8.4, converter=_scalar)  # terminal resistance, Ω

    @property
    def Jr(self):
        """Rotor arm inertia about the motor axis, mr·Lr²/12 (Quanser's convention)."""
        return self.mr * self.Lr**2 / 12.0

    @property
    def Jp(self):
        """Pendulum inertia about its centre of mass, mp·Lp²/12."""
        return self.mp * self.Lp**2 / 12.0

    @property
    def J1(self):
        return self.Jr + self.mp * self.Lr**2

    @property
    def J2(self):
        return self.Jp + self.mp * self.Lp**2 / 4.0


def furuta_lumped(p: FurutaParameters) -> dict[str, jnp.ndarray]:
    """The Furuta's M and V in the parameters they are linear in: J1 (Jr + mp·Lr²), J1b
    (¼mp·Lp², the sin²β term), Jc (½mp·Lr·Lp), J2 (Jp + ¼mp·Lp²), G (½mp·g·Lp). The
    diagnosis fits these (furuta_gym.diagnose)."""
    return {"J1": p.J1, "J1b": 0.25 * p.mp * p.Lp**2, "Jc": 0.5 * p.mp * p.Lr * p.Lp, "J2": p.J2,
            "G": 0.5 * p.mp * p.g * p.Lp}


def furuta_mass_matrix(J1, J1b, Jc, J2, q):
    """M(q) = [[J1 + J1b·sin²β, Jc·cosβ], [Jc·cosβ, J2]]."""
    sb, cb = jnp.sin(q[1]), jnp.cos(q[1])
    m11 = J1 + J1b * sb**2
    m12 = Jc * cb
    return jnp.stack([jnp.stack([m11, m12]), jnp.stack([m12, J2 * jnp.ones_like(m11)])])


def furuta_potential(G, q):
    """V(q) = G·(1 − cosβ): β = 0 hanging down."""
    return G * (1.0 - jnp.cos(q[1]))


class Furuta(AbstractLagrangianSystem):
    """Furuta pendulum, q = (α, β), β = 0 hanging down, u in volts (Laiche et al. 2026, §5).

    M = [[J1 + ¼mpLp²sin²β, ½mpLrLp cosβ], [½mpLrLp cosβ, J2]], V = ½mp g Lp (1 − cosβ),
    τ_NC = (−c_r α̇, −c_p β̇), τ_u = ((kt/Rm)(u − km α̇), 0). Unlike the paper (−u), positive
    voltage drives positive α.
    """

    params: FurutaParameters = eqx.field(default_factory=FurutaParameters)
    spec: ClassVar[SystemSpec] = FURUTA

    def mass_matrix(self, q):
        b = furuta_lumped(self.params)
        return furuta_mass_matrix(b["J1"], b["J1b"], b["Jc"], b["J2"], q)

    def potential(self, q):
        return furuta_potential(furuta_lumped(self.params)["G"], q)

    def nonconservative_force(self, q, qd):
        p = self.params
        return jnp.stack([-p.c_r * qd[0], -p.c_p * qd[1]])

    def input_force(self, q, qd, u):
        p = self.params
        return jnp.stack([p.kt / p.Rm * (u[0] - p.km * qd[0]), jnp.zeros_like(u[0])])


class NMSDParameters(eqx.Module):
    """Nonlinear mass-spring-damper (paper §5); SI units, force input in newtons."""

    m: jnp.ndarray = eqx.field(default=1.0, converter=_scalar)  # mass, kg
    k1: jnp.ndarray = eqx.field(default=10.0, converter=_scalar)  # linear stiffness, N/m
    k2: jnp.ndarray = eqx.field(default=5.0, converter=_scalar)  # cubic stiffness, N/m³
    b1: jnp.ndarray = eqx.field(default=0.5, converter=_scalar)  # linear damping, N·s/m
    b2: jnp.ndarray = eqx.field(default=0.1, converter=_scalar)  # cubic damping, N·s³/m³


def nmsd_potential(k1, k2, q):
    """V(p) = ½k1·p² + ¼k2·p⁴."""
    return 0.5 * k1 * q[0] ** 2 + 0.25 * k2 * q[0] ** 4


class NMSD(AbstractLagrangianSystem):
    """Nonlinear mass-spring-damper: M = m, V = ½k1p² + ¼k2p⁴, τ_NC = −b1ṗ − b2ṗ³, τ_u = u."""

    params: NMSDParameters = eqx.field(default_factory=NMSDParameters)
    spec: ClassVar[SystemSpec] = NMSD

    def mass_matrix(self, q):
        return jnp.reshape(self.params.m, (1, 1))

    def potential(self, q):
        return nmsd_potential(self.params.k1, self.params.k2, q)

    def nonconservative_force(self, q, qd):
        p = self.params
        return -p.b1 * qd - p.b2 * qd**3

    def input_force(self, q, qd, u):
        return u[:1]


#: each system's analytic model and its parameters
ANALYTIC = {"furuta": (Furuta, FurutaParameters), "nmsd": (NMSD, NMSDParameters)}
