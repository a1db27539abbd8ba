"""The public QUBE simulators as prediction baselines: their published equations and parameters,
written here from the facts (no code copied), each mapped onto furuta-gym's convention.

Ours (docs/conventions.md): q = (α rotor, β pendulum), β = 0 hanging, β = π upright, positive β
moves the tip the way positive α moves the arm, u in volts with positive u → positive α.

All three use the same rigid-body model as the Quanser workbook and our nominal model
(``furuta_gym.models.Furuta``): a rotary arm of mass Mr and length Lr with Jr = Mr·Lr²/12, a
pendulum rod of mass Mp and length Lp with Jp = Mp·Lp²/12 and its centre of mass at Lp/2,
M = [[Jr + Mp·Lr² + ¼Mp·Lp²·sin²β, ½Mp·Lp·Lr·cosβ], [·, Jp + ¼Mp·Lp²]], gravity ½Mp·g·Lp·sinβ,
viscous damping Dr, Dp on the joints, and a DC motor τ = km·(V − km·α̇)/Rm. They differ in
frames, signs and parameter values:

* **gym_brt** — BlueRiverTech/quanser-openai-driver, ``gym_brt/quanser/qube_simulator.py``
  (commit 1ee8358f): the workbook's closed-form accelerations in (θ, α) with α = 0 **upright**,
  τ = −km·(V − km·θ̇)/Rm. Its hardware env reads θ = −encoder₀ and sends V unchanged
  (``gym_brt/envs/qube_base_env.py``), so θ = −α_ours, V = u, and its mass matrix then fixes
  α_brt = π − β. Mr 0.095, Lr 0.085, Mp 0.024, Lp 0.129, Rm 8.4, km 0.042, Dr 2.7e-4,
  Dp 5e-5, g 9.81. In our frame its back-EMF term is +km²/Rm·α̇: it *adds* 2.1e-4 N·m·s/rad of
  negative damping, leaving the rotor a net 6e-5 (as published; we keep it).
* **quanser_robots** — TU Darmstadt's QQube (``quanser_robots/qube/base.py``, ``QubeDynamics``;
  read in its copy al91liwo/pytorch-rl-lab, commit 10699fbc) and SimuRLacra's ``QQubeSim``
  (famura/SimuRLacra, ``Pyrado/pyrado/environments/pysim/quanser_qube.py``, commit 01d47c57):
  M·q̈ = rhs in (θ, α) with α = 0 hanging, θ = α_ours, α = β, V = u. Same masses, lengths, Rm, km
  as above; Dr 5e-6, Dp 1e-6 ("identified", replacing 0.0015 / 0.0005).
* **Armandpl** — Armandpl/furuta: ``QubeDynamics`` in ``furuta/robot.py`` (commit 07d92d41) is
  the quanser_robots model (same equations and QUBE values, the action scaled by V = 12 V);
  ``furuta_params.py`` (commit 3d8d658d) gives the values for **the author's own home-built rig**,
  not a QUBE: Rm 6.7, km 0.067, Mr 0.057, Lr 0.083, Mp 0.027, Lp 0.092, Dr 5e-6, Dp 1e-6. That rig
  is the row here (the QUBE values would repeat quanser_robots). Its later pinocchio/URDF model
  of a geared 24 V rig is not a QUBE model either and is left out.

Only their physics is compared: each is integrated by the benchmark's common RK4 (4 substeps per
2 ms period, input held), not by its own scheme (gym_brt: ``odeint`` or semi-implicit Euler;
Armandpl: semi-implicit Euler; SimuRLacra: an RK4 whose stages all evaluate the start state).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import jax.numpy as jnp

QUBE = dict(Mr=0.095, Lr=0.085, Mp=0.024, Lp=0.129, Rm=8.4, km=0.042, g=9.81)


@dataclasses.dataclass(frozen=True)
class Frame:
    """Their state from ours: θ = rotor·α, α_theirs = pendulum·β + offset, V = voltage·u."""

    rotor: float = 1.0
    pendulum: float = 1.0
    offset: float = 0.0
    voltage: float = 1.0

    def state(self, x):
        return jnp.stack(
            [self.rotor * x[0], self.pendulum * x[1] + self.offset, self.rotor * x[2], self.pendulum * x[3]]
        )


@dataclasses.dataclass(frozen=True)
class Baseline:
    name: str
    label: str
    source: str
    params: dict
    frame: Frame
    accelerations: Callable  # (params, θ, α, θ̇, α̇, V) -> (θ̈, α̈) in their frame

    def vector_field(self, x, u):
        """ẋ in our frame for our state x = (α, β, α̇, β̇) and our input u (V)."""
        th, al, thd, ald = self.frame.state(x)
        thdd, aldd = self.accelerations(self.params, th, al, thd, ald, self.frame.voltage * u[0])
        return jnp.stack([x[2], x[3], self.frame.rotor * thdd, self.frame.pendulum * aldd])

    def with_params(self, **changes) -> "Baseline":
        return dataclasses.replace(self, params={**self.params, **changes})


def _inertias(p):
    return p["Mr"] * p["Lr"] ** 2 / 12, p["Mp"] * p["Lp"] ** 2 / 12


def brt_accelerations(p, th, al, thd, ald, V):
    """The workbook's closed form as gym_brt publishes it (α = 0 upright, τ = −km(V − km·θ̇)/Rm)."""
    Jr, Jp = _inertias(p)
    Mp, Lp, Lr, g, Dr, Dp = p["Mp"], p["Lp"], p["Lr"], p["g"], p["Dr"], p["Dp"]
    tau = -(p["km"] * (V - p["km"] * thd)) / p["Rm"]
    s, c, s2 = jnp.sin(al), jnp.cos(al), jnp.sin(2 * al)
    rotor = 4 * Dr * thd + Lp**2 * ald * Mp * thd * s2 + 2 * Lp * Lr * ald**2 * Mp * s - 4 * tau
    pend = -8 * Dp * ald + Lp**2 * Mp * thd**2 * s2 + 4 * Lp * g * Mp * s
    den = 4 * Lp**2 * Lr**2 * Mp**2 * c**2 - (4 * Jp + Lp**2 * Mp) * (4 * Jr + Lp**2 * Mp * s**2 + 4 * Lr**2 * Mp)
    thdd = (-Lp * Lr * Mp * pend * c + (4 * Jp + Lp**2 * Mp) * rotor) / den
    aldd = (2 * Lp * Lr * Mp * rotor * c - 0.5 * (4 * Jr + Lp**2 * Mp * s**2 + 4 * Lr**2 * Mp) * pend) / den
    return thdd, aldd


