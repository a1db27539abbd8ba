"""Method step 11's two fits (issue 64): the large breakaway and the moving rest, each by output
error on the output-error windows from the best of a grid of starts, judged against the model as
diagnosed (:mod:`._rotor_verdict`)."""

from __future__ import annotations

import itertools

import numpy as np
from scipy.optimize import least_squares

from ..effects import EFFECT_KINDS
from ._drift import rest_drift
from ._library import Candidate, is_physical, non_physical
from ._problem import free_columns
from ._rotor_bracket import _breakaway_bound, _settled
from ._rotor_context import (
    Context,
    _cleared,
    _joint_effects,
    _memory_kind,
    _typical_spring,
    _with_first,
    ee_with_cable,
)
from ._rotor_verdict import LAWS, LawFit, _evidence

PLAY_GRID = (0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4, 0.6, 0.8, 1.2, 1.6)  # the play's starts (rad or m)
_FIRST_GRID = (-1.0, 0.0, 1.0)  # starts of ρ of the log's first neutral
_BREAKAWAY_GRID = (1.0, 4.0, 9.0)  # starts of ΔF in Coulomb levels (a breakaway up to 10×)
#: the windows the large breakaway is first fitted on where no input drives the rotor: those where
#: it moves. A window in which it rests says only that friction held it against the cable, which
#: the rests' bracket reads; fitted, the rests' windows (most of a release log) pushed the
#: friction up, since a rotor predicted from a velocity read through quantisation drifts where
#: the real one stayed
MOVING = "moving"


def fit_law(
    ctx: Context,
    theta0,
    effects: list[Candidate],
    cable0: tuple | None,
    max_nfev: int,
    bounds: dict | None = None,
    which: str = "fit",
):
    """Output-error fit on the windows ``which`` of θ's free entries and, given ``cable0``
    (:meth:`Context.cable`), the cable's stiffness, second parameter and each trajectory's first
    neutral (ρ ∈ [−1, 1] of its play: no history before a log); ``bounds``: {effect key: (least, largest)}."""
    layout = ctx.layout
    # the declared model's parameters stay at the start's: the windows where the joint moves, all
    # that tells the laws apart, are few (a release moves the rotor for a second or two)
    free = free_columns(layout, effects, set(range(len(layout.base))))
    scale = np.where(free, np.maximum(np.abs(theta0), layout.typical_scale() * 1e-2), 1.0)
    nf = int(free.sum())
    k_scale = max(cable0[0], 1e-6) if cable0 else 1.0

    def unpack(z):
        th = theta0.copy()
        th[free] = z[:nf] * scale[free]
        return th, (_with_first(ctx, z[nf] * k_scale, z[nf + 1], z[nf + 2]) if cable0 else (0.0, 0.0))

    def residuals(zs) -> np.ndarray:
        ths, cables = zip(*map(unpack, zs), strict=True)
        r = (ctx.predictions(ths, cables, which) - ctx.windows(which).q[None]).reshape(len(zs), -1)
        return np.where(np.isfinite(r), r, 1e3)

    z0 = theta0[free] / scale[free]
    lower, upper = _box(layout, free, scale, bounds or {})
    if cable0:
        lo, hi = EFFECT_KINDS[_memory_kind(ctx).name].second_bounds
        z0 = np.concatenate([z0, [1.0, cable0[1], cable0[2]]])
        lower = np.concatenate([lower, [0.0, lo, -1.0]])
        upper = np.concatenate([upper, [np.inf, hi, 1.0]])
    z0 = np.clip(z0, lower + 1e-9, upper - 1e-9)

    def jac(z):
        h = 1e-6 * np.maximum(1.0, np.abs(z))
        r = residuals([z] + [z + step for step in np.diag(h)])
        return (r[1:] - r[0]).T / h

    sol = least_squares(
        lambda z: residuals([z])[0],
        z0,
        jac=jac,  # pyright: ignore[reportArgumentType]
        method="trf",
        bounds=(lower, upper),
        max_nfev=max_nfev,
        x_scale="jac",
    )
    return unpack(sol.x)


