"""The diagnosis loop: fit the declared model, take its residual, trace it to an effect, refit.

See :func:`diagnose` and ``docs/diagnose.md``.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .._x64 import ensure_x64
from ..effects import INPUT_DYNAMICS_EFFECTS, spring_rests
from ..lagrangian import AbstractLagrangianSystem
from ..models import system_definition
from ..models.checkpoint import load_model
from ..systems import get_spec
from . import _finish, _intervals
from ._cable_search import _cable_laws, _with_cable
from ._candidates import _select, _trace, _untestable
from ._confirm import _confirm
from ._fitter import _fit_declared, _Fitter
from ._input_search import DELAY
from ._intervals import FitOrigin, Interval
from ._library import Candidate, check_input_linear, layout_for
from ._prepare import _segments, _test_segments, prepare, sensor_resolution
from ._problem import fit_equation_error, free_columns
from ._result import DiagnosisResult, EffectEvidence, ErrorSummary
from ._rigid_body import _with_rigid_bodies
from ._settings import DiagnosisSettings
from ._stiction_search import _stiction_by_prediction, _vetoed_with_stiction

__all__ = ["diagnose"]


# ----------------------------------------------------------------------------- the loop


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


def _anchor(spec, layout, fixed, forced, notes):
    """The fixed lumped parameters (the scale anchor; with free data, the gain too)."""
    if layout.learned is not None:
        notes.append(
            "the given model is the declared model, as it is (overall scale held at 1); "
            "only the library's effects are fitted around it"
        )
        return {"scale": 1.0}
    lumped = system_definition(spec).lumped
    nom = lumped.nominal()
    if fixed:
        fixed = {k: float(v) for k, v in fixed.items()}
        for k in fixed:
            if k not in layout.base:
                raise ValueError(f"fixed: unknown parameter {k!r}; expected one of {list(layout.base)}")
    else:
        fixed = {lumped.scale_anchor: nom[lumped.scale_anchor]}
        note = lumped.anchor_note(nom, forced)
        if note:
            notes.append(note)
    if not forced:
        fixed.setdefault(lumped.gain, nom[lumped.gain])
        anchor = lumped.mechanical_anchor
        fixed.setdefault(anchor, nom[anchor])
        notes.append(
            "free data (u = 0): the overall scale and the input gain are not identifiable from "
            f"motion alone; {anchor} fixed at its nominal value {nom[anchor]:.6g} and the input "
            "gain at nominal; input effects are not tested"
        )
    return fixed


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
        if ev.status == "tested" and score.improvement >= fx.settings.inconsistent_gain:
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
        f"{score.z:.1f} < {settings.z_threshold:g}; helps on {helps or 'no recording'}; hurts on "
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
        start = max(1, fx.settings.start_iterations) if sticky else fx.settings.start_iterations
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


def _given_model(model, spec):
    """The model to diagnose instead of the analytic one: None, a Lagrangian system or a
    checkpoint path; checked against ``spec`` and for an input force the fit can integrate."""
    if model is None:
        return None
    if isinstance(model, (str, Path)):
        model = load_model(model, expected_system=spec.name)
    if not isinstance(model, AbstractLagrangianSystem):
        raise ValueError(f"model: expected a Lagrangian system or a checkpoint path, got {type(model).__name__}")
    if model.spec.name != spec.name:
        raise ValueError(f"model: a {model.spec.name} model cannot diagnose {spec.name} data")
    check_input_linear(model)
    return model


def diagnose(
    data,
    system: str,
    *,
    test=None,
    column_map: Mapping[str, str] | None = None,
    signs: Mapping[str, float] | None = None,
    offsets: Mapping[str, float] | None = None,
    units: Mapping[str, str] | str | None = None,
    time_unit: str | None = None,
    fixed: Mapping[str, float] | None = None,
    candidates: Sequence[str] | None = None,
    model=None,
    settings: DiagnosisSettings | None = None,
    finish: str | None = None,
    **overrides,
) -> DiagnosisResult:
    """Fit the declared model, trace its residual to missing effects, add them, refit, report.

    ``data``: a CSV/NPZ/MAT path or a list of paths (long format, see
    :func:`furuta_gym.data.load_trajectories`; ``column_map``/``signs``/``offsets``/``units``/
    ``time_unit`` as there) or a list of :class:`~furuta_gym.data.Trajectory` (``units`` and
    ``time_unit`` apply to these too). Either is read as every log is (wrapped angles unwrapped,
    split at gaps and missing values, repeated rows dropped, said in the notes; a log in degrees,
    counts or milliseconds stops, naming the keyword that fixes it). ``test``: logs in the same form never used by
    any fit or decision; errors before/after on them are reported beside the held-out split.
    ``system``: ``"furuta"`` or ``"nmsd"``. ``fixed``: lumped parameters held at known values
    (the scale anchor; default: the pendulum's gravity term ``G`` = ½mp·g·Lp for the Furuta, the
    input gain for the N-MSD; with free data the mass/gain is fixed too). ``candidates``: restrict
    the library (keys ``"effect:joint"``). ``model``: diagnose this Lagrangian model (e.g. a trained
    DeLaN, or a checkpoint path) instead of the analytic one: it is kept as it is and the
    library's effects are fitted around it. ``finish``: ``"report"`` (None, the default) or
    ``"prediction"``: after the diagnosis, its final model, ``inconsistent`` effects and every
    joint's Coulomb friction are refitted by output error on every fit-set window, kept if they
    predict the held-out windows better (``res.prediction``, ``res.plant(prediction_first=True)``);
    the report is the same either way. Other keyword arguments override
    :class:`DiagnosisSettings` fields.

    Returns a :class:`DiagnosisResult`: effects ordered by held-out evidence (those marked
    ``significant`` were added), held-out (and test) errors before/after, fitted parameters, notes.
    """
    prediction = _check_finish(finish, model, settings, overrides)
    once = functools.partial(
        _diagnose_once,
        data,
        system,
        test=test,
        reading=dict(column_map=column_map, signs=signs, offsets=offsets, units=units, time_unit=time_unit),
        candidates=candidates,
        model=model,
        settings=settings,
        keep_fitter=prediction,
        **overrides,
    )
    result = once(fixed=fixed)
    if model is not None:  # a learned model is kept as it is: no lumped bodies to check
        return result
    result = _with_rigid_bodies(result, lambda held: once(fixed={**result.fixed, **held}))
    if prediction:
        result.prediction = _finish.prediction_finish(result._fitter, result)
        result._fitter = None
    return result


def _check_finish(finish, model, settings, overrides) -> bool:
    """Whether a prediction-first finish was asked for; one error for what cannot have one."""
    if finish is None or finish == "report":
        return False
    if finish != "prediction":
        raise ValueError(f"finish: expected one of {list(_finish.FINISHES)} or None, got {finish!r}")
    if model is not None:
        raise ValueError(
            "finish='prediction' refits a plant of lumped parameters; a diagnosis of a given model has none"
        )
    if not overrides.get("oe", (settings or DiagnosisSettings()).oe):
        raise ValueError("finish='prediction' refits by output error, which oe=False turns off")
    return True


def _diagnose_once(
    data,
    system: str,
    *,
    test=None,
    reading: dict,
    fixed: Mapping[str, float] | None = None,
    candidates: Sequence[str] | None = None,
    model=None,
    settings: DiagnosisSettings | None = None,
    keep_fitter: bool = False,
    **overrides,
) -> DiagnosisResult:
    """One diagnosis with ``fixed`` as given (see :func:`diagnose`; ``reading``: how its logs are
    read, keywords of :func:`furuta_gym.data.read_log`); ``keep_fitter``: its fitting context
    stays on the result, for a finish."""
    ensure_x64()
    spec = get_spec(system)
    layout = layout_for(spec.name, _given_model(model, spec))
    notes: list[str] = []
    trajs, qds, settings = prepare(
        data, spec, dataclasses.replace(settings or DiagnosisSettings(), **overrides), reading, notes
    )
    if any(tr.qd is None for tr in trajs):
        notes.append(f"velocities estimated ({settings.velocity})")
    segs = _segments(trajs, qds, settings)
    test_segs = _test_segments(test, spec, settings, reading, trajs[0].dt, notes)
    u_all = np.concatenate([s.u[:, 0] for s in segs])
    forced = bool(np.std(u_all) > 1e-9 * max(1.0, np.abs(u_all).max()) and np.abs(u_all).max() > 0)
    fixed = _anchor(spec, layout, fixed, forced, notes)
    fixed_idx = {layout.index(k) for k in fixed}
    theta_fixed = layout.nominal()
    for k, v in fixed.items():
        theta_fixed[layout.index(k)] = v
    fx = _Fitter(spec, layout, segs, test_segs, theta_fixed, fixed_idx, settings, notes)
    fx.resolution = sensor_resolution(trajs, spec)
    th_before = _fit_declared(fx)
    before = fx.errors(th_before, fx.held_segs, fx.held_prob)
    test_before = fx.test_errors(th_before)

    library = _select(list(layout.candidates) + [DELAY], candidates)
    evidence = _untestable(fx, library, forced)
    steps = _trace(fx, [c for c in library if c.key not in evidence], evidence)
    accepted, th_after, dyn, vetoed = _confirm(fx, steps, th_before, evidence)
    accepted, th_after = _stiction_by_prediction(fx, library, accepted, th_after, dyn, evidence)
    accepted, th_after = _vetoed_with_stiction(fx, library, vetoed, accepted, th_after, dyn, evidence)
    accepted, th_after, cable_laws, cable = _cable_laws(fx, trajs, library, accepted, th_after, dyn, evidence, forced)
    after = fx.errors(th_after, fx.held_segs, fx.held_prob) if accepted else before
    test_after = fx.test_errors(th_after) if accepted else test_before
    ordered = _finish_evidence(fx, library, accepted, th_after, dyn, evidence)
    _mark_unresolved(ordered, fx.resolution, trajs[0].dt, notes)
    after, intervals, interval_method = _reported(fx, th_after, accepted, dyn, ordered, after, cable, test_after)
    if not accepted:
        notes.append("no effect is significant on held-out data: none added")

    params = lambda th: {b: float(th[i]) for i, b in enumerate(layout.base)}  # noqa: E731
    return DiagnosisResult(
        system=spec.name,
        effects=ordered,
        error_before=before,
        error_after=after,
        parameters_before=params(th_before),
        parameters_after=params(th_after),
        parameter_units=dict(zip(layout.base, layout.base_units, strict=True)),
        fixed=dict(fixed),
        notes=notes,
        settings=settings,
        layout=layout,
        theta_before=th_before,
        theta_after=th_after,
        input_dynamics=dyn,
        test_before=test_before,
        test_after=test_after,
        intervals=intervals,
        interval_method=interval_method,
        _segments=segs,
        _test_segments=test_segs,
        _fitter=fx if keep_fitter else None,
        rotor_laws=cable_laws,
    )
