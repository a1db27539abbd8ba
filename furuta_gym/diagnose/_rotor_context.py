"""What Method step 11's two fits share (issue 64): the joint, the logs in recorded order, the
windows and their neutrals (:class:`Context`), the joint's cable and friction candidates, and the
cable with memory in the equation error and in the held-out errors."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..effects import EFFECT_KINDS, EffectKind
from ..systems import get_spec
from . import _fit, _windows
from ._drift import flicker_tolerance
from ._library import Candidate
from ._problem import free_columns
from ._rotor_neutral import _window_neutrals, carried_starts, neutral_paths, predict


def memory_law_for(kind: EffectKind) -> EffectKind | None:
    """The registered law with memory that generalises ``kind`` (a moving-rest cable for a spring)."""
    return next((k for k in EFFECT_KINDS.values() if k.generalises == kind.name), None)


@dataclasses.dataclass
class Context:
    """What the laws' fits share: the fitter (``_fitter._Fitter``), the joint, the logs in
    recorded order, the input dynamics and the windows (output-error fit, validation)."""

    fx: Any  # the diagnosis's _Fitter (its module imports this one)
    joint: str
    trajs: list
    dyn: Any
    others: list[Candidate]  # the accepted effects the laws leave as they are
    start_iterations: int = 1
    driven: bool = False  # the log has input (the rotor rests against it, not against the cable alone)

    def __post_init__(self):
        fx = self.fx
        self.layout, self.j = fx.layout, get_spec(fx.layout.system).joint_names.index(self.joint)
        self.win_fit, self.win_val = fx.fit_windows(self.dyn, fx.oe_idx), fx.fit_windows(self.dyn, fx.val_idx)
        moving = _moving(self.win_fit, self.j, flicker_tolerance(1, fx.resolution.get(self.joint, 0.0)))
        self.win_moving = self.win_fit.take(moving)
        self.moving_idx = fx.oe_idx[moving]
        self._neutrals: dict[tuple, np.ndarray] = {}

    def neutrals(self, cable: tuple, idx) -> np.ndarray:
        """The starting neutrals of the fit-set windows ``idx`` under ``cable`` (k, play, ρ per
        trajectory; zeros without a cable)."""
        if not cable[0]:
            return np.zeros(len(idx))
        key = tuple(float(x) for x in cable[1:])
        if key not in self._neutrals:
            paths = neutral_paths(self.trajs, self.j, key[0], key[1:])
            self._neutrals[key] = _window_neutrals(self.fx.fit_segs, self.fx.L, paths)
            if len(self._neutrals) > 64:  # a fit visits many; keep the recent ones
                self._neutrals.pop(next(iter(self._neutrals)))
        return self._neutrals[key][idx]

    def windows(self, which: str) -> _windows.Windows:
        """The output-error windows (``"fit"``), those where the joint moves (``"moving"``) or the
        validation windows (``"val"``)."""
        return self._sets()[which][0]

    def _sets(self) -> dict:
        return {
            "fit": (self.win_fit, self.fx.oe_idx),
            "moving": (self.win_moving, self.moving_idx),
            "val": (self.win_val, self.fx.val_idx),
        }

    def predictions(self, thetas, cables, which: str, start_iterations: int | None = None) -> np.ndarray:
        win, idx = self._sets()[which]
        r0s = [self.neutrals(c, idx) for c in cables]
        start = self.start_iterations if start_iterations is None else start_iterations
        return predict(self.layout, thetas, [c[:2] for c in cables], win, r0s, self.fx.substeps, self.j, start)

    def cable(self, stiffness: float, play: float) -> tuple:
        """A cable of this stiffness and play, each trajectory's first neutral the history's."""
        return (stiffness, play, *carried_starts(self.trajs, self.j, play))

    def candidate(self, kind_test) -> Candidate | None:
        """The joint's library candidate of the kind ``kind_test`` accepts."""
        return next((c for c in self.layout.candidates if c.joint == self.joint and kind_test(c.kind)), None)


def _moving(win, j: int, tolerance: float) -> np.ndarray:
    """Which of ``win`` see joint ``j`` leave the ``tolerance`` of its start (the rest, read through a
    flicker, stays); all of them where none does."""
    out = np.any(np.abs(win.q[:, :, j] - win.x0[:, None, j]) > tolerance, axis=1)
    return out if out.any() else np.ones_like(out)


def _with_first(ctx: Context, stiffness: float, play: float, rho: float) -> tuple:
    """The cable with the log's first neutral at ρ in the play of its first sample (no history
    before the log says where), the later trajectories' the history's."""
    return (stiffness, play, rho, *carried_starts(ctx.trajs, ctx.j, play, rho)[1:])