def _box(layout, free: np.ndarray, scale: np.ndarray, bounds: dict) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of the scaled free entries: a base parameter and an effect that only one
    sign makes physical are not fitted past zero; ``bounds``: {effect key: (least, largest)}."""
    positive = [
        i < len(layout.base) or layout.candidates[i - len(layout.base)].kind.physically_positive
        for i in range(layout.size)
    ]
    lower = np.where(positive, 0.0, -np.inf)[free] / scale[free]
    upper = np.full(int(free.sum()), np.inf)
    for key, (least, value) in bounds.items():
        i = int(np.flatnonzero(np.flatnonzero(free) == layout.index(key))[0])
        upper[i] = max(value, 1e-12) / scale[layout.index(key)]
        lower[i] = min(least, 0.99 * value) / scale[layout.index(key)]
    return lower, upper


def _fit_breakaway(ctx: Context, theta0, effects: list[Candidate], bounds: dict, max_nfev: int) -> np.ndarray:
    """The large breakaway's law, within the rests' bracket, its breakaway at most the bracket's
    middle (:func:`_settled`). Without input, in two stages: every coefficient on the windows
    where the rotor moves (:data:`MOVING`), then its ΔF alone on every output-error window, within
    the bracket read about the rest that stage fitted (the rests' windows say how far friction
    held the rotor, and fitted with the rest they pushed the sliding level and the rest's
    constant force up together; the first stage's bracket, read about the rest that centres the
    rests' forces, lets a breakaway through that the fitted rest's rests would not hold). Under
    input in one, on every window: there the rotor rests against the input, which the windows read."""
    stiction = _joint_effects(ctx)["breakaway"]
    if ctx.driven:
        return _settled(ctx, fit_law(ctx, theta0, effects, None, max_nfev, bounds)[0], theta0, bounds)
    first = fit_law(ctx, theta0, effects, None, max_nfev, bounds, MOVING)[0]
    held = _breakaway_bound(ctx, first, centre=False)
    theta = fit_law(ctx, first, [stiction], None, max_nfev, {stiction.key: held[stiction.key]})[0]
    return _settled(ctx, theta, first, held)


def _start_breakaway(ctx: Context, theta, held: float):
    """The fixed cable's start: the equation-error spring and rest, the Coulomb level at least its
    typical size, on that fit's base or the nominal one, ΔF what the rests held above it, or 1,
    4 or 9 Coulomb levels; the one that predicts the output-error windows best (a fit from a
    small ΔF can stay in a minimum without it)."""
    c = _joint_effects(ctx)
    effects = [c[k] for k in ("cable", "rest", "sliding") if k in c]
    th = _physical_base(ctx, ctx.fx.fit_ee(ctx.others + effects)[0], theta)
    scale = ctx.layout.typical_scale()
    for key in ("cable", "sliding"):
        i = ctx.layout.index(c[key].key)
        th[i] = max(th[i], 2.0 * scale[i])
    coulomb, s = th[ctx.layout.index(c["sliding"].key)], ctx.layout.index(c["breakaway"].key)
    # without input the equation error's rest can be far off (few moves): the bracket is read about
    # the rest that centres the rests' forces; under input the driven motion sets that rest
    bounds = _breakaway_bound(ctx, th, centre=not ctx.driven)
    least, most = bounds[c["breakaway"].key]
    deltas = [max(coulomb, held - coulomb)] + [m * coulomb for m in _BREAKAWAY_GRID]
    deltas += [np.sqrt(max(least, coulomb) * most)] if np.isfinite(most) and most > 0 else []
    starts = []
    for delta, rest in itertools.product(deltas, _rest_starts(ctx, th)):
        th[s] = float(np.clip(delta, least, most))
        if "rest" in c:
            th[ctx.layout.index(c["rest"].key)] = rest
        starts += _with_nominal_base(ctx, th)
    best = starts[_best_start(ctx, starts, [(0.0, 0.0)] * len(starts), "fit" if ctx.driven else MOVING)]
    return best, effects + [c["breakaway"]], bounds


def _rest_starts(ctx: Context, theta) -> list[float]:
    """The fixed cable's rest (its constant force) to start from: the equation-error fit's, and
    the middle of the span of the log's rests (a neutral whose friction holds the rotor keeps
    every rest within ±F_s/k of it; the equation error, which leaves rests out, can put it far
    off)."""
    c = _joint_effects(ctx)
    if "rest" not in c:
        return [0.0]
    k, own = theta[ctx.layout.index(c["cable"].key)], theta[ctx.layout.index(c["rest"].key)]
    count = ctx.fx.resolution.get(ctx.joint, 2 * np.pi / 2048)
    rests = [r.position for r in rest_drift(ctx.trajs, ctx.layout.system, ctx.joint, flicker=1, count=count).rests]
    return [own] + ([k * 0.5 * (min(rests) + max(rests))] if rests else [])


def _physical_base(ctx: Context, theta_ee, theta):
    """``theta_ee`` (an equation-error fit with the cable's spring) if physical, else its effects on
    ``theta``'s base: a diagnosis without the cable may leave the rotor's inertia far off, and the
    output-error fits start where the cable is already in."""
    if is_physical(ctx.layout, theta_ee):
        return np.array(theta_ee, dtype=float)
    return np.where(np.arange(theta_ee.size) < len(ctx.layout.base), theta, theta_ee)


def _start_moving(ctx: Context, theta, stiffness: float):
    """The moving rest's start, the one of a grid that predicts the output-error windows best
    (the play and the log's first neutral make the fit's landscape rugged): each play of a grid,
    the log's first neutral at either end of its play or in its middle, and either the equation-
    error fit with the cable's column (its stiffness; ``theta``'s base and ``stiffness`` where
    that fit is not physical) or the nominal base with stiffnesses of 1, 2 and 4× the typical
    (a log without input leaves the rotor's equation without a scale: its equation error may put
    both the inertia and the stiffness far off). Its dry friction is Coulomb friction, at least its
    typical size: beside a rest that moves, a breakaway above it is not identified (fitted free,
    ΔF took any value up to holding every stop where it happened, or turned negative)."""
    c = _joint_effects(ctx)
    i = ctx.layout.index(c["sliding"].key)
    scale, typical = ctx.layout.typical_scale(), _typical_spring(ctx)
    starts, cables = [], []
    for w in PLAY_GRID:
        th, k = ee_with_cable(ctx, [c["sliding"]], w)
        th = _physical_base(ctx, _cleared(ctx, th), theta)
        th[i] = max(th[i] if is_physical(ctx.layout, th) else 0.0, 2.0 * scale[i])
        nominal = _with_nominal_base(ctx, th)[1]
        for start, k_start in [(th, k if k > 0 else stiffness)] + [(nominal, m * typical) for m in (1.0, 2.0, 4.0)]:
            for rho in _FIRST_GRID:
                starts.append(start)
                cables.append(_with_first(ctx, k_start, w, rho))
    best = _best_start(ctx, starts, cables)
    return starts[best], [c["sliding"]], cables[best]


def _with_nominal_base(ctx: Context, theta) -> list[np.ndarray]:
    """``theta`` and ``theta`` on the declared model's nominal base (as the diagnosis's own
    output-error fits may start: an equation-error fit of a log whose law it lacks, or of one
    resting most of the time, can leave the inertias far off)."""
    nominal = np.array(theta, dtype=float)
    nb = len(ctx.layout.base)
    free = np.array([i not in ctx.fx.fixed_idx for i in range(nb)])
    nominal[:nb] = np.where(free, ctx.layout.nominal()[:nb], theta[:nb])
    return [np.array(theta, dtype=float), nominal]


def _best_start(ctx: Context, starts, cables, which: str = "fit") -> int:
    """Index of the start that predicts the output-error windows (``which``) best."""
    pred = ctx.predictions(starts, cables, which)
    costs = np.sum((pred - ctx.windows(which).q[None]) ** 2, axis=(1, 2, 3))
    return int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))


def _changed(ctx: Context, before: np.ndarray, after: np.ndarray) -> int:
    """How many windows' predictions of the joint differ by more than one encoder count (RMS)."""
    rms = np.sqrt(np.mean((after[..., ctx.j] - before[..., ctx.j]) ** 2, axis=1))
    return int(np.sum(rms > ctx.fx.resolution.get(ctx.joint, 0.0)))


