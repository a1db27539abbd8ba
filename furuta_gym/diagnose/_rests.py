"""What a joint's rests say about its dry friction: the force that held it.

Where a quantised encoder shows a joint at one count for a long stretch, the joint was held: the
dry friction balanced every other force on it (input, springs, gravity, the other joints' coupling)
up to its breakaway level. The friction that held it is the model's inverse dynamics at that state
with the joint's velocity and acceleration zero, minus the input force. Averaged over a window of
``window`` seconds inside a rest, it is measured well (estimated accelerations average out; a joint
oscillating within one count at high frequency averages to no force), and to within a slack
2·M_jj·count/window² (the largest force above the friction limit that can act a whole window without
moving the joint by a count). The largest held force bounds the breakaway level from below: no
velocity estimate enters, so it is free of the attenuation that smears sgn(q̇) around slow
reversals and biases friction fitted from velocities low.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..data import Trajectory
from ..lagrangian import inverse_dynamics
from ..measured import estimate_velocities
from ..signals import ENCODER_COUNTS_PER_REV
from ..systems import get_spec
from ._drift import _runs_within, flicker_tolerance
from ._fit import (
    NO_INPUT_DYNAMICS,
    InputDynamics,
    Segment,
    _compiled,
    free_acceleration_along,
    free_excursion,
    value_runs,
)
from ._library import ParameterLayout

__all__ = ["RestBound", "rest_bound", "held_at_rest", "Stop", "stop_excursions", "breakaway_bracket"]


@dataclasses.dataclass(frozen=True)
class RestBound:
    """The largest friction force that held a joint at rest (N·m or N), less the slack, over
    ``n_windows`` rest windows; 0 with no window."""

    joint: str
    held: float
    n_windows: int
    slack: float


def _holding(layout: ParameterLayout, j: int):
    """Batched friction force on joint ``j`` that holds it at rest: inverse dynamics of the model
    without its dry friction at (q, q̇ with q̇_j = 0, q̈ with q̈_j = 0), minus the input force."""

    def build():
        def one(theta, q, qd, qdd, u):
            model = layout.model(theta, dry_friction=False)
            qd, qdd = qd.at[j].set(0.0), qdd.at[j].set(0.0)
            return (inverse_dynamics(model, q, qd, qdd) - model.input_force(q, qd, u))[j]

        return jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0, 0)))

    return _compiled("holding", layout, j, build=build)


def _rest_windows(q_j: np.ndarray, length: int) -> list[tuple[int, int]]:
    """(start, end) of consecutive windows of ``length`` samples inside runs of one count, laid
    back from each run's end: the force that held the joint is largest just before it broke away."""
    change = np.flatnonzero(np.diff(q_j) != 0) + 1
    bounds = np.concatenate([[0], change, [q_j.size]])
    return [
        (k, k + length) for s, e in zip(bounds[:-1], bounds[1:], strict=True) for k in range(e - length, s - 1, -length)
    ]


def rest_bound(
    layout: ParameterLayout,
    theta,
    segments: list[Segment],
    dynamics: InputDynamics,
    joint: str,
    count: float,
    window: float,
) -> RestBound:
    """The largest mean force that held ``joint`` over a ``window``-second stretch at one encoder
    ``count`` in ``segments``, less the slack (see the module docstring)."""
    j = get_spec(layout.system).joint_names.index(joint)
    holding = _holding(layout, j)
    held, n, mass = 0.0, 0, 0.0
    for seg in segments:
        length = int(round(window / seg.dt))
        spans = _rest_windows(seg.q[:, j], length)
        if not spans:
            continue
        idx = np.concatenate([np.arange(a, b) for a, b in spans])
        qdd = np.gradient(seg.qd, seg.dt, axis=0)
        u = dynamics.apply(seg.u, seg.dt)
        force = np.asarray(
            holding(
                jnp.asarray(theta),
                jnp.asarray(seg.q[idx]),
                jnp.asarray(seg.qd[idx]),
                jnp.asarray(qdd[idx]),
                jnp.asarray(u[idx]),
            )
        )
        means = np.abs(force.reshape(len(spans), length).mean(axis=1))
        held, n = max(held, float(means.max())), n + len(spans)
        m = layout.model(jnp.asarray(theta)).mass_matrix(jnp.asarray(seg.q[idx[0]]))
        mass = max(mass, float(m[j, j]))
    slack = 2.0 * mass * count / window**2
    return RestBound(joint, max(0.0, held - slack) if n else 0.0, n, slack)