def qq_accelerations(p, th, al, thd, ald, V):
    """M·q̈ = τ − C(q, q̇) as quanser_robots / SimuRLacra / Armandpl write it (α = 0 hanging)."""
    Jr, Jp = _inertias(p)
    Mp, Lp, Lr = p["Mp"], p["Lp"], p["Lr"]
    c1, c2, c3, c4, c5 = (
        Jr + Mp * Lr**2,
        0.25 * Mp * Lp**2,
        0.5 * Mp * Lp * Lr,
        Jp + 0.25 * Mp * Lp**2,
        0.5 * Mp * Lp * p["g"],
    )
    s, c, s2 = jnp.sin(al), jnp.cos(al), jnp.sin(2 * al)
    a, b, d = c1 + c2 * s**2, c3 * c, c4
    det = a * d - b * b
    trq = p["km"] * (V - p["km"] * thd) / p["Rm"]
    x = trq - p["Dr"] * thd - (c2 * s2 * thd * ald - c3 * s * ald**2)
    y = -p["Dp"] * ald - (-0.5 * c2 * s2 * thd**2 + c5 * s)
    return (d * x - b * y) / det, (a * y - b * x) / det


BASELINES = {
    "gym_brt": Baseline(
        "gym_brt",
        "gym_brt (BlueRiverTech quanser-openai-driver)",
        "BlueRiverTech/quanser-openai-driver gym_brt/quanser/qube_simulator.py",
        {**QUBE, "Dr": 2.7e-4, "Dp": 5e-5},
        Frame(rotor=-1.0, pendulum=-1.0, offset=math.pi),
        brt_accelerations,
    ),
    "quanser_robots": Baseline(
        "quanser_robots",
        "quanser_robots QQube / SimuRLacra QQubeSim (TU Darmstadt)",
        "TU Darmstadt quanser_robots/qube/base.py (QubeDynamics; read in its copy al91liwo/pytorch-rl-lab); "
        "famura/SimuRLacra Pyrado/pyrado/environments/pysim/quanser_qube.py",
        {**QUBE, "Dr": 5e-6, "Dp": 1e-6},
        Frame(),
        qq_accelerations,
    ),
    "armandpl": Baseline(
        "armandpl",
        "Armandpl/furuta (the author's own rig)",
        "Armandpl/furuta furuta/robot.py (QubeDynamics) with furuta_params.py",
        dict(Mr=0.057, Lr=0.083, Mp=0.027, Lp=0.092, Rm=6.7, km=0.067, g=9.81, Dr=5e-6, Dp=1e-6),
        Frame(),
        qq_accelerations,
    ),
}
