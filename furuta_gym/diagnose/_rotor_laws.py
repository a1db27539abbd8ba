"""Issue 64's two laws of a joint on a cable, fitted by prediction and told apart (Method step 11).

A cable whose rest moves (a law with memory, e.g. ``hysteretic_spring``: the play operator) and
a fixed cable held by a breakaway far above the sliding friction both leave a rotor resting off
its cable's neutral; a fixed spring with modest dry friction does neither, so it predicts worse
although its equation error is strong (the equation error leaves rests out). Where a joint's
memoryless spring is vetoed or inconsistent, or its rests name a law (:func:`rest_drift`), each
law is fitted by output error on the output-error windows and judged on the fit-set validation
windows against the model as diagnosed, by the trace's rule:

* **large breakaway**: the fixed spring (its rest as a constant force), Coulomb friction and a
  stiction fitted free, from the breakaway the rests held (:mod:`._rests`);
* **moving rest**: the law with memory (its stiffness and second parameter, the play, fitted) and
  the joint's Coulomb friction. Its neutral is simulated through each window from the state the
  history implies: the play operator run over the log's measured positions (in recorded order,
  across trajectories: a hand that carried the joint between them dragged it; the log's first
  neutral, which no history shows, fitted within the play of its first sample) gives each
  window's starting neutral, and inside the window the neutral is dragged by the predicted
  motion (:class:`furuta_gym.effects.WithNeutral`, advanced after each step as the MuJoCo plant
  advances it). The declared model's parameters stay as diagnosed (or at their nominal values,
  when those predict the law's start better): the windows where the joint moves are few.

The law that passes and predicts better than the other (t ≥ the trace's threshold), or the one
the rests name when prediction cannot tell them apart, is the one the data support; with neither
distinct, both are reported and the better predictor is kept, "cannot be told apart".
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares

from ..effects import EFFECT_KINDS, EffectKind, WithNeutral, dragged_neutral, play_operator
from ..lagrangian import forward_dynamics_with_dry_friction
from ..measured import estimate_velocities
from ..simulate import rk4_zoh_step
from ..systems import get_spec
from . import _fit, _windows
from ._drift import REST_LAWS, RestDrift, _runs_within as _drift_runs, rest_drift
from ._library import Candidate, is_physical, non_physical
from ._problem import free_columns
from ._rests import _holding
from ._trace import Evidence

__all__ = ["RotorLaw", "LawFit", "LAWS", "memory_law_for", "neutral_paths"]

#: the two laws: a moving rest and a fixed cable held by a large breakaway (rest_drift's words)
LAWS = (REST_LAWS[0], REST_LAWS[1])
_PLAY_GRID = (0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4, 0.6, 0.8, 1.2, 1.6)  # the play's starts (rad or m)
_FIRST_GRID = (-1.0, 0.0, 1.0)  # starts of ρ of the log's first neutral
_BREAKAWAY_GRID = (1.0, 4.0, 9.0)  # starts of ΔF in Coulomb levels (a breakaway up to 10×)


def memory_law_for(kind: EffectKind) -> EffectKind | None:
    """The registered law with memory that generalises ``kind`` (a moving-rest cable for a spring)."""
    return next((k for k in EFFECT_KINDS.values() if k.generalises == kind.name), None)


@dataclasses.dataclass
class LawFit:
    """One law fitted on a joint: θ (the library's memoryless part), the cable with memory
    (stiffness, second parameter; (0, 0): none), its predictions of the validation windows and the
    evidence against the model as diagnosed."""

    law: str
    theta: np.ndarray
    cable: tuple
    effects: list[Candidate]
    predictions: np.ndarray
    evidence: Evidence
    physical: bool


@dataclasses.dataclass
class RotorLaw:
    """What a joint's rests and the two laws' fits say (``verdict``: one of :data:`LAWS`,
    ``"cannot be told apart"`` or ``"neither"``), and which fit, if any, the diagnosis kept."""

    joint: str
    verdict: str
    reason: str
    rests: RestDrift
    fits: dict[str, LawFit]
    kept: str | None
    head_to_head: Evidence | None = None

    def to_json(self, layout) -> dict:
        def fit(f: LawFit) -> dict:
            coefs = {c.key: float(f.theta[layout.index(c.key)]) for c in f.effects}
            return dict(
                coefficients=coefs,
                cable_stiffness=f.cable[0] if f.cable[0] else None,
                play=f.cable[1] if f.cable[0] else None,
                validation_gain=float(f.evidence.improvement),
                z_score=float(f.evidence.z),
                physical=bool(f.physical),
            )

        return dict(
            joint=self.joint,
            verdict=self.verdict,
            reason=self.reason,
            kept=self.kept,
            rests=self.rests.to_json(),
            fits={law: fit(f) for law, f in self.fits.items()},
            head_to_head_z=None if self.head_to_head is None else float(self.head_to_head.z),
        )


# ----------------------------------------------------------------------------- neutral paths


def neutral_paths(trajs, j: int, play: float, starts=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{trajectory name: (t, neutral after each sample)}: the play operator run over joint ``j``
    of each of ``trajs``, from its first neutral q_j(0) + play·ρ (``starts``: ρ ∈ [−1, 1] per
    trajectory; None: the history's, :func:`carried_starts`)."""
    starts = carried_starts(trajs, j, play) if starts is None else starts
    out = {}
    for tr, rho in zip(trajs, starts, strict=True):
        q = np.asarray(tr.q[:, j], float)
        out[tr.name] = (np.asarray(tr.t), play_operator(q, play, q[0] + play * float(rho)))
    return out


def carried_starts(trajs, j: int, play: float, first: float = 0.0) -> np.ndarray:
    """ρ of each trajectory's first neutral as the recorded history implies it: the first
    trajectory's at ρ ``first`` (0: a log starts with the joint resting on its neutral), each
    next one's where the last left it, dragged by a hand that carried the joint between them."""
    out, r = [first], None
    for tr, nxt in zip(trajs[:-1], trajs[1:], strict=True):
        q = np.asarray(tr.q[:, j], float)
        r = play_operator(q, play, q[0] + play * out[-1])[-1]
        q1 = float(nxt.q[0, j])
        out.append((float(dragged_neutral(r, q1, play)) - q1) / play if play > 0 else 0.0)
    return np.asarray(out)


def _window_neutrals(segs, length: int, paths) -> np.ndarray:
    """Each window's starting neutral, in :func:`._windows.make_windows`' order."""
    out = []
    for s in segs:
        t, r = paths[s.name.rsplit("[", 1)[0]]
        offset = int(np.searchsorted(t, s.t[0] - 1e-9 * s.dt))
        out += [r[offset + start] for start in range(0, s.q.shape[0] - length, length)]
    return np.asarray(out)


# ----------------------------------------------------------------------------- the predictor


def _predictor(layout, dt: float, length: int, substeps: int, j: int, start_iterations: int):
    """Open-loop windows of the library model plus a cable with memory on joint ``j``: its
    neutral carried through the window, dragged after each step (θ, (k, w), x0, u, q, r0)."""
    n = get_spec(layout.system).n_dof
    h = dt / substeps

    def one(theta, cable, x, u, q_measured, r0):
        base = layout.model(theta, dry_friction=False)

        def positions(v, x, u):
            def step(carry, u_k):
                xk, r = carry
                model = WithNeutral(base, r, cable[0], cable[1], j)

                def field(y, uu):
                    limit = layout.dry_friction_limit(theta, y[n:])
                    qdd = forward_dynamics_with_dry_friction(model, limit, y[:n], y[n:], uu, h)
                    return jnp.concatenate([y[n:], qdd])

                x1 = rk4_zoh_step(model, xk, u_k, dt, substeps, field)
                return (x1, dragged_neutral(r, x1[j], cable[1], jnp)), x1[:n]

            return jax.lax.scan(step, (jnp.concatenate([x[:n], v]), r0), u)[1]

        return _windows._refined_positions(positions, x[n:], x, u, q_measured, start_iterations)

    key = ("cable", j, start_iterations)
    return _fit._compiled("predict_law", layout, dt, length, substeps, *key, build=lambda: jax.jit(jax.vmap(one)))


def predict(layout, thetas, cables, win: _windows.Windows, r0s, substeps: int, j: int, start_iterations: int):
    """(K, W, L, n) predictions under each (θ, cable, per-window neutrals) of ``thetas`` (K, P),
    ``cables`` (K, 2), ``r0s`` (K, W), batched as :func:`._windows.predict_windows_at` does."""
    fn = _predictor(layout, win.dt, win.length, substeps, j, start_iterations)
    thetas, cables, r0s = (np.asarray(a, dtype=float) for a in (thetas, cables, r0s))
    W = win.x0.shape[0]
    which, window = np.divmod(np.arange(len(thetas) * W), W)
    out = []
    for s in range(0, which.size, _windows._BATCH):
        real = np.arange(s, min(s + _windows._BATCH, which.size))
        pad = np.concatenate([real, np.full(_windows._BATCH - real.size, real[-1])])
        k, w = which[pad], window[pad]
        args = (thetas[k], cables[k], win.x0[w], win.us[w], win.q[w], r0s[k, w])
        out.append(np.asarray(fn(*map(jnp.asarray, args)))[: real.size])
    return np.concatenate(out).reshape(len(thetas), *win.q.shape)


def square_sums(pred: np.ndarray, measured: np.ndarray) -> np.ndarray:
    ss = np.sum((pred - measured) ** 2, axis=(1, 2))
    return np.where(np.isfinite(ss), ss, np.inf)


# ----------------------------------------------------------------------------- fitting a law


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

    def __post_init__(self):
        fx = self.fx
        self.layout, self.j = fx.layout, get_spec(fx.layout.system).joint_names.index(self.joint)
        self.win_fit, self.win_val = fx.fit_windows(self.dyn, fx.oe_idx), fx.fit_windows(self.dyn, fx.val_idx)
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

    def predictions(self, thetas, cables, which: str, start_iterations: int | None = None) -> np.ndarray:
        win, idx = (self.win_fit, self.fx.oe_idx) if which == "fit" else (self.win_val, self.fx.val_idx)
        r0s = [self.neutrals(c, idx) for c in cables]
        start = self.start_iterations if start_iterations is None else start_iterations
        return predict(self.layout, thetas, [c[:2] for c in cables], win, r0s, self.fx.substeps, self.j, start)

    def cable(self, stiffness: float, play: float) -> tuple:
        """A cable of this stiffness and play, each trajectory's first neutral the history's."""
        return (stiffness, play, *carried_starts(self.trajs, self.j, play))

    def candidate(self, kind_test) -> Candidate | None:
        """The joint's library candidate of the kind ``kind_test`` accepts."""
        return next((c for c in self.layout.candidates if c.joint == self.joint and kind_test(c.kind)), None)


def fit_law(
    ctx: Context, theta0, effects: list[Candidate], cable0: tuple | None, max_nfev: int, bounds: dict | None = None
):
    """Output-error fit of θ's free entries (the effects' and the declared model's) and, given
    ``cable0`` (:meth:`Context.cable`), the cable's stiffness, second parameter and each
    trajectory's first neutral (ρ ∈ [−1, 1]: where in the play of its first sample; the history
    before a log is unknown); ``bounds``: {effect key: (its least, its largest value)}; returns (θ, cable)."""
    layout = ctx.layout
    # the declared model's parameters stay at the start's: the windows where the joint moves, all
    # that tells the laws apart, are few (a release moves the rotor for a second or two)
    free = free_columns(layout, effects, set(range(len(layout.base))))
    scale = np.where(free, np.maximum(np.abs(theta0), layout.typical_scale() * 1e-2), 1.0)
    nf = int(free.sum())
    k_scale = max(cable0[0], 1e-6) if cable0 else 1.0

    def unpack(z):
        th = theta0.copy()
        th[free] = z[:nf] * scale[free]
        return th, (_with_first(ctx, z[nf] * k_scale, z[nf + 1], z[nf + 2]) if cable0 else (0.0, 0.0))

    def residuals(zs) -> np.ndarray:
        ths, cables = zip(*map(unpack, zs), strict=True)
        r = (ctx.predictions(ths, cables, "fit") - ctx.win_fit.q[None]).reshape(len(zs), -1)
        return np.where(np.isfinite(r), r, 1e3)

    z0 = theta0[free] / scale[free]
    # a base parameter and an effect that only one sign makes physical are not fitted past zero
    positive = [
        i < len(layout.base) or layout.candidates[i - len(layout.base)].kind.physically_positive
        for i in range(layout.size)
    ]
    lower = np.where(positive, 0.0, -np.inf)[free] / scale[free]
    upper = np.full(nf, np.inf)
    for key, (least, value) in (bounds or {}).items():
        i = int(np.flatnonzero(np.flatnonzero(free) == layout.index(key))[0])
        upper[i] = max(value, 1e-12) / scale[layout.index(key)]
        lower[i] = min(least, 0.99 * value) / scale[layout.index(key)]
    if cable0:
        lo, hi = EFFECT_KINDS[_memory_kind(ctx).name].second_bounds
        z0 = np.concatenate([z0, [1.0, cable0[1], cable0[2]]])
        lower = np.concatenate([lower, [0.0, lo, -1.0]])
        upper = np.concatenate([upper, [np.inf, hi, 1.0]])
    z0 = np.clip(z0, lower + 1e-9, upper - 1e-9)

    def jac(z):
        h = 1e-6 * np.maximum(1.0, np.abs(z))
        r = residuals([z] + [z + step for step in np.diag(h)])
        return (r[1:] - r[0]).T / h

    sol = least_squares(
        lambda z: residuals([z])[0],
        z0,
        jac=jac,  # pyright: ignore[reportArgumentType]
        method="trf",
        bounds=(lower, upper),
        max_nfev=max_nfev,
        x_scale="jac",
    )
    return unpack(sol.x)


def _with_first(ctx: Context, stiffness: float, play: float, rho: float) -> tuple:
    """The cable with the log's first neutral at ρ in the play of its first sample (no history
    before the log says where), the later trajectories' the history's."""
    return (stiffness, play, rho, *carried_starts(ctx.trajs, ctx.j, play, rho)[1:])


def _memory_kind(ctx: Context) -> EffectKind:
    spring = ctx.candidate(lambda k: k.absorbs_constant_force)
    kind = memory_law_for(spring.kind) if spring else None
    assert kind is not None  # the stage runs only on joints that have one
    return kind


def _evidence(pred_before: np.ndarray, pred_after: np.ndarray, measured: np.ndarray) -> Evidence:
    """How much better ``pred_after`` predicts the windows; a window counts by how much the
    predictions differ there (as a stiction's evidence does): a joint at rest in both says nothing."""
    before, after = square_sums(pred_before, measured), square_sums(pred_after, measured)
    if not np.all(np.isfinite(after)):
        return Evidence(-np.inf, -np.inf, int(after.size))
    change = np.sum((pred_after - pred_before) ** 2, axis=(1, 2))
    return Evidence.of_sums(before, after, np.where(np.isfinite(change), change, 0.0))


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


def holding_forces(ctx: Context, theta, cable: tuple | None = None) -> list[np.ndarray]:
    """Per trajectory, the force (N·m or N) friction would balance to hold the joint still at each
    sample under θ and a cable with memory (:meth:`Context.cable`; None: none): the model's
    inverse dynamics with the joint's velocity and acceleration zero, less the input, plus the
    cable's pull from its neutral (the play operator over the log)."""
    holding = _holding(ctx.layout, ctx.j)
    paths = neutral_paths(ctx.trajs, ctx.j, cable[1], _starts(cable)) if cable and cable[0] else None
    out = []
    for tr in ctx.trajs:
        qd = np.asarray(estimate_velocities(tr).qd)  # the other joints' motion pushes on it too
        qdd = np.gradient(qd, tr.dt, axis=0)
        args = [jnp.asarray(x) for x in (tr.q, qd, qdd, np.asarray(tr.u, float))]
        f = np.asarray(holding(jnp.asarray(theta), *args))
        if paths is not None:
            f = f + cable[0] * (np.asarray(tr.q[:, ctx.j]) - paths[tr.name][1])
        out.append(f)
    return out


def broke_away(
    ctx: Context, theta, cable=None, min_rest: float = 0.2, flicker: int = 1, first_rest: float = 0.01, span=0.05
) -> float | None:
    """The least force (N·m or N) that moved the joint off a rest, under θ (and ``cable``); the
    breakaway was at most that. A rest: a run of ``min_rest`` s within ``flicker`` counts that
    the joint left, or a trajectory's first run of ``first_rest`` s (a released joint starts at
    rest: a moving one passes a count sooner). Each rest's force is the largest the joint felt
    over the last ``span`` s before it left: the other joints' pull, from estimated
    accelerations, is read with noise, and a noisy least would put the bound below the breakaway
    (it is an upper bound: a larger reading only loosens it). None: no rest was left. Read from
    the logs, not the windows, whose trimmed starts leave out the releases themselves."""
    tolerance = flicker * ctx.fx.resolution.get(ctx.joint, 0.0) * 1.01
    out = []
    for tr, f in zip(ctx.trajs, holding_forces(ctx, theta, cable), strict=True):
        q = np.asarray(tr.q[:, ctx.j], float)
        out += [float(np.abs(f[a:b]).max()) for a, b in _left_rests(q, tr.dt, tolerance, min_rest, first_rest, span)]
    return min(out) if out else None


def _settled(ctx: Context, theta, theta0, bounds: dict):
    """``theta`` with its breakaway at most the geometric middle of the rests' bracket (the value
    least far, in ratio, from any the rests allow): the windows push it up, towards holding every
    stop (a predicted pendulum started from a velocity read through quantisation shakes a rotor
    that the real one kept still, and a larger breakaway keeps it still), so a fit above the
    middle says no more than that the rotor was held."""
    c = _joint_effects(ctx)
    s, i = ctx.layout.index(c["breakaway"].key), ctx.layout.index(c["sliding"].key)
    least, most = bounds.get(c["breakaway"].key, (0.0, np.inf))
    if not (np.isfinite(most) and least > 0):
        return theta
    out = np.array(theta, dtype=float)
    out[s] = min(out[s], np.sqrt((least + theta0[i]) * (most + theta0[i])) - theta0[i])
    return out


def held_still(ctx: Context, theta, cable=None, min_rest: float = 0.2, flicker: int = 1) -> float:
    """The largest force (N·m or N) a rest held, under θ (and ``cable``): over each run of
    ``min_rest`` s within ``flicker`` counts, the median of the force friction balanced (the
    other joints' pull, read with noise, averages out); 0 without a rest. The breakaway was at
    least that."""
    tolerance = flicker * ctx.fx.resolution.get(ctx.joint, 0.0) * 1.01
    out = [0.0]
    for tr, f in zip(ctx.trajs, holding_forces(ctx, theta, cable), strict=True):
        bounds = _drift_runs(np.asarray(tr.q[:, ctx.j], float), tolerance)
        runs = zip(bounds[:-1], bounds[1:], strict=True)
        out += [abs(float(np.median(f[a:b]))) for a, b in runs if b - a >= int(round(min_rest / tr.dt))]
    return max(out)


def _left_rests(q, dt: float, tolerance: float, min_rest: float, first_rest: float, span: float, moved: int = 4):
    """(start, end) of the last ``span`` s of each rest of ``q`` that the joint left (see
    :func:`broke_away`): moving on by ``moved`` tolerances within 2·``span`` s. A joint held by a
    soft friction (MuJoCo's, a real joint's) creeps a count under a load below its breakaway and
    rests again: that rest was not broken."""
    bounds = _drift_runs(q, tolerance)
    n = int(round(span / dt))
    out = []
    for k, (s, e) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        least = first_rest if k == 0 else min_rest
        if e - s >= int(round(least / dt)) and np.any(np.abs(q[e : e + 2 * n] - q[e - 1]) >= moved * tolerance):
            out.append((max(s, e - n), e))
    return out


def _start_breakaway(ctx: Context, theta, held: float):
    """The fixed cable's start: the equation-error spring and rest, the Coulomb level at least its
    typical size, on that fit's base or the nominal one, ΔF what the rests held above it, or 1,
    4 or 9 Coulomb levels; the one that predicts the output-error windows best (a fit from a
    small ΔF can stay in a minimum without it)."""
    c = _joint_effects(ctx)
    effects = [c[k] for k in ("cable", "rest", "sliding") if k in c]
    th = _physical_base(ctx, ctx.fx.fit_ee(ctx.others + effects)[0], theta)
    scale = ctx.layout.typical_scale()
    for key in ("cable", "sliding"):
        i = ctx.layout.index(c[key].key)
        th[i] = max(th[i], 2.0 * scale[i])
    coulomb, s = th[ctx.layout.index(c["sliding"].key)], ctx.layout.index(c["breakaway"].key)
    bounds = _breakaway_bound(ctx, th)
    least, most = bounds[c["breakaway"].key]
    deltas = [max(coulomb, held - coulomb)] + [m * coulomb for m in _BREAKAWAY_GRID]
    deltas += [np.sqrt(max(least, coulomb) * most)] if np.isfinite(most) and most > 0 else []
    starts = []
    for delta, rest in itertools.product(deltas, _rest_starts(ctx, th)):
        th[s] = float(np.clip(delta, least, most))
        if "rest" in c:
            th[ctx.layout.index(c["rest"].key)] = rest
        starts += _with_nominal_base(ctx, th)
    best = starts[_best_start(ctx, starts, [(0.0, 0.0)] * len(starts))]
    return best, effects + [c["breakaway"]], bounds


def _rest_starts(ctx: Context, theta) -> list[float]:
    """The fixed cable's rest (its constant force) to start from: the equation-error fit's, and
    the middle of the span of the log's rests (a neutral whose friction holds the rotor keeps
    every rest within ±F_s/k of it; the equation error, which leaves rests out, can put it far
    off)."""
    c = _joint_effects(ctx)
    if "rest" not in c:
        return [0.0]
    k, own = theta[ctx.layout.index(c["cable"].key)], theta[ctx.layout.index(c["rest"].key)]
    count = ctx.fx.resolution.get(ctx.joint, 2 * np.pi / 2048)
    rests = [r.position for r in rest_drift(ctx.trajs, ctx.layout.system, ctx.joint, flicker=1, count=count).rests]
    return [own] + ([k * 0.5 * (min(rests) + max(rests))] if rests else [])


def _physical_base(ctx: Context, theta_ee, theta):
    """``theta_ee`` (an equation-error fit with the cable's spring) if physical, else its effects on
    ``theta``'s base: a diagnosis without the cable may leave the rotor's inertia far off, and the
    output-error fits start where the cable is already in."""
    if is_physical(ctx.layout, theta_ee):
        return np.array(theta_ee, dtype=float)
    return np.where(np.arange(theta_ee.size) < len(ctx.layout.base), theta, theta_ee)


def _start_moving(ctx: Context, theta, stiffness: float):
    """The moving rest's start, the one of a grid that predicts the output-error windows best
    (the play and the log's first neutral make the fit's landscape rugged): each play of a grid,
    the log's first neutral at either end of its play or in its middle, and either the equation-
    error fit with the cable's column (its stiffness; ``theta``'s base and ``stiffness`` where
    that fit is not physical) or the nominal base with stiffnesses of 1, 2 and 4× the typical
    (a log without input leaves the rotor's equation without a scale: its equation error may put
    both the inertia and the stiffness far off). Its dry friction is Coulomb friction, at least its
    typical size: beside a rest that moves, a breakaway above it is not identified (fitted free,
    ΔF took any value up to holding every stop where it happened, or turned negative)."""
    c = _joint_effects(ctx)
    i = ctx.layout.index(c["sliding"].key)
    scale, typical = ctx.layout.typical_scale(), _typical_spring(ctx)
    starts, cables = [], []
    for w in _PLAY_GRID:
        th, k = ee_with_cable(ctx, [c["sliding"]], w)
        th = _physical_base(ctx, _cleared(ctx, th), theta)
        th[i] = max(th[i] if is_physical(ctx.layout, th) else 0.0, 2.0 * scale[i])
        nominal = _with_nominal_base(ctx, th)[1]
        for start, k_start in [(th, k if k > 0 else stiffness)] + [(nominal, m * typical) for m in (1.0, 2.0, 4.0)]:
            for rho in _FIRST_GRID:
                starts.append(start)
                cables.append(_with_first(ctx, k_start, w, rho))
    best = _best_start(ctx, starts, cables)
    return starts[best], [c["sliding"]], cables[best]


def _with_nominal_base(ctx: Context, theta) -> list[np.ndarray]:
    """``theta`` and ``theta`` on the declared model's nominal base (as the diagnosis's own
    output-error fits may start: an equation-error fit of a log whose law it lacks, or of one
    resting most of the time, can leave the inertias far off)."""
    nominal = np.array(theta, dtype=float)
    nb = len(ctx.layout.base)
    free = np.array([i not in ctx.fx.fixed_idx for i in range(nb)])
    nominal[:nb] = np.where(free, ctx.layout.nominal()[:nb], theta[:nb])
    return [np.array(theta, dtype=float), nominal]


def _best_start(ctx: Context, starts, cables) -> int:
    """Index of the start that predicts the output-error windows best."""
    pred = ctx.predictions(starts, cables, "fit")
    costs = np.sum((pred - ctx.win_fit.q[None]) ** 2, axis=(1, 2, 3))
    return int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))


