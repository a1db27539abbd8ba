"""Measured-like datasets with a known undeclared effect, for tests, demos and benchmarks.

The plant is the MuJoCo ground truth with the effects written into it
(:class:`furuta_gym.envs._backends.MujocoBackend`, a plant variant; Coulomb friction as the exact
sgn law) — or, with ``plant="analytic"``, the analytic model plus
:class:`furuta_gym.effects.WithEffects` — integrated with RK4 and the input held over each sample
period, as a digital controller drives hardware. An input delay is the plant seeing the command
whole samples late. What the user would log is then produced:
encoder-quantised angles at 500 Hz for the Furuta (2048 counts/rev), positions with small
Gaussian noise at 100 Hz for the N-MSD; no velocities.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from .._x64 import ensure_x64
from ..data import Trajectory
from ..effects import Effect, WithEffects
from ..models import NMSD, Furuta
from ..signals import chirp, quantize_encoder
from ..simulate import rollout_zoh

__all__ = ["measured_like"]


def _inputs(system: str, t: np.ndarray, rng: np.random.Generator, forced: bool) -> np.ndarray:
    if not forced:
        return np.zeros_like(t)
    if system == "furuta":
        amp = rng.uniform(0.6, 1.5)
        f0, f1 = rng.uniform(0.3, 1.0), rng.uniform(2.0, 5.0)
        offset = rng.uniform(-0.15, 0.15)
    else:
        amp = rng.uniform(2.0, 5.0)
        f0, f1 = rng.uniform(0.1, 0.3), rng.uniform(0.8, 1.5)
        offset = 0.0
    return offset + chirp(t, f0, f1, t[-1], amplitude=amp, phase=rng.uniform(0, 2 * np.pi))


def measured_like(
    system: str,
    effects: Sequence[Effect] = (),
    *,
    n_trajectories: int = 6,
    duration: float = 5.0,
    seed: int = 0,
    forced: bool = True,
    noise: float | None = None,
    plant: str = "mujoco",
    substeps: int = 10,
) -> list[Trajectory]:
    """Trajectories of the pinned model with ``effects`` added, as a sensor would log them.

    Random initial states (Furuta: α0 ~ U(−1, 1), β0 ~ U(−π, π), velocities ~ U(−3, 3); N-MSD:
    p0 ~ U(−1, 1), ṗ0 ~ U(−3, 3)) and random chirp inputs. ``input_delay`` is applied as the
    plant seeing the command ``round(d/dt)`` samples late.
    """
    ensure_x64()
    rng = np.random.default_rng(seed)
    fur = system == "furuta"
    dt = 0.002 if fur else 0.01
    base = Furuta() if fur else NMSD()
    delay = sum(e.coefficient for e in effects if e.name == "input_delay")
    mem = [e for e in effects if e.name != "input_delay"]
    T = int(round(duration / dt)) + 1
    t = np.arange(T) * dt
    if plant == "mujoco":
        from ..envs._backends import MujocoBackend

        backend = MujocoBackend(system, substeps=1, effects=mem)
        assert abs(backend.control_dt - dt) < 1e-12

        def roll(x0, us):
            backend.reset(np.asarray(x0))
            return np.stack([np.asarray(x0)] + [backend.step(np.asarray(u_k)) for u_k in us])

    elif plant == "analytic":
        model = WithEffects(base, mem, coulomb_smoothing=1e-3) if mem else base
        roll = jax.jit(lambda x0, us: rollout_zoh(model, x0, us, dt, substeps))
    else:
        raise ValueError(f"plant must be 'mujoco' or 'analytic', got {plant!r}")
    shift = int(round(delay / dt))
    out = []
    for k in range(n_trajectories):
        if fur:
            x0 = np.array([rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi), rng.uniform(-3, 3), rng.uniform(-3, 3)])
        else:
            x0 = np.array([rng.uniform(-1, 1), rng.uniform(-3, 3)])
        u = _inputs(system, t, rng, forced)
        u_plant = np.concatenate([np.full(shift, u[0]), u[: T - shift]]) if shift else u
        xs = np.asarray(roll(x0, u_plant[:-1, None]))
        n = 2 if fur else 1
        q = xs[:, :n]
        if fur:
            q = quantize_encoder(q)
        else:
            q = q + rng.normal(0.0, 1e-3 if noise is None else noise, q.shape)
        out.append(Trajectory(t=t.copy(), q=q, u=u[:, None], qd=None, name=str(k)))
    return out