def held_at_rest(
    trajectories: Sequence[Trajectory],
    joint: str,
    layout: ParameterLayout,
    theta,
    *,
    window: float = 0.2,
    count: float = 2 * np.pi / ENCODER_COUNTS_PER_REV,
) -> RestBound:
    """The force that held ``joint`` at rest in measured ``trajectories`` under the model
    ``layout``/``theta`` (e.g. the true one, to judge the bound itself): what the diagnosis
    compares with a fitted Coulomb level. ``count`` is the encoder's resolution (rad); velocities
    are estimated where a trajectory has none, as the diagnosis estimates them."""
    segments = []
    for i, tr in enumerate(trajectories):
        tr = estimate_velocities(tr)  # measured velocities are kept
        assert tr.qd is not None
        segments.append(Segment(tr.name, tr.t, tr.q, tr.qd, tr.u, tr.dt, i, False))
    return rest_bound(layout, theta, segments, NO_INPUT_DYNAMICS, joint, count, window)


@dataclasses.dataclass(frozen=True)
class Stop:
    """A run of ``samples`` samples of one trajectory on one logged value of a joint, from sample
    ``start``, and how far the model's forces other than dry friction would have moved the joint,
    free, over it (its least range over every start velocity, in counts): at most one through a
    reversal or a slow pass; more, and friction held it (``DiagnosisSettings.held_stop``)."""

    trajectory: str
    start: int
    samples: int
    excursion: float


def stop_excursions(
    trajectories: Sequence[Trajectory],
    joint: str,
    layout: ParameterLayout,
    theta,
    *,
    min_samples: int = 20,
    count: float = 2 * np.pi / ENCODER_COUNTS_PER_REV,
) -> list[Stop]:
    """Every run of at least ``min_samples`` on one value of ``joint`` inside measured
    ``trajectories`` (not at their ends) with its free excursion under ``layout``/``theta``, as
    ``diagnose`` measures it (velocities estimated where a trajectory has none)."""
    j = get_spec(layout.system).joint_names.index(joint)
    out = []
    for tr in trajectories:
        tr = estimate_velocities(tr)
        assert tr.qd is not None
        a = free_acceleration_along(layout, theta, tr.q, tr.qd, tr.u, tr.dt, j)
        interior = value_runs(tr.q[:, j])[1:-1]  # a run at either end may go on outside the log
        for s, e in zip(interior[:-1], interior[1:], strict=True):
            if e - s >= min_samples:
                out.append(Stop(tr.name, int(s), int(e - s), free_excursion(a[s:e], tr.dt) / count))
    return out


# ----------------------------------------------------------------------------- the breakaway's bracket


def holding_forces(layout: ParameterLayout, j: int, trajectories: Sequence[Trajectory], theta) -> list[np.ndarray]:
    """Per trajectory, the force (N·m or N) friction would balance to hold joint ``j`` still at
    each sample under ``layout``/``theta``: the model's inverse dynamics with the joint's velocity
    and acceleration zero, less the input (the other joints' motion, from estimated velocities
    and accelerations, pushes on it too)."""
    holding = _holding(layout, j)
    out = []
    for tr in trajectories:
        qd = np.asarray(estimate_velocities(tr).qd)
        qdd = np.gradient(qd, tr.dt, axis=0)
        args = [jnp.asarray(x) for x in (tr.q, qd, qdd, np.asarray(tr.u, float))]
        out.append(np.asarray(holding(jnp.asarray(theta), *args)))
    return out


