"""Reporting a :class:`~._result.DiagnosisResult`: terminal table, JSON file, figures.

Nothing here overwrites an existing file unless ``overwrite=True``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from ..effects import EFFECT_KINDS
from ..models import system_definition
from ..systems import get_spec
from . import _fit, _windows
from ._problem import Problem

__all__ = ["format_table", "write_json", "write_figures"]


def _g(x, fmt="{:.3g}"):
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else fmt.format(x)


def format_table(res) -> str:
    """Human-readable summary: effects by evidence, errors before/after, fitted parameters."""
    lines = [f"diagnosis of a {res.system} model", ""]
    lines += _effect_rows(res)
    lines.append("")
    lines += _error_rows(
        f"held-out errors ({res.error_before.n_windows} open-loop windows of {res.error_before.window_seconds} s)",
        res.error_before,
        res.error_after,
    )
    if res.test_before is not None:
        # the test logs (``test=``) are never fitted nor used for any decision: the fairest score
        lines += _error_rows(
            f"test-log errors ({res.test_before.n_windows} windows, logs never fitted)", res.test_before, res.test_after
        )
    lines.append("")
    lines += _parameter_rows(res)
    lines += [f"note: {n}" for n in res.notes]
    return "\n".join(lines)


def _effect_rows(res) -> list[str]:
    """The effects table and its verdict lines (none, inconsistent, second parameters, cable laws)."""
    lines = [
        f"{'effect':<18}{'joint':<7}{'coefficient':>13}{'± 95 %':>11}  {'unit':<15}{'held-out gain':>14}"
        f"{'z':>7}  verdict"
    ]
    for e in res.effects:
        verdict = "SIGNIFICANT" if e.significant else e.status.upper() if e.status == "inconsistent" else e.status
        if e.significant and not e.resolved:
            verdict += " (below the sensor's resolution)"
        gain = None if e.improvement is None else 100 * e.improvement
        lines.append(
            f"{e.name:<18}{e.joint:<7}{_g(e.coefficient):>13}{_pm(e.interval):>11}  {e.unit:<15}"
            f"{_g(gain, '{:.1f} %'):>14}{_g(e.z_score, '{:.1f}'):>7}  {verdict}"
        )
    if not res.significant:
        lines.append("-> none: no effect is significant on held-out data")
    for e in res.effects:
        if e.status == "inconsistent":  # never just "none": say where it helps and where it hurts
            lines.append(f"-> {e.name}:{e.joint} {e.note}")
        if e.significant and e.play is not None:
            lines.append(f"-> {e.name}:{e.joint} {e.kind.second_parameter} {e.play:.3g}")
    for law in res.rotor_laws:  # Method step 11: which law of the joint's cable the data support
        lines.append(f"-> {law.joint}'s cable: {law.verdict}: {law.reason}")
    return lines


def _parameter_rows(res) -> list[str]:
    """The fitted parameters, before -> after with their intervals, and the input dynamics."""
    fixed = f"; fixed: {res.fixed}" if res.fixed else ""
    lines = [f"fitted parameters (before -> after ± 95 % interval){fixed}"]
    for k in res.parameters_before:
        lines.append(
            f"  {k:<10}{res.parameters_before[k]:>13.5g} -> {res.parameters_after[k]:<13.5g}"
            f"{_pm(res.intervals.get(k)):<11}{res.parameter_units[k]}"
        )
    if res.input_dynamics.kind != "none":
        name = "delay" if res.input_dynamics.kind == "delay" else "lag"
        ev = next((e for e in res.significant if e.kind.input_dynamics), None)
        lines.append(
            f"  {name:<10}{0.0:>13.5g} -> {res.input_dynamics.seconds:<13.5g}"
            f"{_pm(None if ev is None else ev.interval):<11}s"
        )
    return lines


def _pm(interval) -> str:
    """An interval as ± its half-width (the intervals are symmetric), "± inf" when unbounded,
    blank when there is none (not an added effect, a fixed or held parameter)."""
    if interval is None:
        return ""
    if interval.unbounded:
        return "± inf"
    return f"± {0.5 * (interval.upper - interval.lower):.2g}"


def _error_rows(title, b, a) -> list[str]:
    lines = [f"{title:<60}{'before':>10}{'after':>13}{'ratio':>8}"]
    rows = [("trajectory_rmse", b.trajectory_rmse, a.trajectory_rmse)]
    rows += [
        (f"  {j}", b.trajectory_rmse_per_joint[j], a.trajectory_rmse_per_joint[j]) for j in b.trajectory_rmse_per_joint
    ]
    rows += [("residual_rms", b.residual_rms, a.residual_rms)]
    rows += [(f"  {j}", b.residual_rms_per_joint[j], a.residual_rms_per_joint[j]) for j in b.residual_rms_per_joint]
    for name, x, y in rows:
        ratio = x / y if y and np.isfinite(x) and np.isfinite(y) else float("nan")
        lines.append(f"  {name:<58}{_g(x, '{:.4g}'):>10}{_g(y, '{:.4g}'):>13}{_g(ratio, '{:.2f}x'):>8}")
    return lines


def write_json(res, path, overwrite: bool = False) -> Path:
    """The pinned JSON (``system``, ``effects``, ``error_before``, ``error_after``, ...)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; refusing to overwrite (pass --overwrite / overwrite=True)")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(res.to_json(), indent=2) + "\n")
    return path


