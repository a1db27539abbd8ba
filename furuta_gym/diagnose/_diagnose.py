"""The diagnosis loop: fit the declared model, take its residual, trace it to an effect, refit.

Its steps, each in its module: log → prepared data (``_prepare``) → candidates and the trace's
search (``_candidates``) → fit (``_fitter``: equation error in ``_fit``, output error on open-loop
windows in ``_windows``; the refits that confirm the search's steps in
``_confirm``, with ``_input_search``, ``_stiction_search`` and ``_cable_search``) → verdict
(``_verdict``, ``_rigid_body``) → report (``_result``, ``_report``). See :func:`diagnose` and
``docs/diagnose.md``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .._x64 import ensure_x64
from ..lagrangian import AbstractLagrangianSystem
from ..models import system_definition
from ..models.checkpoint import load_model
from ..systems import get_spec
from . import _finish
from ._cable_search import _cable_laws
from ._candidates import _select, _trace, _untestable
from ._confirm import _confirm
from ._fitter import _fit_declared, _Fitter
from ._input_search import DELAY
from ._library import check_input_linear, layout_for
from ._prepare import _segments, _test_segments, prepare, sensor_resolution
from ._result import DiagnosisResult
from ._rigid_body import _with_rigid_bodies
from ._settings import DiagnosisSettings
from ._stiction_search import _stiction_by_prediction, _vetoed_with_stiction
from ._verdict import _finish_evidence, _mark_unresolved, _reported

__all__ = ["diagnose"]


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
    request = _Request(
        data,
        system,
        test,
        dict(column_map=column_map, signs=signs, offsets=offsets, units=units, time_unit=time_unit),
        candidates,
        model,
        (settings or DiagnosisSettings()).replaced(**overrides),
        keep_fitter=prediction,
    )
    result = _diagnose_once(request, fixed)
    if model is not None:  # a learned model is kept as it is: no lumped bodies to check
        return result
    result = _with_rigid_bodies(result, lambda held: _diagnose_once(request, {**result.fixed, **held}))
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
    if not overrides.get("oe", (settings or DiagnosisSettings()).output_error.oe):
        raise ValueError("finish='prediction' refits by output error, which oe=False turns off")
    return True


@dataclasses.dataclass(frozen=True)
class _Request:
    """What :func:`diagnose` was asked, passed whole to each diagnosis it runs: the logs and how
    they are read (``reading``: keywords of :func:`furuta_gym.data.read_log`), the library's
    ``candidates``, a given ``model``, the settings with the overrides applied; ``keep_fitter``:
    the fitting context stays on the result, for a finish."""

    data: Any
    system: str
    test: Any
    reading: dict
    candidates: Sequence[str] | None
    model: Any
    settings: DiagnosisSettings
    keep_fitter: bool = False


def _diagnose_once(request: _Request, fixed: Mapping[str, float] | None) -> DiagnosisResult:
    """One diagnosis with ``fixed`` as given (see :func:`diagnose`): the logs prepared and the
    fitting context built, then :func:`_search`."""
    ensure_x64()
    spec = get_spec(request.system)
    layout = layout_for(spec.name, _given_model(request.model, spec))
    notes: list[str] = []
    trajs, qds, settings = prepare(request.data, spec, request.settings, request.reading, notes)
    if any(tr.qd is None for tr in trajs):
        notes.append(f"velocities estimated ({settings.reading.velocity})")
    segs = _segments(trajs, qds, settings)
    test_segs = _test_segments(request.test, spec, settings, request.reading, trajs[0].dt, notes)
    u_all = np.concatenate([s.u[:, 0] for s in segs])
    forced = bool(np.std(u_all) > 1e-9 * max(1.0, np.abs(u_all).max()) and np.abs(u_all).max() > 0)
    fixed = _anchor(spec, layout, fixed, forced, notes)
    fixed_idx = {layout.index(k) for k in fixed}
    theta_fixed = layout.nominal()
    for k, v in fixed.items():
        theta_fixed[layout.index(k)] = v
    fx = _Fitter(spec, layout, segs, test_segs, theta_fixed, fixed_idx, settings, notes)
    fx.resolution = sensor_resolution(trajs, spec)
    return _search(fx, trajs, fixed, forced, request)


def _search(fx: _Fitter, trajs, fixed: dict[str, float], forced: bool, request: _Request) -> DiagnosisResult:
    """The declared model fitted, its residual traced to candidates, the steps confirmed or
    vetoed, stiction and the cable laws searched, the verdict and the result."""
    spec, layout, notes, settings = fx.spec, fx.layout, fx.notes, fx.settings
    segs, test_segs, candidates, keep_fitter = fx.segs, fx.test_segs, request.candidates, request.keep_fitter
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