def held_forces(trajectories, forces, j: int, tolerance: float, min_rest: float) -> np.ndarray:
    """The force each rest held, signed: over each run of ``min_rest`` s of joint ``j`` within
    ``tolerance`` of its first value (an encoder flickering by a count under a resting joint does
    not cut the rest), the median of ``forces`` (the other joints' pull, read with noise, averages
    out)."""
    out = []
    for tr, f in zip(trajectories, forces, strict=True):
        bounds = _runs_within(np.asarray(tr.q[:, j], float), tolerance)
        runs = zip(bounds[:-1], bounds[1:], strict=True)
        out += [float(np.median(f[a:b])) for a, b in runs if b - a >= int(round(min_rest / tr.dt))]
    return np.asarray(out)


def held_force(trajectories, forces, j: int, tolerance: float, min_rest: float) -> float:
    """The largest force a rest held (:func:`held_forces`); 0 without a rest. The breakaway was at
    least that."""
    return float(np.abs(held_forces(trajectories, forces, j, tolerance, min_rest)).max(initial=0.0))


def moving_force(
    trajectories, forces, j: int, tolerance: float, min_rest: float, first_rest: float, span: float
) -> float | None:
    """The least force that moved joint ``j`` off a rest: a run of ``min_rest`` s within
    ``tolerance`` that the joint left, or a trajectory's first run of ``first_rest`` s (a released
    joint starts at rest: a moving one passes a count sooner) (:func:`_left_rests`). Each rest's
    force is the largest of ``forces`` over the last ``span`` s before it left: the other joints'
    pull, from estimated accelerations, is read with noise, and a noisy least would put the bound
    below the breakaway (it is an upper bound: a larger reading only loosens it). None: no rest
    was left. The breakaway was at most that."""
    out = []
    for tr, f in zip(trajectories, forces, strict=True):
        q = np.asarray(tr.q[:, j], float)
        out += [float(np.abs(f[a:b]).max()) for a, b in _left_rests(q, tr.dt, tolerance, min_rest, first_rest, span)]
    return min(out) if out else None


def _left_rests(q, dt: float, tolerance: float, min_rest: float, first_rest: float, span: float, moved: int = 4):
    """(start, end) of the last ``span`` s of each rest of ``q`` that the joint left (see
    :func:`moving_force`): moving on by ``moved`` tolerances within 2·``span`` s. A joint held by a
    soft friction (MuJoCo's, a real joint's) creeps a count under a load below its breakaway and
    rests again: that rest was not broken."""
    bounds = _runs_within(q, tolerance)
    n = int(round(span / dt))
    out = []
    for k, (s, e) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        least = first_rest if k == 0 else min_rest
        if e - s >= int(round(least / dt)) and np.any(np.abs(q[e : e + 2 * n] - q[e - 1]) >= moved * tolerance):
            out.append((max(s, e - n), e))
    return out


def breakaway_bracket(
    trajectories: Sequence[Trajectory],
    joint: str,
    layout: ParameterLayout,
    theta,
    *,
    count: float = 2 * np.pi / ENCODER_COUNTS_PER_REV,
    flicker: int = 1,
    min_rest: float = 0.2,
) -> tuple[float, float | None]:
    """(at least, at most) the breakaway of ``joint`` in measured ``trajectories`` under the model
    ``layout``/``theta``, as Method step 11 reads it: the largest force a rest held
    (:func:`held_force`) and the least that moved the joint off one (:func:`moving_force`; None:
    no rest was left), each rest read through an encoder flicker of ``flicker`` counts of
    ``count``."""
    j = get_spec(layout.system).joint_names.index(joint)
    forces = holding_forces(layout, j, trajectories, theta)
    tolerance = flicker_tolerance(flicker, count)
    return (
        held_force(trajectories, forces, j, tolerance, min_rest),
        moving_force(trajectories, forces, j, tolerance, min_rest, 0.01, 0.05),
    )