def _memory_kind(ctx: Context) -> EffectKind:
    spring = ctx.candidate(lambda k: k.absorbs_constant_force)
    kind = memory_law_for(spring.kind) if spring else None
    assert kind is not None  # the stage runs only on joints that have one
    return kind


def _joint_effects(ctx: Context) -> dict[str, Candidate]:
    """The joint's candidates of the fixed cable, its rest (a constant force), the sliding friction
    and the breakaway above it."""
    found = {
        "cable": ctx.candidate(lambda k: k.absorbs_constant_force),
        "rest": ctx.candidate(lambda k: k.is_constant_force),
        "sliding": ctx.candidate(lambda k: k.is_dry_friction and not k.breakaway_above),
        "breakaway": ctx.candidate(lambda k: k.is_dry_friction and bool(k.breakaway_above)),
    }
    return {k: c for k, c in found.items() if c is not None}


def _cleared(ctx: Context, theta) -> np.ndarray:
    out = np.array(theta, dtype=float)
    for c in _joint_effects(ctx).values():
        out[ctx.layout.index(c.key)] = 0.0
    return out


def _typical_spring(ctx: Context) -> float:
    spring = _joint_effects(ctx)["cable"]
    return float(ctx.layout.typical_scale()[ctx.layout.index(spring.key)])


def window_errors(ctx: Context, theta, cable, segs) -> tuple[np.ndarray, float]:
    """Per-joint and combined RMS position error of the open-loop windows of ``segs`` (cut from
    ``ctx.trajs``) under θ and a cable with memory, each window from the neutral its history
    implies; measured start velocities, as the diagnosis's own errors are."""
    win = _windows.make_windows(segs, ctx.fx.L, ctx.dyn)
    assert win is not None  # the segments were cut to hold windows of this length
    r0 = _window_neutrals(segs, ctx.fx.L, neutral_paths(ctx.trajs, ctx.j, cable[1], _starts(cable)))
    err = predict(ctx.layout, [theta], [cable[:2]], win, [r0], ctx.fx.substeps, ctx.j, 0)[0] - win.q
    if not np.all(np.isfinite(err)):
        return np.full(err.shape[-1], np.inf), float("inf")
    return np.sqrt(np.mean(err**2, axis=(0, 1))), float(np.sqrt(np.mean(err**2)))


def _starts(cable: tuple):
    return cable[2:] if len(cable) > 2 else None


def cable_column(ctx: Context, prob, play: float, starts=None) -> np.ndarray:
    """(N,) the equation-error regressor of the cable's stiffness on the joint (:func:`memory_column`)."""
    return memory_column(ctx.trajs, ctx.j, ctx.fx.stride, prob, play, starts)


def memory_column(trajs, j: int, stride: int, prob, play: float, starts=None) -> np.ndarray:
    """(N,) the equation-error regressor of a cable with memory's stiffness on joint ``j``:
    −∫(q_j − r) over each interval of ``prob`` (segments cut from ``trajs``, ``stride`` samples
    per interval; trapezoid, as the library's forces), r the neutral the play operator gives over
    the log's positions, left out where the joint rests as the library's equations are."""
    paths = neutral_paths(trajs, j, play, starts)
    column = []
    for s in prob.segments:
        t, r = paths[s.name.rsplit("[", 1)[0]]
        offset = int(np.searchsorted(t, s.t[0] - 1e-9 * s.dt))
        stretch = s.q[:, j] - r[offset : offset + s.q.shape[0]]
        column.append(_fit._group(0.5 * s.dt * (stretch[:-1] + stretch[1:]), stride)[: s.A.shape[0]])
    return -np.concatenate(column) * prob.keep[:, j]


def residual(ctx: Context, theta, cable, prob) -> np.ndarray:
    """(N, n) equation-error residual Z̄ − Ā of ``prob`` under θ plus the cable (Z̄ − Ā gains the
    cable's force integrated over each interval)."""
    out = prob.R @ theta
    out[:, ctx.j] += cable[0] * cable_column(ctx, prob, cable[1], _starts(cable))
    return out


def ee_with_cable(ctx: Context, effects: list[Candidate], play: float):
    """(θ, stiffness): the equation-error fit of the declared model, ``effects`` and a cable of
    this play (its column from the log's neutral path), as the library's fits are made."""
    fx, layout = ctx.fx, ctx.layout
    prob = fx.fit_prob
    extra = np.zeros(prob.R.shape[:2] + (1,))
    extra[:, ctx.j, 0] = cable_column(ctx, prob, play)
    free = free_columns(layout, ctx.others + effects, fx.fixed_idx)
    theta, coef = _fit.ee_fit(prob.R, prob.D, free, fx.theta_fixed, fx.weights, layout.typical_scale(), extra)
    return theta, float(coef[0])
