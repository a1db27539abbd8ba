"""The nonlinear mass-spring-damper (Laiche et al. 2026, §5): its physics, written once, and its
:class:`~furuta_gym.models.SystemDefinition`."""

from __future__ import annotations

import dataclasses
from typing import ClassVar, Mapping

import equinox as eqx
import jax.numpy as jnp

from ..lagrangian import AbstractLagrangianSystem, SystemSpec
from ..systems import NMSD as NMSD_SPEC
from ._system import (
    Equilibrium,
    LumpedForm,
    MujocoTerms,
    RigidBodyCondition,
    SystemDefinition,
    check_rigid_bodies,
    scalar,
)

__all__ = ["NMSD_DEFINITION", "NMSDParameters", "NMSD", "nmsd_energy", "nmsd_potential"]


class NMSDParameters(eqx.Module):
    """Nonlinear mass-spring-damper (paper §5); SI units, force input in newtons."""

    m: jnp.ndarray = eqx.field(default=1.0, converter=scalar)  # mass, kg
    k1: jnp.ndarray = eqx.field(default=10.0, converter=scalar)  # linear stiffness, N/m
    k2: jnp.ndarray = eqx.field(default=5.0, converter=scalar)  # cubic stiffness, N/m³
    b1: jnp.ndarray = eqx.field(default=0.5, converter=scalar)  # linear damping, N·s/m
    b2: jnp.ndarray = eqx.field(default=0.1, converter=scalar)  # cubic damping, N·s³/m³


def nmsd_potential(k1, k2, q):
    """V(p) = ½k1·p² + ¼k2·p⁴."""
    return 0.5 * k1 * q[0] ** 2 + 0.25 * k2 * q[0] ** 4


def nmsd_energy(parameters: Mapping[str, float], x) -> float:
    """T + V at the state ``x`` = (p, ṗ) on plain floats (the envs' per-step ``info["energy"]``)."""
    return 0.5 * parameters["m"] * x[1] * x[1] + nmsd_potential(parameters["k1"], parameters["k2"], x)


class NMSD(AbstractLagrangianSystem):
    """Nonlinear mass-spring-damper: M = m, V = ½k1p² + ¼k2p⁴, τ_NC = −b1ṗ − b2ṗ³, τ_u = u."""

    params: NMSDParameters = eqx.field(default_factory=NMSDParameters)
    spec: ClassVar[SystemSpec] = NMSD_SPEC

    def mass_matrix(self, q):
        return jnp.reshape(self.params.m, (1, 1))

    def potential(self, q):
        return nmsd_potential(self.params.k1, self.params.k2, q)

    def nonconservative_force(self, q, qd):
        p = self.params
        return -p.b1 * qd - p.b2 * qd**3

    def input_force(self, q, qd, u):
        return u[:1]


def _nominal_lumped() -> dict[str, float]:
    p = NMSDParameters()
    return {"m": float(p.m), "k1": float(p.k1), "k2": float(p.k2), "b1": float(p.b1), "b2": float(p.b2), "gain": 1.0}


def _anchor_note(nominal, forced) -> str | None:
    return "scale anchored on the input gain (u is a force in N)" if forced else None


NMSD_LUMPED = LumpedForm(
    names=("m", "k1", "k2", "b1", "b2", "gain"),
    units=("kg", "N/m", "N/m^3", "N s/m", "N s^3/m^3", "1"),
    nominal=_nominal_lumped,
    mass_matrix=lambda b, q: jnp.reshape(b("m"), (1, 1)),
    potential=lambda b, q: nmsd_potential(b("k1"), b("k2"), q),
    damping=lambda b, qd: -b("b1") * qd - b("b2") * qd**3,
    is_physical=lambda p: bool(p["m"] > 0 and p["b1"] >= 0 and p["k1"] >= 0),
    gain="gain",
    scale_anchor="gain",
    anchor_note=_anchor_note,
    mechanical_anchor="m",
)


def write_nmsd_mujoco(model, p: Mapping[str, float]) -> MujocoTerms:
    """The mass; the linear spring and damper native, the cubic terms for the passive callback."""
    model.body_mass[model.body("mass").id] = p["m"]
    return MujocoTerms(stiffness=(p["k1"],), damping=(p["b1"],), cubic_stiffness=(p["k2"],), cubic_damping=(p["b2"],))


def nmsd_body_conditions(b: Mapping[str, float]) -> tuple[RigidBodyCondition, ...]:
    """A body needs a mass > 0."""
    return (RigidBodyCondition("m", b["m"], ("m",)),)


def write_nmsd_lumped_mujoco(model, b: Mapping[str, float]) -> MujocoTerms:
    """The lumped parameters are the physical ones, plus the input's gain."""
    check_rigid_bodies(b, nmsd_body_conditions(b))
    return dataclasses.replace(write_nmsd_mujoco(model, b), motor_gain=b["gain"])


NMSD_DEFINITION = SystemDefinition(
    spec=NMSD_SPEC,
    title="the N-MSD",
    model=NMSD,
    parameters=NMSDParameters,
    lumped=NMSD_LUMPED,
    # m = 1 kg, k1·(1 m)² = 10 J
    learned_defaults=dict(
        hidden=(64, 64),
        mass_scale=1.0,
        potential_scale=10.0,
        force_scale=1.0,
        position_scale=1.0,
        velocity_scale=5.0,
        damping_init=(1.0, 1.0),
        input_gain=1.0,
    ),
    force_defaults={
        # W in the network's force / velocity scale (1 N / 5 m/s) for both; APHYNITY's prior
        # holds M and V exactly; the augmented DeLaN's F_a is odd in q̇ (pure friction)
        "aph": {"damping_scale": 0.2, "force_activation": "silu", "odd_in_velocity": False},
        "adln": {"damping_scale": 0.2, "force_activation": "silu", "odd_in_velocity": True},
    },
    learnable_parameters=("m", "k1", "k2"),
    friction_parameters=("b1", "b2"),
    known_damping_force=lambda coefficients, qd: -coefficients[0] * qd - coefficients[1] * qd**3,
    sample_period=0.01,
    chirp_ranges=((2.0, 5.0), (0.1, 0.3), (0.8, 1.5), None),
    chirp_initial_ranges=((-1.0, 1.0), (-3.0, 3.0)),
    chirp_end_frequency=2.0,
    diagnosis_window=1.0,
    diagnosis_substeps=2,
    elementary_seconds=2.0,  # its simulated trajectories' (the paper has no measured N-MSD)
    diagnosis_segment_seconds=5.0,
    table_title="Table 1 — N-MSD",
    energy_panels=((0, -1.5, 1.5, 1.0, "p [m] (ṗ = 0)"), (1, -1.5, 1.5, 3.0, "ṗ [m/s] (p = 0)")),
    equilibria=(Equilibrium("rest (p = 0)", (0.0,), "p", "minimum"),),  # the spring's stable rest
    lumped_values=dict,
    energy=nmsd_energy,
    write_mujoco=write_nmsd_mujoco,
    write_lumped_mujoco=write_nmsd_lumped_mujoco,
    body_conditions=nmsd_body_conditions,
)