def model_as_law(ctx: Context, theta, owned: list[Candidate], found, base=None) -> LawFit:
    """The model as diagnosed as the large breakaway's fit (it holds the joint's spring and
    stiction, ``owned``), with its stiction's evidence ``found``; ``base``: its predictions of the
    validation windows, if made."""
    base = ctx.predictions([theta], [(0.0, 0.0)], "val")[0] if base is None else base
    th = np.array(theta, dtype=float)
    return LawFit(LAWS[1], th, (0.0, 0.0), owned, base, found, physical=True, incumbent=True)


def fit_laws(ctx: Context, theta, spring_k: float, held: float, max_nfev: int, diagnosed=None) -> dict[str, LawFit]:
    """Both laws fitted on the joint (module docstring) and judged against ``theta``.
    ``diagnosed``: (the joint's effects, the stiction's evidence) where the model as diagnosed is
    already the large breakaway's law (the earlier steps found the joint's spring and stiction):
    that law is then the model itself, with the stiction's evidence, and the moving rest's
    evidence against it is the head-to-head of the two."""
    base = ctx.predictions([theta], [(0.0, 0.0)], "val")[0]
    out = {}
    th0, effects, bounds = _start_breakaway(ctx, theta, held)
    if diagnosed is None:
        fitted = _fit_breakaway(ctx, th0, effects, bounds, max_nfev)
        fits = {LAWS[1]: (effects, (fitted, (0.0, 0.0)))}
    else:
        owned, found = diagnosed
        fits, out[LAWS[1]] = {}, model_as_law(ctx, theta, owned, found, base)
    th0, effects, cable0 = _start_moving(ctx, th0, max(spring_k, 2.0 * _typical_spring(ctx)))
    fits[LAWS[0]] = (effects, fit_law(ctx, th0, effects, cable0, max_nfev))
    for law, (effects, (th, cable)) in fits.items():
        pred = ctx.predictions([th], [cable], "val")[0]
        physical = bool(is_physical(ctx.layout, th) and not non_physical(ctx.layout, th, effects))
        physical = physical and bool(cable[0] > 0 if law == LAWS[0] else True)
        ev = _evidence(base, pred, ctx.win_val.q)
        out[law] = LawFit(
            law, th, tuple(float(x) for x in cable), effects, pred, ev, physical, changed=_changed(ctx, base, pred)
        )
    return {law: out[law] for law in (LAWS[1], LAWS[0])}
