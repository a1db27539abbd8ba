"""A prediction-first finish: the diagnosed model refitted for prediction, beside the diagnosis.

The diagnosis adds an effect only on consistent cross-validated evidence (docs/diagnose.md,
Method). A user who wants the best simulator of the rig rather than a claim about it can ask for
more (``diagnose(..., finish="prediction")``): the final model, its ``inconsistent`` effects and
every joint's Coulomb friction refitted together by output error on every fit-set window, kept
only if it predicts the held-out windows of the fit logs better than the diagnosis' own plants,
by the diagnosis' rule for a gain (``min_improvement`` of the sum of squares, per-window log
ratios' t ≥ ``z_threshold``).
The diagnosis' report (effects, evidence, intervals, errors) is not touched: the finish is
recorded beside it (:class:`PredictionFinish`).

The refit's windows start at every point of a window-long cycle: one after another in each fit
segment with a ``STARTS_EVERY`` gap between them (:func:`placed_windows`, ``"staggered"``). A
0.1 s window's error depends on where it starts in a periodic input (the shipped runs' input steps
every 0.1 s), and windows back to back from each segment's first sample start at a few points of
such a cycle only, which the refit then favours (docs/diagnose.md, "What separates
prediction-first from sysid"). The held-out windows stay the diagnosis' own.

The refit then tries an input dead band (``input_dead_band``, :func:`_fit_dead_band`): a few
widths ranked by short refits of θ, the best refitted in full, its width then searched on
:data:`DEAD_BAND_GRID` and θ refitted there. It joins the finish's plant only by the diagnosis' rule for a gain on the held-out
windows against the refit without it (:class:`DeadBandTrial`). It is not a library candidate:
the diagnosis' report does not name it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..effects import Effect, can_join, merge_spring_rests
from ..envs import Plant
from ..models import system_definition
from . import _fit, _trace as _trace_mod, _windows
from ._library import Candidate, is_physical
from ._problem import free_columns

__all__ = [
    "FINISHES",
    "PLACEMENTS",
    "STARTS_EVERY",
    "DEAD_BAND_GRID",
    "DeadBandTrial",
    "PredictionFinish",
    "log_starts",
    "placed_windows",
    "prediction_finish",
]

#: ``diagnose(finish=...)``: the report alone, or the report and a plant refitted for prediction
FINISHES = ("report", "prediction")
#: where a segment's windows start: back to back from the segment's first sample (the
#: diagnosis'), on its log's back-to-back grid from the log's first sample (the head-to-head's
#: scoring and mujoco.sysid's fit), or every ``STARTS_EVERY`` s of the log (every phase alike)
PLACEMENTS = ("segments", "grid", "starts")
STARTS_EVERY = 0.01
#: ... or one after another with a ``STARTS_EVERY`` gap between them, so that their starts move
#: through every point of a cycle of the window's length without overlapping (the refit's)
STAGGERED = "staggered"
#: the input dead bands the finish searches (the input's unit: V for the Furuta's motor; the
#: real QUBE's is about 50 mV, docs/diagnose.md), and the rounds of search and refit
DEAD_BAND_GRID = tuple(round(0.01 * k, 3) for k in range(16))
#: the widths the refit is repeated at before the search on the grid (:func:`_fit_dead_band`)
DEAD_BAND_COARSE = (0.02, 0.05, 0.1)
#: the output-error evaluations of the short refits that rank those widths: a refit's first steps
#: take nearly all of its fall in error, and only the best width is worth a refit in full
DEAD_BAND_SCREEN_NFEV = 3


@dataclasses.dataclass(frozen=True)
class DeadBandTrial:
    """The finish's input dead band: the ``width`` its search found (0: none better than none),
    whether it joined the plant and why, and its evidence on the held-out windows against the
    refit without it (``improvement`` of the sum of squares, ``z_score`` the t of the per-window
    log ratios; NaN when not refitted), with both refits' position RMSE."""

    width: float
    unit: str
    kept: bool
    reason: str
    improvement: float = float("nan")
    z_score: float = float("nan")
    heldout_rmse: dict[str, float] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        finite = lambda x: float(x) if np.isfinite(x) else None  # noqa: E731
        return {
            "effect": "input_dead_band:u",
            "width": self.width,
            "unit": self.unit,
            "kept": self.kept,
            "reason": self.reason,
            "heldout_improvement": finite(self.improvement),
            "z_score": finite(self.z_score),
            "heldout_trajectory_rmse": {k: finite(v) for k, v in self.heldout_rmse.items()},
        }

    def summary(self) -> str:
        return f"  input dead band: {'kept' if self.kept else 'not kept'} — {self.reason}"