# ----------------------------------------------------------------------------- the report folder

REPORT_FILES = ("residual_over_time.png", "prediction_windows.png", "residual_vs_effect.png", "summary.txt")
_DPI = 110  # small files (< 300 KB each) that still read well on screen
_MAX_SEGMENTS = 3  # segments shown in residual_over_time.png
_N_WORST, _N_TYPICAL = 3, 2  # windows shown in prediction_windows.png


def write_figures(res, directory, overwrite: bool = False) -> list[Path]:
    """Write a stand-alone report of ``res`` into ``directory`` and return the written paths:

    * ``residual_over_time.png``: the integral residual per interval of the declared model
      (before) and of the model with the found effects (after), over time, on test-log segments
      when there are any (else held-out ones);
    * ``prediction_windows.png``: a few open-loop windows, measured positions vs both models;
    * ``residual_vs_effect.png``: the declared model's residual against the regressor of the
      strongest significant effect (or the top tested one);
    * ``summary.txt``: :meth:`~._result.DiagnosisResult.table`.

    Every target is checked before anything is written: no file is replaced unless ``overwrite``.
    """
    directory = Path(directory)
    targets = [directory / name for name in REPORT_FILES]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{existing}: exist; refusing to overwrite (pass --overwrite / overwrite=True)")
    directory.mkdir(parents=True, exist_ok=True)
    segs, kind = _shown_segments(res)
    _save(_plot_residual_over_time(res, _spread(segs, _MAX_SEGMENTS), kind), targets[0])
    _save(_plot_prediction_windows(res, segs, kind), targets[1])
    _save(_plot_residual_vs_effect(res), targets[2])
    targets[3].write_text(res.table() + "\n")
    return targets


def _spread(items, k: int) -> list:
    """At most ``k`` of ``items``, evenly spread (first and last included): deterministic."""
    idx = np.unique(np.linspace(0, len(items) - 1, min(k, len(items))).round().astype(int))
    return [items[i] for i in idx]


def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=_DPI)


def _figure(layout: Any = "tight", **kw):
    # a bare Figure (no pyplot): no global backend switch, no open-figure registry to leak into
    from matplotlib.figure import Figure  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    return Figure(layout=layout, **kw)


def _shown_segments(res):
    """Test-log segments when there are any (never fitted: what the user cares about), else the
    held-out ones (never fitted either, but they took part in choosing the effects)."""
    if res._test_segments:
        return list(res._test_segments), "test logs"
    return [s for s in res._segments if s.held_out], "held-out segments"


def _anchor(res):
    """The linearisation point of the regressors, as in ``diagnose``: nominal θ, fixed entries in."""
    theta = res.layout.nominal()
    for k, v in res.fixed.items():
        theta[res.layout.index(k)] = v
    return theta


def _stride(res, dt: float) -> int:
    return max(1, int(round(res.settings.search.interval / dt)))


