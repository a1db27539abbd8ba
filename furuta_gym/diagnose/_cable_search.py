"""Method step 11 in the loop (issue 64): on which joints the two cable laws (:mod:`._rotor_laws`)
are tried, the law kept replacing the joint's spring and dry friction, and a kept cable with
memory's held-out errors."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..models import system_definition
from . import _rotor_laws as _laws
from ._drift import rest_drift
from ._fitter import _Fitter
from ._intervals import FitOrigin
from ._library import Candidate
from ._problem import free_columns
from ._result import EffectEvidence, ErrorSummary
from ._stiction_search import _rest_bound
from ._trace import Evidence


def _cable_law_joints(fx: _Fitter, trajs, library, accepted, evidence, forced):
    """(spring, rests) of each joint where the two cable laws are tried (Method step 11): not loaded
    by gravity (there gravity sets the rest), encoder-quantised, with a spring a law with memory
    generalises and dry friction in the library, and asked for by the data (:func:`_data_ask`) or
    by the settings (``cable_laws="always"``)."""
    gravity = system_definition(fx.spec.name).lumped.gravity_joints
    out, always = [], fx.settings.rests.cable_laws == "always"
    for c in library:
        friction = [d for d in library if d.joint == c.joint and d.kind.is_dry_friction]
        if not (c.kind.absorbs_constant_force and _laws.memory_law_for(c.kind)) or len(friction) < 2:
            continue
        if c.joint in gravity or c.joint not in fx.resolution:
            continue
        rests = _data_ask(fx, trajs, c, friction, accepted, evidence, forced)
        if rests is None and always:
            rests = rest_drift(trajs, fx.spec.name, c.joint, flicker=1, count=fx.resolution[c.joint])
        if rests is not None:
            out.append((c, rests))
    return out


def _data_ask(fx: _Fitter, trajs, c: Candidate, friction, accepted, evidence, forced):
    """The rests of spring ``c``'s joint (:func:`rest_drift`, read through a one-count flicker) where
    the data ask for the laws, else None: the spring not added and vetoed for predicting worse, or
    removing ``inconsistent_gain`` of the held-out residual, fixed or with a neutral that moves
    (:func:`_memory_gain`), or added (under input, where :func:`_holding_open`), or its rests
    naming a law."""
    ev = evidence.get(c.key)
    if ev is not None and not ev.significant and ev.status in ("absorbed", "not identifiable", "equivalent"):
        return None
    rests = rest_drift(trajs, fx.spec.name, c.joint, flicker=1, count=fx.resolution[c.joint])
    named = not forced and rests.verdict in _laws.LAWS  # a spring added too may be the wrong law
    # without input a spring added may be either law's stand-in, whatever the rests say (a
    # fixed spring far too stiff holds a rotor that a breakaway held): the laws are tried;
    # under input, only where its joint's friction leaves open what held it (a controller
    # holds the rotor wherever it rests, and sliding friction found beside it explains that)
    if c in accepted and forced and not _holding_open(friction, accepted):
        return None
    if not (named or c in accepted or (ev is not None and ev.status == "not confirmed")):
        gain = fx.settings.search.inconsistent_gain
        if fx.comparer().compare(accepted, [c]).improvement < gain and _memory_gain(fx, trajs, accepted, c) < gain:
            return None
    return rests


def _holding_open(friction: list[Candidate], accepted) -> bool:
    """Whether a joint's dry friction as diagnosed leaves open what held it: no sliding friction
    added (a breakaway 5–10× a small sliding level hides that level from the equation error,
    which leaves stops out) or a stiction added (which law it belongs to is step 11's question)."""
    sliding = [d for d in friction if not d.kind.breakaway_above]
    return not any(d in accepted for d in sliding) or any(d in accepted for d in friction if d.kind.breakaway_above)


def _memory_gain(fx: _Fitter, trajs, accepted, spring: Candidate) -> float:
    """The held-out gain beside ``accepted`` of ``spring`` with a neutral that moves: its column
    with the neutral the play operator gives over the log's positions, at the best play of step
    11's grid. A cable whose rest moves pulls like a fixed spring only within its play, so the
    fixed spring's column can be flat where this one is not."""
    j, i = fx.spec.joint_names.index(spring.joint), fx.layout.index(spring.key)
    gains = [
        fx.comparer(fx.fit_prob.with_column(i, j, _laws.memory_column(trajs, j, fx.stride, fx.fit_prob, play)))
        .compare(accepted, [spring])
        .improvement
        for play in _laws.PLAY_GRID
    ]
    return max(gains)


def _cable_owned(c: Candidate, joint: str) -> bool:
    """Whether the cable laws refit ``c``: a spring, constant force or dry friction of ``joint``."""
    return c.joint == joint and (c.kind.in_potential or c.kind.is_constant_force or c.kind.is_dry_friction)


def _breakaway_diagnosed(accepted, spring: Candidate, evidence, rule, size_test: bool = False) -> tuple | None:
    """(the joint's effects, its stiction's evidence) where ``accepted`` already holds the large
    breakaway's law on the spring's joint (the spring and a stiction the earlier steps found,
    passing the trace's rule; or, ``size_test``, gaining its share whatever its t, as a stiction
    added on its rests' evidence does), else None: that law's fit is then the model as diagnosed,
    judged by the stiction's evidence."""
    owned = [a for a in accepted if _cable_owned(a, spring.joint)]
    stiction = next((a for a in owned if a.kind.breakaway_above), None)
    if spring not in owned or stiction is None or stiction.key not in evidence:
        return None
    ev = evidence[stiction.key]
    found = Evidence(ev.improvement or 0.0, ev.z_score or 0.0, 0)
    held = (
        found.improvement >= rule.min_improvement if size_test else found.passes(rule.min_improvement, rule.z_threshold)
    )
    return (owned, found) if held else None


def _model_if_refit_fails(ctx, theta, fits: dict, accepted, spring: Candidate, evidence, rule) -> dict:
    """``fits`` with the large breakaway's law the model as diagnosed where, under input, its refit
    does not pass the trace's rule and the model holds the law with a stiction added on its rests'
    evidence (:func:`_breakaway_diagnosed` with the size test): the refit is then the output-error
    fit the search made, re-finds what the model holds and, judged against it, gains nothing
    ("neither", though the model held the law). A log without input keeps its refit: it is
    fitted within the rests' bracket, which the search does not read."""
    refit = fits[_laws.LAWS[1]]
    if (
        not ctx.driven
        or refit.incumbent
        or (refit.physical and refit.evidence.passes(rule.min_improvement, rule.z_threshold))
    ):
        return fits
    held = _breakaway_diagnosed(accepted, spring, evidence, rule, size_test=True)
    return fits if held is None else {**fits, _laws.LAWS[1]: _laws.model_as_law(ctx, theta, *held)}


def _cable_laws(fx: _Fitter, trajs, library, accepted, theta, dyn, evidence, forced):
    """Method step 11 (:mod:`._rotor_laws`): on each joint of :func:`_cable_law_joints`, the
    moving rest and the large breakaway fitted by prediction and told apart; the law the data
    support (or the better of two that cannot be told apart) replaces the joint's spring and dry
    friction. Returns (accepted, θ, the joints' reports, (context, cable, its evidence) of a cable
    with memory kept, or None)."""
    s, reports, kept_cable = fx.settings, [], None
    rule = _laws.Rule(s.search.min_improvement, s.search.z_threshold, s.search.veto_t, rests_count=not forced)
    for spring, rests in _cable_law_joints(fx, trajs, library, accepted, evidence, forced):
        stays = [a for a in accepted if not _cable_owned(a, spring.joint)]
        ctx = _laws.Context(fx, spring.joint, trajs, dyn, stays, max(1, s.output_error.start_iterations), forced)
        stiffness = float(fx.fit_ee(accepted + [spring])[0][fx.layout.index(spring.key)])
        held = _rest_bound(fx, theta, dyn, spring.joint).held
        diagnosed = _breakaway_diagnosed(accepted, spring, evidence, rule)
        fits = _laws.fit_laws(ctx, theta, stiffness, held, s.output_error.oe_max_nfev, diagnosed)
        fits = _model_if_refit_fails(ctx, theta, fits, accepted, spring, evidence, rule)
        verdict, reason, kept, h2h = _laws.verdict(fits, rests, ctx.win_val.q, rule)
        fx.notes.append(f"{spring.joint}: the cable laws (Method step 11): {verdict}: {reason}")
        reports.append(_laws.RotorLaw(spring.joint, verdict, reason, rests, fits, kept, h2h))
        if kept is None or fits[kept].incumbent:  # none, or the model as diagnosed: nothing to change
            continue
        f = fits[kept]
        accepted, theta = ctx.others + f.effects, f.theta
        why = f"the {kept} law (Method step 11: {verdict})"
        if spring.key in evidence and evidence[spring.key].status == "not confirmed":
            why += f"; it fixed {spring.key}, vetoed for predicting worse with the joint's friction as it was"
            fx.notes.append(f"{spring.key}: vetoed, then fixed by the {kept} law (Method step 11)")
        for c in f.effects:
            evidence[c.key] = EffectEvidence(
                c.name, c.joint, None, c.unit(fx.spec), True, f.evidence.improvement, f.evidence.z, "selected", why
            )
        if f.cable[0]:
            kind = _laws.memory_law_for(spring.kind)
            assert kind is not None
            cable = EffectEvidence(
                kind.name,
                spring.joint,
                f.cable[0],
                spring.unit(fx.spec),
                True,
                f.evidence.improvement,
                f.evidence.z,
                "selected",
                why,
                play=f.cable[1],
            )
            kept_cable = (ctx, f.cable, cable)
        else:
            free = free_columns(fx.layout, accepted, fx.fixed_idx)
            fx.record(theta, FitOrigin("output_error", theta, free, dyn, ctx.start_iterations))
    return accepted, theta, reports, kept_cable


def _with_cable(fx: _Fitter, summary: ErrorSummary, kept_cable, theta, segs, prob) -> ErrorSummary:
    """``summary`` of ``segs`` with a kept cable with memory in the predictions and the residual."""
    ctx, cable, _ = kept_cable
    per, comb = _laws.window_errors(ctx, theta, cable, segs)
    r = _laws.residual(ctx, theta, cable, prob)
    names = fx.spec.joint_names
    return dataclasses.replace(
        summary,
        trajectory_rmse=comb,
        trajectory_rmse_per_joint={j: float(v) for j, v in zip(names, per, strict=True)},
        residual_rms=float(np.sqrt(np.mean(r**2))),
        residual_rms_per_joint={j: float(v) for j, v in zip(names, np.sqrt(np.mean(r**2, axis=0)), strict=True)},
    )