@dataclasses.dataclass(frozen=True)
class PredictionFinish:
    """What the prediction-first finish did. ``plant`` is the plant to simulate with: the refit's
    when ``kept``, else the diagnosis' own (``res.plant()``); ``refit`` is the refit's either way
    (None when it did not simulate). ``heldout_rmse``: position RMSE (rad or m) on the held-out
    windows of the fit logs of the diagnosed plant, of it with its inconsistent effects, and of the
    refit; ``improvement`` and ``z_score``: the refit's drop of the held-out sum of squares
    against ``baseline`` (the better of the first two) and the t of its per-window log ratios."""

    kept: bool
    reason: str
    plant: Plant
    refit: Plant | None
    added: tuple[str, ...]  # effects beyond the found ones in the refit
    left_out: tuple[str, ...]  # of the wrong physical sign after the refit
    heldout_rmse: dict[str, float]
    baseline: str
    improvement: float
    z_score: float
    fit_windows: int
    heldout_windows: int
    window_seconds: float
    dead_band: DeadBandTrial | None = None
    #: the refit without its dead band, which plain MuJoCo cannot run (None: no dead band kept)
    mujoco_refit: Plant | None = None

    @property
    def mujoco_plant(self) -> Plant:
        """The plant for plain MuJoCo (``diagnose --mjcf``, :func:`~furuta_gym.envs.save_mjcf`):
        ``plant``, or, when it holds an effect MJCF cannot express (an input dead band) and it is
        the refit, the refit fitted without it, which predicts better than the plant with that
        effect dropped."""
        return self.mujoco_refit if self.kept and self.mujoco_refit is not None else self.plant

    def to_json(self) -> dict:
        finite = lambda x: float(x) if np.isfinite(x) else None  # noqa: E731
        return {
            "kept": self.kept,
            "reason": self.reason,
            "added": list(self.added),
            "left_out": list(self.left_out),
            "heldout_trajectory_rmse": {k: finite(v) for k, v in self.heldout_rmse.items()},
            "baseline": self.baseline,
            "heldout_improvement": finite(self.improvement),
            "z_score": finite(self.z_score),
            "fit_windows": self.fit_windows,
            "heldout_windows": self.heldout_windows,
            "window_seconds": self.window_seconds,
            "plant": self.plant.to_json(),
            "refit_plant": None if self.refit is None else self.refit.to_json(),
            "dead_band": None if self.dead_band is None else self.dead_band.to_json(),
            "mujoco_plant": None if self.mujoco_refit is None else self.mujoco_refit.to_json(),
        }

    def summary(self) -> str:
        """Lines for the terminal: the decision and the held-out comparison."""
        rmse = ", ".join(f"{k.replace('_', ' ')} {v:.4g}" for k, v in self.heldout_rmse.items())
        return "\n".join(
            (
                f"prediction-first finish: {'kept' if self.kept else 'not kept'} — {self.reason}",
                f"  held-out windows of the fit logs ({self.heldout_windows} × {self.window_seconds:g} s), "
                f"position RMSE: {rmse}",
                f"  refitted by output error on {self.fit_windows} fit-set windows (starting anywhere); added: "
                f"{', '.join(self.added) or 'nothing'}; left out (wrong sign): {', '.join(self.left_out) or 'nothing'}",
            )
            + (() if self.dead_band is None else (self.dead_band.summary(),))
        )


def _log_name(segment) -> str:
    return segment.name.rsplit("[", 1)[0]


def log_starts(segments, trim_seconds: float) -> dict[str, float]:
    """Each log's first sample time: its first segment starts ``trim_seconds`` after it."""
    out: dict[str, float] = {}
    for s in segments:
        out[_log_name(s)] = min(out.get(_log_name(s), np.inf), float(s.t[0]) - trim_seconds)
    return out