def _problem(res, segments, dynamics):
    """The equation-error problem of ``segments`` rebuilt on copies (``res._segments`` keep the
    regressors ``diagnose`` left in them)."""
    copies = [dataclasses.replace(s) for s in segments]
    theta0, st = _anchor(res), res.settings
    _fit.build_regressors(
        copies,
        res.layout,
        theta0,
        _stride(res, segments[0].dt),
        st.reading.input_hold,
        st.search.block_seconds,
        dynamics,
        st.rests.exclude_rest,
        st.rests.stop_dwell,
        st.rests.held_stop,
    )
    return Problem(copies, _fit.input_direction(res.layout, theta0))


def residual_series(res, segments, which: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per segment, (t, r): interval centres (s) and the integral residual Z̄ − Ā per interval
    (N, n_joints; N·m·s or N·s) of the declared model (``which="before"``) or of the model with
    the found effects and input dynamics (``"after"``). Intervals where a joint is at rest (left
    out of the fit's equations) are NaN for that joint."""
    if which not in ("before", "after"):
        raise ValueError(f"which must be 'before' or 'after', got {which!r}")
    theta = res.theta_before if which == "before" else res.theta_after
    dyn = _fit.NO_INPUT_DYNAMICS if which == "before" else res.input_dynamics
    prob = _problem(res, segments, dyn)
    out = []
    for seg in prob.segments:
        r = seg.residual_jacobian(prob.c_input) @ theta
        r[seg.rest] = np.nan
        stride = _stride(res, seg.dt)
        t = seg.t[0] + (np.arange(r.shape[0]) + 0.5) * stride * seg.dt
        out.append((t, r))
    return out


def _rms(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def _joint_labels(res):
    """Per joint: name, position unit, residual unit (∫ torque dt or ∫ force dt per interval)."""
    spec = get_spec(res.system)
    return [
        (j, "rad" if a else "m", "N·m·s" if a else "N·s") for j, a in zip(spec.joint_names, spec.angular, strict=True)
    ]


def _after_label(res) -> str:
    found = [f"{e.name}:{e.joint}" for e in res.significant]
    return "after (+ " + ", ".join(found) + ")" if found else "after (= before: no effect added)"


def _plot_residual_over_time(res, segs, kind: str):
    joints = _joint_labels(res)
    before, after = residual_series(res, segs, "before"), residual_series(res, segs, "after")
    fig = _figure(figsize=(max(9.0, 5.2 * len(joints)), 2.6 * len(segs) + 0.8))
    axes = fig.subplots(len(segs), len(joints), squeeze=False)
    for i, seg in enumerate(segs):
        (t, rb), (_, ra) = before[i], after[i]
        for j, (name, _, runit) in enumerate(joints):
            ax = axes[i, j]
            rest = ~np.isfinite(rb[:, j])
            if rest.any():  # dry friction holds a joint at rest: its equation is left out
                ax.bar(
                    t[rest],
                    1,
                    width=res.settings.search.interval,
                    color="0.88",
                    transform=ax.get_xaxis_transform(),
                    label="at rest (left out of the fit)",
                )
            ax.axhline(0, color="0.6", lw=0.6)
            ax.plot(t, rb[:, j], "C3-", lw=1, label=f"before (declared), RMS {_rms(rb[:, j]):.3g}")
            ax.plot(t, ra[:, j], "C0-", lw=1, label=f"{_after_label(res)}, RMS {_rms(ra[:, j]):.3g}")
            _room_for_legend(ax, rb[:, j], ra[:, j])
            ax.legend(fontsize=7, loc="upper center", ncol=1, framealpha=0.9)
            ax.set_title(f"{kind[:-1]} {seg.name}: {name}", fontsize=9)
            ax.set_ylabel(f"Z̄ − Ā on {name} [{runit}]", fontsize=8)
            ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
            ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time in the log [s]", fontsize=8)
    fig.suptitle(
        f"{res.system}, {kind}: integral residual Z̄ − Ā per {res.settings.search.interval:g} s interval\n"
        f"(the impulse the model misses; 0 = perfect), declared model before vs after",
        fontsize=10,
    )
    return fig


def _room_for_legend(ax, *series) -> None:
    """Leave the top ~third of the axes empty so the legend covers no data."""
    v = np.concatenate([np.ravel(x) for x in series])
    v = v[np.isfinite(v)]
    if v.size:
        lo, hi = float(v.min()), float(v.max())
        span = max(hi - lo, 1e-12)
        ax.set_ylim(lo - 0.05 * span, hi + 0.6 * span)


def _window_predictions(res, segs):
    """Every non-overlapping open-loop window of ``segs`` (as ``diagnose`` scores them): the
    measured positions (W, L + 1, n) from the start state on, both models' predictions the same
    shape, the time axis (W, L + 1) and each window's segment name."""
    L = int(round(res.settings.output_error.window / segs[0].dt))
    substeps = system_definition(res.system).diagnosis_substeps
    preds = []
    for theta, dyn in ((res.theta_before, _fit.NO_INPUT_DYNAMICS), (res.theta_after, res.input_dynamics)):
        win = _windows.make_windows(segs, L, dyn)
        if win is None:
            return None
        p = _windows.predict_windows(res.layout, theta, win, substeps)
        preds.append(np.concatenate([win.x0[:, None, : p.shape[2]], p], axis=1))  # from the start state
    # start states and measured positions do not depend on the input dynamics: either win does
    meas = np.concatenate([win.x0[:, None, : p.shape[2]], win.q], axis=1)
    # make_windows starts windows at 0, L, 2L, ... of each segment, in segment order
    first = {i: int(np.argmax(win.segment == i)) for i in np.unique(win.segment)}
    starts = [(w - first[i]) * L for w, i in enumerate(win.segment)]
    t = np.stack([segs[i].t[s : s + L + 1] for i, s in zip(win.segment, starts, strict=True)])
    return meas, preds[0], preds[1], t, [segs[i].name for i in win.segment]


def _pick_windows(err: np.ndarray):
    """The ``_N_WORST`` windows with the largest declared-model error, then ``_N_TYPICAL`` typical
    ones (closest to the median error): where the model fails and what it usually does."""
    order = np.argsort(-np.where(np.isfinite(err), err, np.inf), kind="stable")
    worst = list(order[:_N_WORST])
    rest = [i for i in np.argsort(np.abs(err - np.nanmedian(err)), kind="stable") if i not in worst]
    picked = worst + rest[:_N_TYPICAL]
    tags = ["largest error"] * len(worst) + ["typical"] * (len(picked) - len(worst))
    return picked, tags


def _ylim(ax, measured, *preds) -> None:
    """Keep the measurement readable when a prediction runs away: at most 3 measured spans
    beyond the measured range (the runaway is then visibly cut at the frame)."""
    lo, hi = float(np.min(measured)), float(np.max(measured))
    span = max(hi - lo, 1e-3)
    vals = np.concatenate([np.ravel(p) for p in preds] + [np.ravel(measured)])
    vals = vals[np.isfinite(vals)]
    ax.set_ylim(max(vals.min(), lo - 3 * span) - 0.05 * span, min(vals.max(), hi + 3 * span) + 0.05 * span)


def _plot_prediction_windows(res, segs, kind: str):
    joints = _joint_labels(res)
    got = _window_predictions(res, segs)
    # constrained layout makes room for the figure-level legend below the panels
    fig = _figure("constrained", figsize=(2.9 * (_N_WORST + _N_TYPICAL), 2.4 * len(joints) + 1.0))
    if got is None:
        fig.text(0.5, 0.5, f"no complete {res.settings.output_error.window} s window in the {kind}", ha="center")
        return fig
    meas, pb, pa, t, names = got
    # one position RMSE per window over both joints (as trajectory_rmse), rad or m
    err, err_after = (np.sqrt(np.mean((p - meas) ** 2, axis=(1, 2))) for p in (pb, pa))
    picked, tags = _pick_windows(err)
    axes = fig.subplots(len(joints), len(picked), squeeze=False)
    for c, (w, tag) in enumerate(zip(picked, tags, strict=True)):
        for j, (name, qunit, _) in enumerate(joints):
            ax = axes[j, c]
            ax.plot(t[w], meas[w, :, j], "k-", lw=1.6, label="measured")
            ax.plot(t[w], pb[w, :, j], "C3-", lw=1, label="before (declared)")
            ax.plot(t[w], pa[w, :, j], "C0--", lw=1, label=_after_label(res))
            _ylim(ax, meas[w, :, j], pb[w, :, j], pa[w, :, j])
            ax.tick_params(labelsize=7)
            if c == 0:
                ax.set_ylabel(f"{name} [{qunit}]", fontsize=8)
            if j == 0:
                ax.set_title(
                    f"{tag}: {kind[:-1]} {names[w]}\nposition RMSE {err[w]:.3g} before, {err_after[w]:.3g} after",
                    fontsize=8,
                )
            if j == len(joints) - 1:
                ax.set_xlabel("time in the log [s]", fontsize=8)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=3, fontsize=8)
    fig.suptitle(
        f"{res.system}: open-loop predictions over {res.settings.output_error.window:g} s from the measured state, "
        f"{kind} ({tags.count('largest error')} windows with the largest declared-model error, "
        f"{tags.count('typical')} typical)",
        fontsize=10,
    )
    return fig


def _shown_effect(res):
    """The strongest significant effect, else the top tested one (``res.effects`` is ordered by
    evidence, significant first), else None."""
    return next(
        (e for e in res.effects if e.significant), next((e for e in res.effects if e.improvement is not None), None)
    )


def _effect_regressor(res, eff, prob):
    """(x (N, n), description) with ∂(Z̄ − Ā)/∂coefficient per interval, or (None, why not).

    A missing effect leaves r ≈ −coefficient × x in the declared model's residual. The input
    dynamics have no column in θ; a delay or a lag both first show as −d·u̇ (the delay column)."""
    if getattr(EFFECT_KINDS.get(eff.name), "input_dynamics", None):  # an unknown name has a column or none
        x = prob.delay_column(res.theta_before)[:, :, 0]
        return x, f"−(change of u over the interval) × gain, the signature of {eff.name}"
    key = f"{eff.name}:{eff.joint}"
    try:
        col = res.layout.index(key)
    except ValueError:
        return None, f"{key} has no column in the lumped model: no regressor to plot against"
    return prob.R[:, :, col], f"regressor of {key}: ∂(Z̄ − Ā)/∂coefficient per interval"


def _plot_residual_vs_effect(res):
    fig = _figure(figsize=(6.4, 4.8))
    ax = fig.subplots()
    eff = _shown_effect(res)
    segs = [s for s in res._segments if s.held_out] + list(res._test_segments)
    prob = _problem(res, segs, _fit.NO_INPUT_DYNAMICS)
    x, xlabel = _effect_regressor(res, eff, prob) if eff is not None else (None, "no effect could be tested")
    if x is None or not np.any(x):
        ax.axis("off")
        ax.set_title(f"{res.system}: declared model's residual vs the strongest effect: not plotted", fontsize=9)
        ax.text(
            0.5,
            0.5,
            xlabel if x is None else f"the regressor of {eff.name}:{eff.joint} is zero on these data",
            ha="center",
            va="center",
            wrap=True,
            fontsize=9,
        )
        return fig
    names = [n for n, _, _ in _joint_labels(res)]
    # the effect's joint; an input effect acts where its regressor is largest (the rotor)
    j = names.index(eff.joint) if eff.joint in names else int(np.argmax(np.linalg.norm(x, axis=0)))
    runit = _joint_labels(res)[j][2]
    keep = prob.keep[:, j] > 0  # intervals at rest are not in the fit's equations
    xs, r = x[keep, j], (prob.R @ res.theta_before)[keep, j]
    ax.plot(xs, r, ".", ms=3, alpha=0.5, label=f"held-out and test intervals ({keep.sum()})")
    if eff.coefficient is not None and np.isfinite(eff.coefficient):
        line = np.linspace(xs.min(), xs.max(), 2)
        ax.plot(
            line,
            -eff.coefficient * line,
            "C3-",
            label=f"− coefficient × regressor, coefficient {eff.coefficient:.3g} {eff.unit}",
        )
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_xlabel(f"{xlabel} [{runit} per {eff.unit}]", fontsize=8)
    ax.set_ylabel(f"declared model's residual Z̄ − Ā on {names[j]} [{runit}]", fontsize=8)
    verdict = "significant" if eff.significant else "strongest tested, not significant"
    ax.set_title(
        f"{res.system}: residual per {res.settings.search.interval:g} s interval vs {eff.name}:{eff.joint} ({verdict})",
        fontsize=9,
    )
    ax.legend(fontsize=7)
    return fig
