"""Fit → verdict: every candidate's coefficient and final evidence (added, inconsistent, tested),
effects under the sensor's resolution marked, and the reported errors and 95 % intervals."""

from __future__ import annotations

import numpy as np

from ..effects import INPUT_DYNAMICS_EFFECTS, spring_rests
from . import _intervals
from ._cable_search import _with_cable
from ._fitter import _Fitter
from ._input_search import DELAY
from ._intervals import FitOrigin, Interval
from ._library import Candidate
from ._problem import fit_equation_error, free_columns
from ._result import EffectEvidence, ErrorSummary
from ._settings import DiagnosisSettings


def _reported(fx: _Fitter, theta, accepted, dyn, ordered, after: ErrorSummary, cable, test_after):
    """(held-out errors after, intervals, their method): as fitted, or with a kept cable with
    memory (its evidence put first), whose errors are predicted with its moving neutral and whose
    fit has no intervals (their criterion has no such cable in it)."""
    if cable is None:
        return (after, *_reported_intervals(fx, theta, accepted, dyn, ordered))
    ordered.insert(0, cable[2])
    fx.notes.append(f"{cable[2].name}:{cable[2].joint}: fitted with a neutral that moves; no intervals reported")
    if test_after is not None:
        fx.notes.append("the test logs' errors after are of the model without the cable's moving neutral")
    after = _with_cable(fx, after, cable, theta, fx.held_segs, fx.held_prob)
    none: dict[str, Interval | None] = {b: None for b in fx.layout.base}
    return after, none, None


def _finish_evidence(fx, library, accepted, theta, dyn, evidence):
    """Coefficients (the refit's for accepted effects; a fit with the accepted ones plus the
    candidate for the rest) and, for untested-or-rejected candidates, evidence given the final model."""
    comparer = fx.comparer()
    for c in library:
        ev = evidence.get(c.key)
        if ev is not None and ev.status in ("absorbed", "not identifiable", "equivalent"):
            continue
        if c in accepted:
            ev.coefficient = dyn.seconds if c == DELAY else float(theta[fx.layout.index(c.key)])
            if c == DELAY:
                ev.name = INPUT_DYNAMICS_EFFECTS[dyn.kind]
                ev.note = "; ".join(x for x in (ev.note, fx.alternative) if x)
            continue
        given = [a for a in accepted if a != c]
        score = comparer.compare(given, [c])
        if ev is None:
            ev = evidence[c.key] = EffectEvidence(
                c.name, c.joint, None, c.unit(fx.spec), False, score.improvement, score.z, "tested"
            )
        elif ev.status == "tested":
            ev.improvement, ev.z_score = score.improvement, score.z
        if ev.status == "tested" and score.improvement >= fx.settings.search.inconsistent_gain:
            ev.status, ev.note = "inconsistent", _inconsistency(c, score, fx.settings)
            fx.notes.append(f"{c.key}: {ev.note}")
        free = free_columns(fx.layout, given + [c], fx.fixed_idx)
        with_delay = c == DELAY or DELAY in given
        th, d = fit_equation_error(fx.fit_prob, fx.layout, free, fx.theta_fixed, fx.weights, with_delay)
        ev.coefficient = d if c == DELAY else float(th[fx.layout.index(c.key)])
    chosen = [evidence[c.key] for c in accepted]
    rests = spring_rests(chosen)
    for ev in (e for e in chosen if e.kind.is_constant_force and e.joint in rests):
        joint, rest = ev.joint, rests[ev.joint]
        ev.note = "; ".join(x for x in (ev.note, f"with spring:{joint}: its rest position is {rest:.3g} (tau0/k)") if x)
    rest = sorted(
        (e for e in evidence.values() if e.status in ("inconsistent", "tested", "not confirmed")),
        key=lambda e: -(e.improvement if e.improvement is not None else -np.inf),
    )
    return chosen + rest + [e for e in evidence.values() if e.status in ("equivalent", "absorbed", "not identifiable")]


def _inconsistency(c: Candidate, score, settings: DiagnosisSettings) -> str:
    """Why a candidate that removes much of the held-out residual was not added, and where it
    helps and where it hurts, per recording."""
    per = score.by_recording()
    helps = ", ".join(f"{k} ({v:+.0%})" for k, v in sorted(per.items(), key=lambda kv: -kv[1]) if v > 0)
    hurts = ", ".join(f"{k} ({v:+.0%})" for k, v in sorted(per.items(), key=lambda kv: kv[1]) if v < 0)
    cause = (
        "its gain sits in a few blocks: the effect acts strongly in part of the data only, or it "
        "changes between recordings (a cable's neutral or stiffness, friction that depends on "
        "position), or another effect it needs is missing"
    )
    return (
        f"inconsistent: removes {score.improvement:.0%} of the held-out residual, but its t "
        f"{score.z:.1f} < {settings.search.z_threshold:g}; helps on {helps or 'no recording'}; hurts on "
        f"{hurts or 'no recording'}. Likely: {cause}"
    )


def _mark_unresolved(effects: list[EffectEvidence], resolution: dict[str, float], dt: float, notes) -> None:
    """An added effect smaller than what the sensor resolves — a centre-of-mass offset under one
    encoder count, an input delay or lag under one sample — is kept but reported as not resolved:
    a sub-count offset is the encoder's zero, a sub-sample lag the sampling's own phase."""
    for e in effects:
        if not e.significant or e.coefficient is None:
            continue
        why = None
        if e.kind.resolution == "position" and e.joint in resolution and abs(e.coefficient) < resolution[e.joint]:
            why = f"{abs(e.coefficient):.2g} rad is under one encoder count ({resolution[e.joint]:.2g} rad)"
        elif e.kind.resolution == "sample" and abs(e.coefficient) < dt:
            why = f"{abs(e.coefficient):.2g} s is under one sample period ({dt:.2g} s)"
        if why:
            e.resolved = False
            e.note = "; ".join(x for x in (e.note, f"not resolved at this sensor resolution: {why}") if x)
            notes.append(f"{e.name}:{e.joint}: not resolved at this sensor resolution ({why})")


def _reported_intervals(fx: _Fitter, theta, accepted, dyn, ordered):
    """95 % intervals of the reported parameters and added effects' coefficients, from the fit
    whose estimate is reported — not always the last one run: ``_Fitter.refine`` keeps the
    equation-error estimate (or the nominal base values) when the output-error refinement does
    not predict the validation windows better, and a stiction may be set from its rests. The
    intervals of an estimate come from the residual it minimises (its Jacobian there); values
    that no fit produced get none. Returns ({base parameter: Interval or None}, method) and sets
    each added effect's ``interval``."""
    origin = fx.origin(theta)
    if origin is None:  # not a recorded estimate: the output-error criterion at the reported θ
        sticky = any(c.kind.breakaway_above for c in accepted)
        start = (
            max(1, fx.settings.output_error.start_iterations) if sticky else fx.settings.output_error.start_iterations
        )
        free = free_columns(fx.layout, accepted, fx.fixed_idx)
        origin = FitOrigin("output_error", theta, free, dyn, start, recorded=False)
    out, notes, method = _intervals.fit_intervals(fx, theta, origin)
    if fx.dynamics != dyn:
        fx.build(dyn)
    for e in ordered:
        if e.significant:
            e.interval = out.get(f"{e.name}:{e.joint}")
    fx.notes.extend(notes)
    return {b: out.get(b) for b in fx.layout.base}, method