def placed_windows(segments, length: int, dyn, placement: str, starts: dict[str, float]) -> _windows.Windows:
    """``length``-step windows inside each segment, starting as ``placement`` says
    (:data:`PLACEMENTS`; ``starts``: each log's first sample time, :func:`log_starts`)."""
    if placement not in PLACEMENTS + (STAGGERED,):
        raise ValueError(f"placement: expected one of {PLACEMENTS + (STAGGERED,)}, got {placement!r}")
    if placement == "segments":
        win = _windows.make_windows(segments, length, dyn)
        assert win is not None, "every segment holds a window"
        return win
    x0, us, qs, idx = [], [], [], []
    for i, s in enumerate(segments):
        gap = max(1, int(round(STARTS_EVERY / s.dt)))
        step = {"grid": length, "starts": gap, STAGGERED: length + gap}[placement]
        first = int(round((s.t[0] - starts[_log_name(s)]) / s.dt))  # the segment's sample on its log
        u = dyn.apply(s.u, s.dt)
        for a in range((-first) % step, s.q.shape[0] - length, step):
            x0.append(np.concatenate([s.q[a], s.qd[a]]))
            us.append(u[a : a + length])
            qs.append(s.q[a + 1 : a + length + 1])
            idx.append(i)
    assert x0, "every segment holds a window"
    return _windows.Windows(np.array(x0), np.array(us), np.array(qs), np.array(idx), segments[0].dt, length)


def drawn(win: _windows.Windows, count: int | None) -> _windows.Windows:
    """``count`` of the windows drawn at random (as ``make_windows`` draws), or all of them."""
    if count is None or win.x0.shape[0] <= count:
        return win
    keep = np.sort(np.random.default_rng(0).choice(win.x0.shape[0], count, replace=False))
    return win.take(keep)


def refit_windows(fx, segments, dyn) -> _windows.Windows:
    """The refit's windows: one after another in each segment with a :data:`STARTS_EVERY` gap
    between them, from each log's grid (module docstring)."""
    return placed_windows(segments, fx.L, dyn, STAGGERED, log_starts(fx.segs, fx.settings.reading.trim_seconds))


def _extra_candidates(layout, result) -> list[tuple[Candidate, float]]:
    """What the refit adds to the found effects, with its start coefficient: the joinable
    ``inconsistent`` effects at their tested coefficients, and each joint's Coulomb friction not
    already in (at its tested coefficient when that is positive, else 0). An inconsistent input
    delay or lag is not among them: it has no column in θ (:func:`_refit_dynamics` holds it)."""
    found = result.significant
    have = {(e.name, e.joint) for e in found}
    out = [
        (Candidate(e.name, e.joint), float(e.coefficient))
        for e in result.inconsistent
        if can_join(e, found) and not e.kind.input_dynamics
    ]
    have |= {(c.name, c.joint) for c, _ in out}
    tested = {(e.name, e.joint): e.coefficient for e in result.effects}
    for c in layout.candidates:
        if c.kind.is_dry_friction and c.kind.breakaway_above is None and (c.name, c.joint) not in have:
            out.append((c, max(0.0, float(tested.get((c.name, c.joint)) or 0.0))))
    return out


def _refit_dynamics(result) -> tuple[_fit.InputDynamics, list[Candidate]]:
    """The refit's input dynamics: the diagnosis' own, or, when it found none, an ``inconsistent``
    input delay or lag at its tested value (held there: the refit has no column for it, and the
    windows are built on it), with its candidate for the refit's plant."""
    if result.input_dynamics.kind != "none":
        return result.input_dynamics, []
    for e in result.inconsistent:
        if e.kind.input_dynamics and e.coefficient is not None and e.coefficient > 0:
            return _fit.InputDynamics(e.kind.input_dynamics, float(e.coefficient)), [Candidate(e.name, e.joint)]
    return result.input_dynamics, []


def _effects(layout, theta, chosen, dyn) -> list[Effect]:
    """``chosen`` candidates at their coefficients in ``theta`` (the input dynamics' at ``dyn``)."""
    return [
        Effect(c.name, c.joint, dyn.seconds if c.kind.input_dynamics else float(theta[layout.index(c.key)]))
        for c in chosen
    ]


