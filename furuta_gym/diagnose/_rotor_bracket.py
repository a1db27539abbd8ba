"""Method step 11's evidence from the rests on the fixed cable's breakaway (issue 64): at least
the largest force a rest held, at most the least force that moved the joint off one, each read
through a one-count flicker (:mod:`._rests`); the same least force bounds the Coulomb level."""

from __future__ import annotations

import numpy as np

from . import _rests
from ._drift import flicker_tolerance
from ._rotor_context import Context, _joint_effects, _starts
from ._rotor_neutral import neutral_paths


def holding_forces(ctx: Context, theta, cable: tuple | None = None) -> list[np.ndarray]:
    """Per trajectory, the force (N·m or N) friction would balance to hold the joint still at each
    sample under θ and a cable with memory (:meth:`Context.cable`; None: none): the model's
    (:func:`._rests.holding_forces`) plus the cable's pull from its neutral (the play operator
    over the log)."""
    out = _rests.holding_forces(ctx.layout, ctx.j, ctx.trajs, theta)
    if cable and cable[0]:
        paths = neutral_paths(ctx.trajs, ctx.j, cable[1], _starts(cable))
        out = [
            f + cable[0] * (np.asarray(tr.q[:, ctx.j]) - paths[tr.name][1])
            for tr, f in zip(ctx.trajs, out, strict=True)
        ]
    return out


def held_still(ctx: Context, theta, cable=None, min_rest: float = 0.2, flicker: int = 1) -> float:
    """The largest force (N·m or N) a rest held, under θ (and ``cable``): the breakaway was at
    least that (:func:`._rests.held_force`)."""
    tolerance = flicker_tolerance(flicker, ctx.fx.resolution.get(ctx.joint, 0.0))
    return _rests.held_force(ctx.trajs, holding_forces(ctx, theta, cable), ctx.j, tolerance, min_rest)


def broke_away(
    ctx: Context, theta, cable=None, min_rest: float = 0.2, flicker: int = 1, first_rest: float = 0.01, span=0.05
) -> float | None:
    """The least force (N·m or N) that moved the joint off a rest, under θ (and ``cable``): the
    breakaway was at most that (:func:`._rests.moving_force`). None: no rest was left."""
    tolerance = flicker_tolerance(flicker, ctx.fx.resolution.get(ctx.joint, 0.0))
    forces = holding_forces(ctx, theta, cable)
    return _rests.moving_force(ctx.trajs, forces, ctx.j, tolerance, min_rest, first_rest, span)


def centred(ctx: Context, theta, cable=None, min_rest: float = 0.2, flicker: int = 1) -> np.ndarray:
    """``theta`` with the fixed cable's rest (its constant force) where the forces the log's rests
    held are centred on it: a neutral whose friction holds the joint keeps every rest within
    ±F_s/k of it, so the least breakaway the rests allow is half the spread of those forces,
    whatever the rest (a log without input, with few moves, leaves the equation error's rest far
    off, and the largest force held about that rest put the bracket above the breakaway).
    Unchanged without a rest's column or without a rest."""
    c = _joint_effects(ctx)
    if "rest" not in c:
        return np.asarray(theta)
    tolerance = flicker_tolerance(flicker, ctx.fx.resolution.get(ctx.joint, 0.0))
    i, out = ctx.layout.index(c["rest"].key), np.array(theta, dtype=float)

    def held(value: float) -> np.ndarray:
        out[i] = value
        return _rests.held_forces(ctx.trajs, holding_forces(ctx, out, cable), ctx.j, tolerance, min_rest)

    # the rests' forces are affine in the constant force: two reads give the shift that centres them
    at_zero, unit = held(0.0), ctx.layout.typical_scale()[i]
    if at_zero.size == 0:
        return np.asarray(theta)
    slope = float(np.median(held(unit) - at_zero)) / unit
    out[i] = -0.5 * (at_zero.max() + at_zero.min()) / slope
    return out


def _breakaway_bound(ctx: Context, theta, cable=None, *, centre: bool) -> dict:
    """{the stiction's key: (its least, its largest ΔF)}: the joint's breakaway at least the
    largest force a rest held (:func:`held_still`) and at most the least force that moved it off
    a rest (:func:`broke_away`), both under the start's cable, less its Coulomb level; the windows
    alone say little between the two (a stiction that held every stop they show fits them as well
    as the right one). With a rest left, the Coulomb level's key too: (0, that least force).
    ``centre``: read about the rest that centres the rests' forces (:func:`centred`), else about
    θ's own."""
    c, theta = _joint_effects(ctx), centred(ctx, theta, cable) if centre else theta
    most, coulomb = broke_away(ctx, theta, cable), theta[ctx.layout.index(c["sliding"].key)]
    least = held_still(ctx, theta, cable) - coulomb
    if most is None:
        return {c["breakaway"].key: (max(least, 0.0), np.inf)}
    # the same least moving force bounds the Coulomb level: without it, the Coulomb level and the
    # rest's constant force can grow together until every stop is held (the fit's cost is flat there)
    return {
        c["breakaway"].key: (min(max(least, 0.0), most - coulomb), most - coulomb),
        c["sliding"].key: (0.0, most),
    }


def _settled(ctx: Context, theta, theta0, bounds: dict):
    """``theta`` with its breakaway at most the geometric middle of the rests' bracket (the value
    least far, in ratio, from any the rests allow): the windows push it up, towards holding every
    stop (a predicted pendulum started from a velocity read through quantisation shakes a rotor
    that the real one kept still, and a larger breakaway keeps it still), so a fit above the
    middle says no more than that the rotor was held."""
    c = _joint_effects(ctx)
    s, i = ctx.layout.index(c["breakaway"].key), ctx.layout.index(c["sliding"].key)
    least, most = bounds.get(c["breakaway"].key, (0.0, np.inf))
    if not (np.isfinite(most) and least > 0):
        return theta
    out = np.array(theta, dtype=float)
    out[s] = min(out[s], np.sqrt((least + theta0[i]) * (most + theta0[i])) - theta0[i])
    return out
