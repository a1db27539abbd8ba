"""Stiction's own search: a joint's stiction acts only where it nearly stops, which the equation
error leaves out, so it is fitted by prediction (output error) and bounded below by the forces
the joint's rests held (:mod:`._rests`), given the joint's Coulomb friction."""

from __future__ import annotations

import numpy as np

from . import _rests, _trace as _trace_mod, _windows
from ._fitter import _Fitter, _prediction_evidence, _square_sums
from ._intervals import FitOrigin
from ._library import Candidate, is_physical, non_physical
from ._problem import free_columns
from ._result import EffectEvidence


def _stiction_start(fx: _Fitter, theta, c: Candidate, held: float) -> np.ndarray:
    """The output-error start of a stiction candidate: the model so far with ΔF at the joint's
    Coulomb level, or up to the force its rests held, if larger (the EE estimate is meaningless:
    it rests on velocities near zero, which the estimates do not resolve, in intervals the equation
    error mostly leaves out)."""
    start = theta.copy()
    coulomb = theta[fx.layout.index(f"{c.kind.breakaway_above}:{c.joint}")]
    start[fx.layout.index(c.key)] = max(coulomb, held - coulomb)
    return start


def _rest_bound(fx: _Fitter, theta, dyn, joint: str) -> _rests.RestBound:
    """The force the fit segments' rests held ``joint`` against (0 without encoder counts)."""
    count = fx.resolution.get(joint)
    if count is None:
        return _rests.RestBound(joint, 0.0, 0, 0.0)
    return _rests.rest_bound(fx.layout, theta, fx.fit_segs, dyn, joint, count, fx.settings.rests.rest_window)


def _stiction_candidates(library, accepted, evidence) -> list:
    """The library's stiction terms not yet judged whose joint's Coulomb friction is accepted."""
    accepted_keys = {a.key for a in accepted}
    return [
        c
        for c in library
        if c.kind.breakaway_above and c.key not in evidence and f"{c.kind.breakaway_above}:{c.joint}" in accepted_keys
    ]


def _stiction_by_prediction(fx: _Fitter, library, accepted, theta, dyn, evidence):
    """Stiction acts only where a joint nearly stops, which the equation error cannot see, but a
    joint that sticks shows in open-loop predictions and in the forces its rests held (``_rests``).
    With a joint's Coulomb friction accepted, its stiction is fitted by output error on the
    output-error windows and judged on the fit-set validation windows by the trace's rule (gain ≥
    ``min_improvement``, t ≥ ``z_threshold``, each window weighted by how much the stiction changes
    its prediction), ΔF > 0, against the model without it refitted the same way; its breakaway is
    never left below what the rests held. Failing that, it is added from the rests when they held
    the joint against ``min_breakaway_ratio`` × its Coulomb level and the model with it does not
    predict significantly worse. Returns (accepted, θ)."""
    s = fx.settings
    todo = _stiction_candidates(library, accepted, evidence)
    if not todo:
        return accepted, theta
    # whether a joint stops within a window depends on its start velocity, which a smoothed
    # estimate near a stop does not resolve: the windows' start velocities are estimated too
    start = max(1, s.output_error.start_iterations)
    win = fx.fit_windows(dyn, fx.oe_idx)

    def refit(th0, effects):
        free = free_columns(fx.layout, effects, fx.fixed_idx)
        th, ok = _windows.oe_fit(fx.layout, th0, free, win, fx.substeps, s.output_error.oe_max_nfev, start)
        if ok:
            fx.record(th, FitOrigin("output_error", th, free, dyn, start))
        return th, fx.validation_predictions(th, dyn, start)

    # the baseline is refitted as the trial is, so that the gain is the stiction's own
    base, pred = refit(theta, accepted)
    measured = fx.fit_windows(dyn, fx.val_idx).q
    for c in todo:
        bound = _rest_bound(fx, base, dyn, c.joint)
        th, trial_pred = refit(_stiction_start(fx, base, c, bound.held), accepted + [c])
        ev = _stiction_evidence(pred, trial_pred, measured)
        coef = float(th[fx.layout.index(c.key)])
        how = "found by prediction, given the joint's Coulomb friction: gain and t on the fit-set validation windows"
        if coef > 0 and is_physical(fx.layout, th) and ev.passes(s.search.min_improvement, s.search.z_threshold):
            th = _breakaway_at_least(fx, th, c, bound)
        else:
            fx.notes.append(
                f"{c.key}: tested by prediction given coulomb_friction:{c.joint}: ΔF {coef:.3g}, "
                f"validation gain {ev.improvement:.1%}, t {ev.z:.1f}; not added"
            )
            found = _stiction_from_rests(fx, base, c, bound, lambda th0, acc=accepted: refit(th0, acc)[0], dyn)
            if found is None:
                continue
            fitted, (th, how) = (th, trial_pred), found
            trial_pred = fx.validation_predictions(th, dyn, start)
            ev = _stiction_evidence(pred, trial_pred, measured)
            if ev.z <= -s.search.veto_t:
                fx.notes.append(
                    f"{c.key}: {how}, but predicts worse with it (gain {ev.improvement:.1%}, t {ev.z:.1f}): not added"
                )
                continue
            th, how, trial_pred = _sized(fx, (th, how, trial_pred), fitted, c, bound, (dyn, start, measured))
            ev = _stiction_evidence(pred, trial_pred, measured)
        accepted, theta, base, pred = accepted + [c], th, th, trial_pred
        evidence[c.key] = EffectEvidence(
            c.name, c.joint, None, c.unit(fx.spec), True, ev.improvement, ev.z, "selected", how
        )
    return accepted, theta