def _refit(fx, theta, chosen, dyn, win, max_nfev: int | None = None):
    """Output error on ``win`` with ``chosen`` free (at most ``max_nfev`` evaluations, default the
    settings'); effects the refit leaves of the wrong physical sign
    (:func:`~furuta_gym.effects.can_join`) are left out and the rest refitted. Returns (θ, kept
    candidates, left-out keys, whether any refit lowered the fit windows' error)."""
    s, chosen, left_out, improved = fx.settings, list(chosen), [], False
    max_nfev = s.output_error.oe_max_nfev if max_nfev is None else max_nfev
    for _ in range(len(chosen) + 1):
        free = free_columns(fx.layout, chosen, fx.fixed_idx)
        theta, ok = _windows.oe_fit(fx.layout, theta, free, win, fx.substeps, max_nfev, s.output_error.start_iterations)
        improved |= ok
        effects = _effects(fx.layout, theta, chosen, dyn)
        bad = [c for c, e in zip(chosen, effects, strict=True) if not can_join(e, effects)]
        if not bad:
            break
        theta = np.array(theta, dtype=float)
        for c in bad:
            theta[fx.layout.index(c.key)] = 0.0
        left_out += [c.key for c in bad]
        chosen = [c for c in chosen if c not in bad]
    return theta, chosen, left_out, improved


def _heldout_sums(fx, thetas: dict, win) -> dict[str, np.ndarray]:
    """Per-window squared position errors on the held-out windows, as ``error_after`` scores them."""
    return {k: _windows.window_square_sums(fx.layout, th, win, fx.substeps) for k, th in thetas.items()}


def _rigid_failure(system: str, theta, layout) -> str | None:
    """Why the refit's lumped values have no rigid bodies (MuJoCo refuses them), or None."""
    conditions = system_definition(system).body_conditions
    if conditions is None:
        return None
    failed = [c for c in conditions({b: float(theta[i]) for i, b in enumerate(layout.base)}) if not c.holds]
    return None if not failed else f"{failed[0].expression} = {failed[0].value:.3g} ≤ 0, which no rigid bodies have"


def _decide(fx, result, theta, improved, ev) -> str | None:
    """Why the refit is not kept, or None when it is."""
    s = fx.settings
    if not improved:
        return "the output-error refit did not lower the fit windows' error"
    if not is_physical(fx.layout, theta):
        return "the refit's declared parameters are non-physical"
    rigid = _rigid_failure(result.system, theta, fx.layout)
    if rigid:
        return f"the refit's values fail a body condition: {rigid}"
    if not ev.passes(s.search.min_improvement, s.search.z_threshold):
        return (
            f"it predicts the held-out windows {ev.improvement:+.1%} better (sum of squares, t {ev.z:.1f}); "
            f"the diagnosis' rule for a gain asks ≥ {s.search.min_improvement:.0%} and t ≥ {s.search.z_threshold:g}"
        )
    return None


def _heldout_evidence(base, sums) -> _trace_mod.Evidence:
    """The gain of per-window held-out ``sums`` over ``base`` (a refit that did not simulate
    every window gains nothing)."""
    if not np.all(np.isfinite(sums)):
        return _trace_mod.Evidence(-np.inf, -np.inf, int(sums.size))
    return _trace_mod.Evidence.of_sums(base, sums)


def _fit_total(fx, theta, win) -> float:
    """The sum of squares of windows ``win`` at ``theta``."""
    return float(_windows.window_square_sums(fx.layout, theta, win, fx.substeps).sum())


def _band_refit(fx, fit, dyn, width: float, windows, max_nfev: int | None = None):
    """The refit ``fit`` (θ, chosen, left out, improved) refitted from its θ with a dead band of
    ``width`` on the training windows ``windows(dynamics)`` (``max_nfev``: :func:`_refit`'s):
    (their sum of squares, the refit, its input dynamics)."""
    band = _fit.DeadBandInput(dyn.kind, dyn.seconds, float(width))
    win = windows(band)
    theta, chosen, left_out, improved = _refit(fx, fit[0], fit[1], band, win, max_nfev)
    refit = (theta, chosen, list(fit[2]) + [k for k in left_out if k not in fit[2]], improved or fit[3])
    return _fit_total(fx, theta, win), refit, band


