"""Reporting a :class:`~._diagnose.DiagnosisResult`: terminal table, JSON file, figures.

Nothing here overwrites an existing file unless ``overwrite=True``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["format_table", "write_json", "write_figures"]


def _g(x, fmt="{:.3g}"):
    return "-" if x is None or (isinstance(x, float) and not np.isfinite(x)) else fmt.format(x)


def format_table(res) -> str:
    """Human-readable summary: effects by evidence, errors before/after, fitted parameters."""
    lines = [f"diagnosis of a {res.system} model"]
    lines.append("")
    lines.append(f"{'effect':<18}{'joint':<7}{'coefficient':>13}  {'unit':<15}{'held-out gain':>14}{'z':>7}  verdict")
    for e in res.effects:
        verdict = "SIGNIFICANT" if e.significant else e.status
        gain = None if e.improvement is None else 100 * e.improvement
        lines.append(
            f"{e.name:<18}{e.joint:<7}{_g(e.coefficient):>13}  {e.unit:<15}"
            f"{_g(gain, '{:.1f} %'):>14}{_g(e.z_score, '{:.1f}'):>7}  {verdict}"
        )
    if not res.significant:
        lines.append("-> none: no effect is significant on held-out data")
    lines.append("")
    b, a = res.error_before, res.error_after
    lines.append(f"held-out errors ({b.n_windows} open-loop windows of {b.window_seconds} s)   before        after   ratio")
    rows = [("trajectory_rmse", b.trajectory_rmse, a.trajectory_rmse)]
    rows += [(f"  {j}", b.trajectory_rmse_per_joint[j], a.trajectory_rmse_per_joint[j]) for j in b.trajectory_rmse_per_joint]
    rows += [("residual_rms", b.residual_rms, a.residual_rms)]
    rows += [(f"  {j}", b.residual_rms_per_joint[j], a.residual_rms_per_joint[j]) for j in b.residual_rms_per_joint]
    for name, x, y in rows:
        ratio = x / y if y and np.isfinite(x) and np.isfinite(y) else float("nan")
        lines.append(f"  {name:<58}{_g(x, '{:.4g}'):>10}{_g(y, '{:.4g}'):>13}{_g(ratio, '{:.2f}x'):>8}")
    lines.append("")
    lines.append("fitted parameters (before -> after)" + (f"; fixed: {res.fixed}" if res.fixed else ""))
    for k in res.parameters_before:
        lines.append(f"  {k:<10}{res.parameters_before[k]:>13.5g} -> {res.parameters_after[k]:<13.5g}{res.parameter_units[k]}")
    if res.delay_after:
        lines.append(f"  {'delay':<10}{0.0:>13.5g} -> {res.delay_after:<13.5g}s")
    for n in res.notes:
        lines.append(f"note: {n}")
    return "\n".join(lines)


def write_json(res, path, overwrite: bool = False) -> Path:
    """The pinned JSON (``system``, ``effects``, ``error_before``, ``error_after``, ...)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; refusing to overwrite (pass --overwrite / overwrite=True)")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(res.to_json(), indent=2) + "\n")
    return path


def write_figures(res, directory, overwrite: bool = False) -> list[Path]:
    """``residual_vs_effect.png`` (held-out residual of the declared model against the regressor
    of the strongest effect) and ``heldout_predictions.png`` (open-loop windows before/after)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from . import _fit
    from ._diagnose import _Problem

    directory = Path(directory)
    targets = [directory / "residual_vs_effect.png", directory / "heldout_predictions.png"]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{existing}: exist; refusing to overwrite (pass --overwrite / overwrite=True)")
    directory.mkdir(parents=True, exist_ok=True)
    spec_joints = list(res.error_before.trajectory_rmse_per_joint)
    held = [s for s in res._segments if s.held_out]
    c_input = _fit.input_direction(res.layout, _anchor(res))
    prob = _Problem(held, c_input)
    r_before = prob.R @ res.theta_before

    # 1. residual vs the strongest effect's regressor (or the strongest tested one if none)
    eff = next((e for e in res.effects if e.improvement is not None), None)
    fig, ax = plt.subplots(figsize=(6, 4.5))
    if eff is not None:
        if eff.name == "input_delay":
            x, j = prob.delay_column(res.theta_before)[:, 0, 0], 0
        else:
            col = res.layout.index(f"{eff.name}:{eff.joint}")
            j = spec_joints.index(eff.joint)
            x = prob.R[:, j, col]
        ax.plot(x, r_before[:, j], ".", ms=3, alpha=0.5, label="held-out intervals")
        if eff.coefficient is not None:
            xs = np.linspace(x.min(), x.max(), 2)
            ax.plot(xs, -eff.coefficient * xs, "r-", label=f"−coefficient × regressor ({eff.coefficient:.3g} {eff.unit})")
        ax.set_xlabel(f"regressor of {eff.name}:{eff.joint} (∫ unit force dt per interval)")
        ax.set_ylabel(f"residual Z̄ − Ā on {spec_joints[j]} (declared model)")
        verdict = "significant" if eff.significant else "not significant"
        ax.set_title(f"{res.system}: residual vs {eff.name}:{eff.joint} ({verdict})")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(targets[0], dpi=120)
    plt.close(fig)

    # 2. held-out open-loop predictions before/after (first held-out segment, consecutive windows)
    seg = held[0]
    L = int(round(res.settings.window / seg.dt))
    smoothing = 0.02 if res.system == "furuta" else 0.01
    substeps = 1 if res.system == "furuta" else 2
    win_b = _fit.make_windows([seg], L, 0.0)
    win_a = _fit.make_windows([seg], L, res.delay_after)
    pb = _fit.predict_windows(res.layout, res.theta_before, win_b, smoothing, substeps)
    pa = _fit.predict_windows(res.layout, res.theta_after, win_a, smoothing, substeps)
    n = len(spec_joints)
    fig, axes = plt.subplots(n, 1, figsize=(8, 2.6 * n), sharex=True, squeeze=False)
    for j in range(n):
        ax = axes[j, 0]
        ax.plot(seg.t, seg.q[:, j], "k-", lw=1, label="measured")
        for w in range(pb.shape[0]):
            t = seg.t[w * L + 1 : w * L + L + 1]
            ax.plot(t, pb[w, :, j], "C3-", lw=1, label="before" if w == 0 else None)
            ax.plot(t, pa[w, :, j], "C0--", lw=1, label="after" if w == 0 else None)
        ax.set_ylabel(spec_joints[j])
        if j == 0:
            ax.legend(fontsize=8, ncol=3)
            ax.set_title(f"held-out open-loop predictions ({res.settings.window} s windows), segment {seg.name}", fontsize=9)
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(targets[1], dpi=120)
    plt.close(fig)
    return targets


def _anchor(res):
    theta = res.layout.nominal()
    for k, v in res.fixed.items():
        theta[res.layout.index(k)] = v
    return theta