def fit_laws(ctx: Context, theta, spring_k: float, held: float, max_nfev: int) -> dict[str, LawFit]:
    """Both laws fitted on the joint (module docstring) and judged against ``theta``."""
    base = ctx.predictions([theta], [(0.0, 0.0)], "val")[0]
    out = {}
    th0, effects, bounds = _start_breakaway(ctx, theta, held)
    fitted = fit_law(ctx, th0, effects, None, max_nfev, bounds)
    fits = {LAWS[1]: (effects, (_settled(ctx, fitted[0], th0, bounds), fitted[1]))}
    th0, effects, cable0 = _start_moving(ctx, th0, max(spring_k, 2.0 * _typical_spring(ctx)))
    fits[LAWS[0]] = (effects, fit_law(ctx, th0, effects, cable0, max_nfev))
    for law, (effects, (th, cable)) in fits.items():
        pred = ctx.predictions([th], [cable], "val")[0]
        physical = bool(is_physical(ctx.layout, th) and not non_physical(ctx.layout, th, effects))
        physical = physical and bool(cable[0] > 0 if law == LAWS[0] else True)
        ev = _evidence(base, pred, ctx.win_val.q)
        out[law] = LawFit(law, th, tuple(float(x) for x in cable), effects, pred, ev, physical)
    return out