def _fit_dead_band(fx, fit, dyn, windows=None):
    """The dead band fitted with the rest from the refit ``fit``: the widths of
    :data:`DEAD_BAND_COARSE` ranked by the training windows' error after a short refit of θ at
    each (:data:`DEAD_BAND_SCREEN_NFEV`; the refit without one has absorbed what it can into the
    friction, so a width searched at its θ alone finds none), θ refitted in full at the best; then
    the width searched on :data:`DEAD_BAND_GRID` at that refit's θ and θ refitted there once more.
    ``windows(dynamics)``: the training windows (default: the finish's, on the fit segments).
    Returns (the refit with it, its input dynamics), or None when none beats the refit without."""
    windows = windows or (lambda d: refit_windows(fx, fx.fit_segs, d))
    total = lambda b: b[0]  # noqa: E731
    none = (_fit_total(fx, fit[0], windows(dyn)), fit, None)
    short = [_band_refit(fx, fit, dyn, w, windows, DEAD_BAND_SCREEN_NFEV) for w in DEAD_BAND_COARSE]
    ranked = min([none, *short], key=total)[2]
    best = none if ranked is None else min(none, _band_refit(fx, fit, dyn, ranked.dead_band, windows), key=total)
    if best[2] is None:
        return None
    grid = [_fit.DeadBandInput(dyn.kind, dyn.seconds, w) for w in DEAD_BAND_GRID]
    width = DEAD_BAND_GRID[int(np.nanargmin([_fit_total(fx, best[1][0], windows(d)) for d in grid]))]
    if width not in (0.0, best[2].dead_band):
        best = min(best, _band_refit(fx, best[1], dyn, width, windows), key=total)
    return best[1], best[2]


def _dead_band_trial(fx, result, fit, dyn, refit_sums):
    """The refit with an input dead band when it passes the diagnosis' rule for a gain on the
    held-out windows against ``fit``, the refit without (held-out sums ``refit_sums``), and is
    physical: (refit, input dynamics, held-out sums, :class:`DeadBandTrial`)."""
    unit = Effect("input_dead_band", "u", 0.0).unit(fx.spec)
    if dyn.kind == "lag":
        why = "not tried: with an actuator lag, the MuJoCo plant and the model would apply it in other orders"
        return fit, dyn, refit_sums, DeadBandTrial(0.0, unit, False, why)
    found = _fit_dead_band(fx, fit, dyn)
    if found is None:
        return fit, dyn, refit_sums, DeadBandTrial(0.0, unit, False, "the fit windows' error is least without one")
    band_fit, band = found
    sums = _heldout_sums(fx, {"band": band_fit[0]}, _windows.make_windows(fx.held_segs, fx.L, band))["band"]
    ev = _heldout_evidence(refit_sums, sums)
    why_not = _decide(fx, result, band_fit[0], True, ev)
    n = len(fx.spec.joint_names)
    rmse = {k: _windows.position_rmse(v, fx.L, n) for k, v in (("without", refit_sums), ("with", sums))}
    reason = (
        why_not or f"predicts the held-out windows {ev.improvement:.1%} better (t {ev.z:.1f}) than the refit without"
    )
    trial = DeadBandTrial(
        band.dead_band, unit, why_not is None, f"{band.dead_band:g} {unit}: {reason}", ev.improvement, ev.z, rmse
    )
    return (band_fit, band, sums, trial) if why_not is None else (fit, dyn, refit_sums, trial)


def _plant_effects(layout, theta, chosen, dyn) -> list[Effect]:
    """The refit plant's effects: the chosen ones (springs with their rests), and a dead band."""
    effects = merge_spring_rests(_effects(layout, theta, chosen, dyn))
    width = getattr(dyn, "dead_band", 0.0)
    return effects + ([Effect("input_dead_band", "u", width)] if width > 0 else [])


def _refit_names(chosen, dyn) -> list[str]:
    """The refit's effects by name: the ``chosen`` candidates, and the dead band of ``dyn``."""
    return [c.key for c in chosen] + (["input_dead_band:u"] if getattr(dyn, "dead_band", 0.0) > 0 else [])


