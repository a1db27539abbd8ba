"""The input dynamics' search: a delay or a first-order lag between the logged input and the
plant, fitted with the input transformed exactly and chosen by prediction."""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from ..effects import INPUT_DYNAMICS_EFFECTS
from . import _fit
from ._fitter import _Fitter, _prediction_evidence
from ._library import Candidate
from ._problem import Problem, fit_equation_error, free_columns

# the input dynamics' candidate (a delay or a lag between the logged input and the plant, not
# memoryless: applied to the input itself; which of the two is decided after it is accepted)
DELAY = Candidate(INPUT_DYNAMICS_EFFECTS["delay"], "u")


def _search_input_dynamics(fx: _Fitter, effects: list[Candidate]) -> _fit.InputDynamics:
    """A delay or a first-order lag between the logged input and the plant. Both share one
    first-order signature (−d·u̇) in the linear test; each is fitted with the input transformed
    exactly, on a grid of half samples up to 3× the linear estimate, and judged by how well the
    refitted model predicts the validation windows (the equation error alone is biased on
    closed-loop logs, where a long lag refitted with the inertias mimics the loop's phase). The
    lag replaces the simpler delay only if it predicts significantly better."""
    effects = [c for c in effects if c != DELAY]
    free = free_columns(fx.layout, effects, fx.fixed_idx)
    _, linear = fit_equation_error(fx.fit_prob, fx.layout, free, fx.theta_fixed, fx.weights, True)
    dt = fx.segs[0].dt
    bound = min(fx.settings.search.max_delay, max(3.0 * linear, 4.0 * dt))
    grid = np.arange(0.5 * dt, bound + 1e-12, 0.5 * dt)

    def sums(dyn):
        fx.build(dyn, fx.fit_segs)
        prob = Problem(fx.fit_segs, fx.c_input)
        th, _ = fit_equation_error(prob, fx.layout, free, fx.theta_fixed, fx.weights, False)
        return fx.validation_sums(th, dyn)

    found = {}
    for kind in ("delay", "lag"):
        tried = [(sums(_fit.InputDynamics(kind, float(x))), float(x)) for x in grid]
        best = min(tried, key=lambda p: p[0].sum())
        # refine between the grid's neighbours of its best point
        res = minimize_scalar(
            lambda x, kind=kind: sums(_fit.InputDynamics(kind, x)).sum(),
            method="bounded",
            bounds=(max(0.0, best[1] - 0.5 * dt), best[1] + 0.5 * dt),
            options={"xatol": 1e-5},
        )
        refined = (sums(_fit.InputDynamics(kind, float(res.x))), float(res.x))
        found[kind] = refined if refined[0].sum() < best[0].sum() else best
    ev = _prediction_evidence(found["delay"][0], found["lag"][0])
    lag_wins = ev.passes(fx.settings.search.min_improvement, fx.settings.search.z_threshold)
    dyn = _fit.InputDynamics("lag", found["lag"][1]) if lag_wins else _fit.InputDynamics("delay", found["delay"][1])
    other = (
        (INPUT_DYNAMICS_EFFECTS["delay"], found["delay"][1])
        if lag_wins
        else (INPUT_DYNAMICS_EFFECTS["lag"], found["lag"][1])
    )
    fx.alternative = (
        f"{other[0]} {other[1]:.4g} s {'fits worse' if lag_wins else 'fits as well'} "
        f"(validation gain of the lag over the delay {ev.improvement:.1%}, t {ev.z:.1f})"
    )
    fx.notes.append(f"input dynamics: {dyn.kind} {dyn.seconds:.4g} s; {fx.alternative}")
    if dyn.seconds > 0.95 * fx.settings.search.max_delay:
        fx.notes.append(
            f"input {dyn.kind} estimate {dyn.seconds:.4g} s is at the search bound max_delay = "
            f"{fx.settings.search.max_delay} s: it stands in for something else"
        )
    return dyn