def _vetoed_with_stiction(fx: _Fitter, library, vetoed, accepted, theta, dyn, evidence):
    """A step vetoed for predicting worse is tried once more with its joint's stiction, fitted free
    by output error, where that joint's Coulomb friction is in the model: the equation error leaves
    out where a joint stops, so it never sees the stiction, and a cable spring that the stiction
    holds off its neutral predicts worse without it (the modelled rotor slides back where the real
    one sticks). Kept, both, if the model with them predicts the fit-set validation windows better
    in total and not significantly worse by t (the veto's rule), with ΔF > 0 and the step's
    coefficients physical. Returns (accepted, θ)."""
    if not vetoed:  # nearly every diagnosis: no windows to build
        return accepted, theta
    start = max(1, fx.settings.output_error.start_iterations)
    win, measured = fx.fit_windows(dyn, fx.oe_idx), fx.fit_windows(dyn, fx.val_idx).q
    for step in vetoed:
        c = _stiction_partner(library, accepted, step)
        if c is None:
            continue
        trial = accepted + list(step.members) + [c]
        free, bound = free_columns(fx.layout, trial, fx.fixed_idx), _rest_bound(fx, theta, dyn, c.joint)
        th0 = _stiction_start(fx, fx.fit_ee(accepted + list(step.members))[0], c, bound.held)
        th, ok = _windows.oe_fit(fx.layout, th0, free, win, fx.substeps, fx.settings.output_error.oe_max_nfev, start)
        before = _square_sums(fx.validation_predictions(theta, dyn, start), measured)
        ev = _prediction_evidence(before, _square_sums(fx.validation_predictions(th, dyn, start), measured))
        coef, members = float(th[fx.layout.index(c.key)]), ", ".join(m.key for m in step.members)
        if not (ok and coef > 0 and is_physical(fx.layout, th) and not non_physical(fx.layout, th, step.members)):
            fx.notes.append(f"{members}: tried again with {c.key} (ΔF {coef:.3g}): not physical; dropped")
            continue
        if not (ev.improvement > 0 and ev.z > -fx.settings.search.veto_t):
            fx.notes.append(
                f"{members}: tried again with {c.key} free: validation gain {ev.improvement:.1%}, t {ev.z:.1f}; dropped"
            )
            continue
        fx.record(th, FitOrigin("output_error", th, free, dyn, start))
        accepted, theta = trial, _breakaway_at_least(fx, th, c, bound)
        _selected_with_stiction(fx, step, c, ev, evidence)
    return accepted, theta


def _stiction_partner(library, accepted, step) -> Candidate | None:
    """The stiction of a joint of ``step`` whose Coulomb friction is accepted and stiction is not."""
    keys, joints = {a.key for a in accepted}, {m.joint for m in step.members}
    for c in library:
        if c.kind.breakaway_above and c.joint in joints and c.key not in keys:
            if f"{c.kind.breakaway_above}:{c.joint}" in keys:
                return c
    return None


def _selected_with_stiction(fx: _Fitter, step, c: Candidate, ev, evidence) -> None:
    """Record a vetoed step's members (their search evidence) and the stiction ``c`` they came
    back with (its prediction evidence ``ev``) as selected."""
    members = ", ".join(m.key for m in step.members)
    how = f"with {c.key}, fitted with it by prediction: validation gain {ev.improvement:.1%}, t {ev.z:.1f}"
    for m in step.members:
        e = step.evidence[m.key]
        evidence[m.key] = EffectEvidence(
            m.name, m.joint, None, m.unit(fx.spec), True, e.improvement, e.z, "selected", how
        )
    why = f"found with {members}, which predicts worse without it: fitted with it by prediction"
    evidence[c.key] = EffectEvidence(
        c.name, c.joint, None, c.unit(fx.spec), True, ev.improvement, ev.z, "selected", why
    )
    fx.notes.append(f"{members}: {how}; added with it")