def _refit_plant(layout, result, theta, chosen, dyn) -> Plant:
    """The refit at ``theta`` with the ``chosen`` effects and input dynamics ``dyn`` as a plant."""
    names = _refit_names(chosen, dyn)
    return Plant(
        effects=_plant_effects(layout, theta, chosen, dyn),
        lumped={b: float(theta[i]) for i, b in enumerate(layout.base)},
        system=result.system,
        source=f"diagnosis, prediction-first refit ({', '.join(names) or 'no effect'})",
    )


def prediction_finish(fx, result) -> PredictionFinish:
    """Refit ``result``'s final model for prediction on its fitting context ``fx`` (the
    diagnosis' ``_Fitter``) and decide whether to keep it (module docstring)."""
    layout, (dyn, extra_dynamics) = fx.layout, _refit_dynamics(result)
    if fx.dynamics != result.input_dynamics:
        fx.build(result.input_dynamics)
    found = [Candidate(e.name, e.joint) for e in result.significant] + extra_dynamics
    extra = _extra_candidates(layout, result)
    start = np.array(result.theta_after, dtype=float)
    with_inconsistent = start.copy()
    for c, coefficient in extra:
        start[layout.index(c.key)] = coefficient
        if any(c == Candidate(e.name, e.joint) for e in result.inconsistent):
            with_inconsistent[layout.index(c.key)] = coefficient
    fit_win = refit_windows(fx, fx.fit_segs, dyn)
    held_win = _windows.make_windows(fx.held_segs, fx.L, dyn)
    fit = _refit(fx, start, found + [c for c, _ in extra], dyn, fit_win)
    # the diagnosed plant is scored with its own input dynamics, the other two with the refit's
    sums = _heldout_sums(fx, {"with_inconsistent": with_inconsistent, "refit": fit[0]}, held_win)
    without = (fit, dyn)  # the refit without a dead band: plain MuJoCo has no form of one
    fit, dyn, sums["refit"], band = _dead_band_trial(fx, result, fit, dyn, sums["refit"])
    theta, chosen, left_out, improved = fit
    diagnosed_win = _windows.make_windows(fx.held_segs, fx.L, result.input_dynamics)
    sums = {**_heldout_sums(fx, {"diagnosed": result.theta_after}, diagnosed_win), **sums}
    baseline = min(("diagnosed", "with_inconsistent"), key=lambda k: sums[k].sum())
    ev = _heldout_evidence(sums[baseline], sums["refit"])
    why_not = _decide(fx, result, theta, improved, ev)
    names = _refit_names(chosen, dyn)
    refit = _refit_plant(layout, result, theta, chosen, dyn)
    reason = why_not or (
        f"predicts the held-out windows {ev.improvement:.1%} better (sum of squares, t {ev.z:.1f}) "
        f"than the diagnosed plant{' with its inconsistent effects' if baseline == 'with_inconsistent' else ''}"
    )
    length, n = held_win.q.shape[1:]
    return PredictionFinish(
        kept=why_not is None,
        reason=reason,
        plant=refit if why_not is None else result.plant(),
        refit=refit if np.all(np.isfinite(sums["refit"])) else None,
        added=tuple(k for k in names if k not in {f"{e.name}:{e.joint}" for e in result.significant}),
        left_out=tuple(left_out),
        heldout_rmse={k: _windows.position_rmse(v, length, n) for k, v in sums.items()},
        baseline=baseline,
        improvement=float(ev.improvement),
        z_score=float(ev.z),
        fit_windows=int(fit_win.x0.shape[0]),
        heldout_windows=int(held_win.x0.shape[0]),
        window_seconds=float(fx.settings.output_error.window),
        dead_band=band,
        mujoco_refit=_mujoco_refit(layout, result, without, band),
    )


def _mujoco_refit(layout, result, without, band: DeadBandTrial) -> Plant | None:
    """The refit without its dead band (``without``: that refit and its input dynamics) as the
    plant for plain MuJoCo, which has no form of one; None when no dead band was kept."""
    if not band.kept:
        return None
    plant = _refit_plant(layout, result, without[0][0], without[0][1], without[1])
    why = f"refitted without its input dead band ({band.width:g} {band.unit}), which MJCF cannot express"
    return dataclasses.replace(plant, source=f"{plant.source}; {why}")
