"""The verdict on the search's steps: each refitted in order and kept unless the refitted model
predicts the fit-set validation windows significantly worse or turns a coefficient non-physical."""

from __future__ import annotations

from . import _fit
from ._fitter import _Fitter, _prediction_evidence
from ._input_search import DELAY, _search_input_dynamics
from ._library import Candidate, non_physical


def _try_step(fx: _Fitter, accepted, dyn, sums, step):
    """Refit with ``step`` added to ``accepted``; returns (evidence on the fit-set validation
    windows against ``sums``, θ, input dynamics, the refit's per-window sums)."""
    trial = accepted + list(step.members)
    trial_dyn = _search_input_dynamics(fx, trial) if DELAY in step.members else dyn
    fx.build(trial_dyn)
    th_ee, free = fx.fit_ee(trial)
    th = fx.refine(th_ee, free, trial_dyn, "with " + ", ".join(c.key for c in trial))
    trial_sums = fx.validation_sums(th, trial_dyn)
    return _prediction_evidence(sums, trial_sums), th, trial_dyn, trial_sums


def _confirm(fx: _Fitter, steps, theta_before, evidence):
    """Add the search's steps in order and refit; a step is vetoed if the refitted model predicts
    the fit-set validation windows significantly worse (t of per-window log ratios ≤
    −``veto_t``): the trace is an equation-error test, and on closed-loop logs the input correlates
    with the measurement noise. A vetoed step is tried once more after the others: an effect can
    predict worse only while another one is missing (a pendulum's centre-of-mass offset before the
    rotor's friction and the input lag). A step is vetoed too if its refit gives one of its own
    coefficients the non-physical sign (a spring, friction or drag ≤ 0: the search tested signs on
    the equation-error fit alone); an effect that a later step's refit turns non-physical is
    dropped at the end. Returns (accepted candidates, θ, input dynamics, the steps vetoed for
    predicting worse)."""
    if not steps:
        return [], theta_before, fx.dynamics, []
    accepted: list[Candidate] = []
    theta, dyn = theta_before, _fit.NO_INPUT_DYNAMICS
    sums = fx.validation_sums(theta, dyn)
    todo = list(steps)
    for _ in range(2):  # a second pass for what was vetoed
        vetoed = []
        for step in todo:
            ev, th, trial_dyn, trial_sums = _try_step(fx, accepted, dyn, sums, step)
            flipped = non_physical(fx.layout, th, step.members)
            if ev.z > -fx.settings.search.veto_t and not flipped:
                accepted, theta, dyn, sums = accepted + list(step.members), th, trial_dyn, trial_sums
            else:
                vetoed.append((step, ev, flipped))
        if not vetoed or len(vetoed) == len(todo):  # nothing vetoed, or nothing added since
            break
        todo = [step for step, _, _ in vetoed]
    for step, ev, flipped in vetoed:
        for c in step.members:
            _not_confirmed(
                fx,
                evidence,
                c.key,
                f"the refit gives {', '.join(flipped)} the non-physical sign"
                if flipped
                else f"the refitted model predicts the fit-set validation windows significantly worse "
                f"(error {-ev.improvement:+.1%}, t {ev.z:.1f})",
            )
    fx.build(dyn)
    accepted, theta = _drop_non_physical(fx, accepted, theta, dyn, evidence)
    return accepted, theta, dyn, [step for step, _, flipped in vetoed if not flipped]


def _not_confirmed(fx: _Fitter, evidence, key: str, why: str) -> None:
    """Mark an effect the search found but the refits did not keep, with the reason."""
    bad = evidence[key]
    bad.significant, bad.status = False, "not confirmed"
    bad.note = f"equation-error evidence, but {why}"
    fx.notes.append(f"{key}: {bad.note}; dropped")


def _drop_non_physical(fx: _Fitter, accepted, theta, dyn, evidence):
    """Effects that the refits of steps added after them left with the non-physical sign are
    dropped and the rest refitted (the later, physical steps stay); the regressors are those of
    ``dyn``, built already. Returns (accepted, θ)."""
    for _ in range(len(accepted)):
        flipped = non_physical(fx.layout, theta, accepted)
        if not flipped:
            break
        for key in flipped:
            _not_confirmed(fx, evidence, key, "refitted with the effects added after it its sign is non-physical")
        accepted = [c for c in accepted if c.key not in flipped]
        th_ee, free = fx.fit_ee(accepted)
        theta = fx.refine(th_ee, free, dyn, "with " + ", ".join(c.key for c in accepted))
    return accepted, theta