def _breakaway_bound(ctx: Context, theta, cable=None) -> dict:
    """{the stiction's key: (its least, its largest ΔF)}: the joint's breakaway at least the
    largest force a rest held (:func:`held_still`) and at most the least force that moved it off
    a rest (:func:`broke_away`), both under the start's cable, less its Coulomb level; the windows
    alone say little between the two (a stiction that held every stop they show fits them as well
    as the right one)."""
    c = _joint_effects(ctx)
    most, coulomb = broke_away(ctx, theta, cable), theta[ctx.layout.index(c["sliding"].key)]
    least = held_still(ctx, theta, cable) - coulomb
    if most is None:
        return {c["breakaway"].key: (max(least, 0.0), np.inf)}
    return {c["breakaway"].key: (min(max(least, 0.0), most - coulomb), most - coulomb)}


def _typical_spring(ctx: Context) -> float:
    spring = _joint_effects(ctx)["cable"]
    return float(ctx.layout.typical_scale()[ctx.layout.index(spring.key)])


@dataclasses.dataclass(frozen=True)
class Rule:
    """The trace's thresholds (gain, t), the veto's t, and whether the rests count (a log without
    input: under feedback a controller holds the joint wherever it rests)."""

    min_improvement: float
    z_threshold: float
    veto_t: float
    rests_count: bool


