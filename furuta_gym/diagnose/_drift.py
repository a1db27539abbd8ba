"""Where a joint comes to rest after large excursions: a cable whose rest moves, or a fixed one
held by friction, told apart from the log alone (issue 64 item 2; no model is fitted).

A fixed cable of stiffness k whose neutral friction holds up to a breakaway F_s keeps every rest
within ±F_s/k of one neutral, whatever the excursions: after a large one the rotor slides back
past the neutral and stops where its friction catches it. A cable whose rest moves (the play
operator: its neutral dragged along beyond a play) leaves the rotor near where the excursion
dragged the neutral: each rest moves towards the excursion before it, on either side.

A rest is a run of at least ``min_rest`` seconds on one logged value (one encoder count; with
``flicker`` = n, within n counts of its first value, so that an encoder flickering between two
counts under a resting joint does not cut the rest into pieces). The
rests of all trajectories are taken in order as one history, so a log of releases
(``excitation="rotor_releases"``, each trajectory continuing where the last left it) or of sweeps
is read as it was recorded. For each rest after a large excursion (at least ``large`` from the
rest before it) from which the joint came back (by at least ``returned``: a rotor that stayed
where the excursion left it says nothing, either law holds it there), the share of the
excursion the rest followed is (R_i − R_{i−1}) / (E_i − R_{i−1}): about 1 − play/excursion for a
moving rest, at most 2·(F_s/k)/excursion and mostly negative (an overshoot past the neutral) for
a fixed neutral.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from ..data import Trajectory
from ..signals import ENCODER_COUNTS_PER_REV
from ..systems import get_spec
from ._fit import value_runs

__all__ = ["Rest", "RestDrift", "rest_drift", "REST_LAWS"]

#: the verdicts of :func:`rest_drift`
REST_LAWS = ("moving rest", "fixed neutral held by friction", "cannot tell")


@dataclasses.dataclass(frozen=True)
class Rest:
    """A run of ``samples`` samples of trajectory ``trajectory`` from ``start`` on one value,
    ``position``; ``excursion``: the farthest point from the previous rest reached since it (None
    for the first rest of the log)."""

    trajectory: str
    start: int
    samples: int
    position: float
    excursion: float | None


@dataclasses.dataclass(frozen=True)
class RestDrift:
    """What a log's rests say about the law that holds a joint (see the module docstring).

    ``spread``: max − min of the rest positions; ``follows``: the share of each large excursion
    that the rest after it followed (those from which the joint came back), with ``sides`` the
    excursions' signs; ``follow_positive`` / ``follow_negative``: their medians on each side
    (None: no such excursion). ``verdict`` is one of :data:`REST_LAWS`, ``reason`` says why."""

    joint: str
    rests: tuple[Rest, ...]
    spread: float
    follows: tuple[float, ...]
    sides: tuple[int, ...]
    follow_positive: float | None
    follow_negative: float | None
    verdict: str
    reason: str

    def to_json(self) -> dict:
        return dict(
            joint=self.joint,
            n_rests=len(self.rests),
            spread=self.spread,
            rest_positions=[r.position for r in self.rests],
            follows=list(self.follows),
            sides=list(self.sides),
            follow_positive=self.follow_positive,
            follow_negative=self.follow_negative,
            verdict=self.verdict,
            reason=self.reason,
        )


def flicker_tolerance(flicker: int, count: float) -> float:
    """How far a resting joint's reading may stray from its first value and still be one rest:
    ``flicker`` encoder counts of ``count`` (rad or m), with a margin for counts held as floats."""
    return flicker * count * 1.01


def _runs_within(q: np.ndarray, tolerance: float) -> np.ndarray:
    """Bounds [0, …, T] of the runs of ``q`` that stay within ``tolerance`` of their first value
    (greedy from the start); ``tolerance`` 0: runs on one value."""
    if tolerance <= 0:
        return value_runs(q)
    bounds, start = [0], q[0]
    for k in range(1, q.size):
        if abs(q[k] - start) > tolerance:
            bounds.append(k)
            start = q[k]
    return np.asarray(bounds + [q.size])


def _rests(trajectories: Sequence[Trajectory], j: int, min_rest: float, tolerance: float) -> list[Rest]:
    """Every run of at least ``min_rest`` s on one value of joint ``j``, in order, each with the
    farthest point from the rest before it reached since that rest."""
    out: list[Rest] = []
    far: float | None = None  # farthest point from the last rest so far
    for tr in trajectories:
        q = np.asarray(tr.q[:, j], dtype=float)
        bounds = _runs_within(q, tolerance)
        length = int(round(min_rest / tr.dt))
        for s, e in zip(bounds[:-1], bounds[1:], strict=True):
            if out:
                stretch = q[s:e]
                k = int(np.argmax(np.abs(stretch - out[-1].position)))
                if far is None or abs(stretch[k] - out[-1].position) > abs(far - out[-1].position):
                    far = float(stretch[k])
            if e - s >= length:
                out.append(Rest(tr.name, int(s), int(e - s), float(np.median(q[s:e])), far if out else None))
                far = None
    return out


def _median(values) -> float | None:
    return float(np.median(values)) if len(values) else None


def _verdict(pos, neg, min_each: int, min_pairs: int, follow: float) -> tuple[str, str]:
    """(verdict, reason) from the shares followed after large excursions on each side."""
    if len(pos) < min_each or len(neg) < min_each or len(pos) + len(neg) < min_pairs:
        return REST_LAWS[2], (
            f"{len(pos)} large excursion(s) up and {len(neg)} down came back to a rest; "
            f"at least {min_each} each way and {min_pairs} in all are needed"
        )
    up, down = float(np.median(pos)), float(np.median(neg))
    if up >= follow and down >= follow:
        return REST_LAWS[0], (
            f"rests moved towards the excursion before them on both sides "
            f"(median share followed {up:.2f} up, {down:.2f} down; ≥ {follow} each)"
        )
    if up < follow and down < follow:
        return REST_LAWS[1], (
            f"rests came back after excursions on both sides (median share followed {up:.2f} up, "
            f"{down:.2f} down; < {follow} each)"
        )
    return REST_LAWS[2], f"rests followed excursions on one side only (median share {up:.2f} up, {down:.2f} down)"


def rest_drift(
    trajectories: Sequence[Trajectory],
    system: str = "furuta",
    joint: str = "alpha",
    *,
    min_rest: float = 0.3,
    large: float = 0.3,
    returned: float = 0.05,
    follow: float = 0.15,
    min_each: int = 1,
    min_pairs: int = 3,
    flicker: int = 0,
    count: float = 2 * np.pi / ENCODER_COUNTS_PER_REV,
) -> RestDrift:
    """Whether ``joint``'s rests in measured ``trajectories`` (in recorded order) follow its large
    excursions (a rest that moves) or stay by one neutral (a fixed one held by friction), with the
    numbers; no model is fitted (module docstring). ``large`` and ``returned`` are in the joint's
    unit; ``follow`` is the median share followed, on each side, that splits the two laws;
    ``min_each`` large excursions each way, ``min_pairs`` in all, are needed for a verdict other
    than "cannot tell" (a law seen on one side only could be a constant force). ``flicker``: a
    rest may flicker by that many encoder counts of ``count`` (rad or m)."""
    j = get_spec(system).joint_names.index(joint)
    rests = _rests(trajectories, j, min_rest, flicker_tolerance(flicker, count))
    follows, sides = [], []
    for before, rest in zip(rests[:-1], rests[1:], strict=True):
        assert rest.excursion is not None
        reach = rest.excursion - before.position
        if abs(reach) >= large and abs(rest.excursion - rest.position) >= returned:
            follows.append((rest.position - before.position) / reach)
            sides.append(int(np.sign(reach)))
    pos = [f for f, s in zip(follows, sides, strict=True) if s > 0]
    neg = [f for f, s in zip(follows, sides, strict=True) if s < 0]
    verdict, reason = _verdict(pos, neg, min_each, min_pairs, follow)
    positions = [r.position for r in rests]
    return RestDrift(
        joint,
        tuple(rests),
        float(np.ptp(positions)) if positions else 0.0,
        tuple(follows),
        tuple(sides),
        _median(pos),
        _median(neg),
        verdict,
        reason,
    )