def _sized(fx: _Fitter, from_rests, fitted, c: Candidate, bound: _rests.RestBound, where):
    """A stiction added on its rests' evidence (``from_rests``: θ, how, predictions) takes its size
    from the output-error fit with ΔF free (``fitted``: θ, predictions; its breakaway kept at least
    what the rests held) when that fit predicts the fit-set validation windows better: rests bound
    the breakaway from below only, and with it set too low the Coulomb level absorbs the rest.
    Returns (θ, how, predictions)."""
    dyn, start, measured = where
    (th_rests, how, pred_rests), (th_fit, pred_fit) = from_rests, fitted
    i = fx.layout.index(c.key)
    if not (th_fit[i] > 0 and is_physical(fx.layout, th_fit)):
        return th_rests, how, pred_rests
    raised = _raised_breakaway(fx, th_fit, c, bound)
    if raised is not th_fit:
        pred_fit = fx.validation_predictions(raised, dyn, start)
    better = _prediction_evidence(_square_sums(pred_rests, measured), _square_sums(pred_fit, measured))
    if not better.improvement > 0:
        return th_rests, how, pred_rests
    th = _breakaway_at_least(fx, th_fit, c, bound)
    return (
        th,
        (
            f"{how}; ΔF {th[i]:.3g} from the output-error fit with it free, which predicts the validation "
            f"windows {better.improvement:.0%} better than ΔF {th_rests[i]:.3g} set from the rests"
        ),
        pred_fit,
    )


def _stiction_evidence(pred, trial_pred, measured) -> _trace_mod.Evidence:
    """A stiction's gain on the validation windows; a window counts by how much the stiction
    changes its prediction (the output-error form of its regressor): a joint that never nears rest
    there says nothing about it."""
    change = np.sum((trial_pred - pred) ** 2, axis=(1, 2))
    return _prediction_evidence(
        _square_sums(pred, measured), _square_sums(trial_pred, measured), np.where(np.isfinite(change), change, 0.0)
    )


def _raised_breakaway(fx: _Fitter, theta, c: Candidate, bound: _rests.RestBound) -> np.ndarray:
    """θ with the joint's breakaway (Coulomb + ΔF) raised to what its rests held, if it was below
    (``theta`` itself if not)."""
    i, coulomb = fx.layout.index(c.key), theta[fx.layout.index(f"{c.kind.breakaway_above}:{c.joint}")]
    if coulomb + theta[i] >= bound.held:
        return theta
    out = theta.copy()
    out[i] = bound.held - coulomb
    return out


def _breakaway_at_least(fx: _Fitter, theta, c: Candidate, bound: _rests.RestBound) -> np.ndarray:
    """:func:`_raised_breakaway`, with the raise recorded (notes; no interval for ΔF)."""
    out = _raised_breakaway(fx, theta, c, bound)
    if out is theta:
        return theta
    i = fx.layout.index(c.key)
    _held_from(fx, out, theta, i, "raised to the force the rests held (a lower bound, not a fit)")
    fx.notes.append(
        f"{c.key}: ΔF raised {theta[i]:.3g} -> {out[i]:.3g} to the force the rests held "
        f"({bound.held:.3g} over {bound.n_windows} windows of {fx.settings.rests.rest_window:g} s)"
    )
    return out


def _held_from(fx: _Fitter, theta, fitted, i: int, why: str) -> None:
    """``theta`` is the fit ``fitted`` came from with entry ``i`` set, not fitted: no interval there."""
    origin = fx.origin(fitted)
    if origin is not None:
        fx.record(theta, origin.holding([i], why))


def _stiction_from_rests(fx: _Fitter, base, c: Candidate, bound: _rests.RestBound, refit_others, dyn):
    """(θ, note) with the stiction set from the rests — ΔF = held − Coulomb, the rest refitted with
    it held, ΔF set again from the refitted model — or None when the rests held no more than
    ``min_breakaway_ratio`` × the Coulomb level (or ΔF comes out non-physical)."""
    s, i = fx.settings, fx.layout.index(c.key)
    j = fx.layout.index(f"{c.kind.breakaway_above}:{c.joint}")
    ratio = bound.held / base[j] if base[j] > 0 else 0.0
    seen = (
        f"rests held the joint against up to {bound.held:.3g} ({ratio:.2f}× its Coulomb level, "
        f"{bound.n_windows} windows of {s.rests.rest_window:g} s)"
    )
    if ratio < s.rests.min_breakaway_ratio:
        fx.notes.append(f"{c.key}: {seen}; under {s.rests.min_breakaway_ratio:g}×: no stiction from rests")
        return None
    th = base.copy()
    th[i] = bound.held - base[j]
    th = refit_others(th)
    fitted = th.copy()
    th[i] = _rest_bound(fx, th, dyn, c.joint).held - th[j]
    _held_from(fx, th, fitted, i, "set from the force the rests held, not fitted")
    if not (th[i] > 0 and is_physical(fx.layout, th)):
        fx.notes.append(f"{c.key}: {seen}; refitted, ΔF {th[i]:.3g} is not physical: not added")
        return None
    return th, f"found from rests: {seen}; breakaway at least {th[i] + th[j]:.3g}"