def verdict(fits: dict[str, LawFit], rests: RestDrift, measured, rule: Rule):
    """(verdict, reason, the law kept or None, head-to-head evidence of the moving rest against
    the breakaway): the law that passes the trace's rule and predicts significantly better than
    the other; else the one the rests name, if it passes, or, passing the size test alone, does
    not predict significantly worse (as a stiction from rests is added); else "cannot be told
    apart" (the better predictor kept) or "neither"."""
    ok = {law: f for law, f in fits.items() if f.physical}
    passing = [law for law, f in ok.items() if f.evidence.passes(rule.min_improvement, rule.z_threshold)]
    said = ", ".join(
        f"{law}: validation gain {f.evidence.improvement:.1%}, t {f.evidence.z:.1f}" for law, f in fits.items()
    )
    named = rests.verdict if rule.rests_count and rests.verdict in LAWS else None
    rest_words = f"rests: {rests.verdict} ({rests.reason})" + ("" if rule.rests_count else ", not counted under input")
    h2h = _evidence(fits[LAWS[1]].predictions, fits[LAWS[0]].predictions, measured)
    if len(passing) == 2 and abs(h2h.z) >= rule.z_threshold:
        law = LAWS[0] if h2h.z > 0 else LAWS[1]
        return (
            law,
            f"both predict better, the {law} law significantly (t {abs(h2h.z):.1f}; {said}); {rest_words}",
            law,
            h2h,
        )
    if len(passing) == 1 and named in (None, passing[0]):
        return passing[0], f"only the {passing[0]} law predicts better ({said}); {rest_words}", passing[0], h2h
    if named in ok and ok[named].evidence.improvement >= rule.min_improvement and ok[named].evidence.z > -rule.veto_t:
        why = (
            "prediction cannot tell the laws apart"
            if len(passing) == 2
            else "named by the rests, its prediction agrees"
        )
        return named, f"{why} (t {h2h.z:.1f} between them; {said}); the {rest_words}", named, h2h
    if len(passing) == 2 or (len(passing) == 1 and named):
        better = LAWS[0] if h2h.improvement > 0 else LAWS[1]
        return "cannot be told apart", f"t {h2h.z:.1f} between them ({said}); {rest_words}", better, h2h
    return "neither", f"neither law predicts the validation windows better ({said}); {rest_words}", None, None


# ----------------------------------------------------------------------------- errors with the cable


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
    """(N,) the equation-error regressor of the cable's stiffness on the joint: −∫(q_j − r) over
    each interval of ``prob`` (segments cut from ``ctx.trajs``; trapezoid, as the library's
    forces), left out where the joint rests as the library's equations are."""
    paths = neutral_paths(ctx.trajs, ctx.j, play, starts)
    column = []
    for s in prob.segments:
        t, r = paths[s.name.rsplit("[", 1)[0]]
        offset = int(np.searchsorted(t, s.t[0] - 1e-9 * s.dt))
        stretch = s.q[:, ctx.j] - r[offset : offset + s.q.shape[0]]
        column.append(_fit._group(0.5 * s.dt * (stretch[:-1] + stretch[1:]), ctx.fx.stride)[: s.A.shape[0]])
    return -np.concatenate(column) * prob.keep[:, ctx.j]


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
