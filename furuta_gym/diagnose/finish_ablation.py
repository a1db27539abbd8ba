"""Ablations of the prediction-first finish on the fit logs' own folds (issue 66).

The finish (:mod:`._finish`) refits the diagnosed model by output error on the fit segments'
windows and judges it on the held-out ones. To ask what a change of its recipe is worth without
touching any test data, the diagnosis' segments are split into folds as the diagnosis splits them
(every third segment of a log; fold 2 is its held-out set), and a variant of the refit is fitted
on the other folds and scored on each fold in turn (:func:`run_variant`). A variant changes one
thing: the dry-friction law of the predictor (``friction_law``), the input delay refitted with the
rest, an input dead band fitted with the rest (:class:`DeadBandInput`), J1b freed to the
rigid-body boundary, the refit's data (one fold, or its windows placed
otherwise: :data:`PLACEMENTS`), its evaluations or its start. Every variant is scored on the held-out
fold's windows under each placement, since where a 0.1 s window starts changes its error (the
shipped runs' input steps every 0.1 s). ``studies/head_to_head_ablation.py`` runs them on the
head-to-head's fit runs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..lagrangian import forward_dynamics, forward_dynamics_with_dry_friction, solve_mass_matrix
from ..simulate import rollout_zoh
from ..systems import get_spec
from . import _cable_search, _finish, _fit, _trace as _trace_mod, _windows
from ._diagnose import diagnose
from ._finish import PLACEMENTS, STARTS_EVERY, drawn, log_starts, placed_windows, refit_windows
from ._fit import DeadBandInput
from ._library import Candidate
from ._rotor_context import window_errors
from ._settings import DiagnosisSettings
from ._windows import Windows, predict_windows, window_square_sums

__all__ = [
    "PLACEMENTS",
    "STARTS_EVERY",
    "FINISH",
    "DeadBandInput",
    "Variant",
    "Windows",
    "diagnose_with_context",
    "fold_of",
    "friction_law",
    "log_starts",
    "placed_windows",
    "predict_windows",
    "refit",
    "refit_start",
    "refit_windows",
    "rotor_laws_held_out",
    "run_variant",
    "summarise",
    "window_square_sums",
]

FOLDS = 3
#: the delay grid around the refit's value (s), and the margin kept off a body boundary
DELAY_STEPS = np.array([-0.5e-3, -0.25e-3, 0.25e-3, 0.5e-3])
BOUNDARY_MARGIN = 0.01
RULE = DiagnosisSettings()  # its rule for a gain judges a variant against the current finish
#: the variant every other is compared with: the finish's refit (its windows staggered,
#: :mod:`._finish`) before its dead band search (variant ``finish`` adds that search)
FINISH = "staggered"


@dataclasses.dataclass(frozen=True)
class Variant:
    name: str
    label: str
    law: tuple[str, float] | None = None  # ("karnopp", relaxation s) or ("tanh", ε rad/s); None: the diagnosis'
    refit_delay: bool = False
    free_j1b: bool = False
    one_fold: bool = False  # refit on one fold (the next one) instead of two
    max_nfev: int | None = None  # the refit's output-error evaluations (None: the finish's 15)
    # or "nominal" (the datasheet's lumped values) or "given" (``given(context, start)`` -> (θ, input dynamics))
    start: str = "diagnosis"
    refit: bool = True  # False: the start itself scored (e.g. another tool's fit in this predictor)
    placement: str = "segments"  # where the refit's windows start (:data:`PLACEMENTS`)
    max_windows: int | None = None  # the refit on this many of them, drawn at random (None: all)
    # Gauss-Newton steps on each training window's start velocity in the refit (scored without)
    start_iterations: int = 0
    # an input dead band (V, :class:`DeadBandInput`): the refit at each, the one whose refit fits
    # the training windows best kept (empty: none)
    dead_bands: tuple[float, ...] = ()
    # the finish's own dead band search (:func:`._finish._fit_dead_band`) on the training windows,
    # after the refit without one; always taken when found (the finish's keep rule reads the
    # held-out fold, which here is the scored one)
    finish_dead_band: bool = False


@contextlib.contextmanager
def _spying(module, name: str):
    """``module.name`` wrapped while inside: yields the list of its calls' positional arguments
    (one ablation at a time, not thread-safe)."""
    calls, original = [], getattr(module, name)

    def spy(*args, **kwargs):
        calls.append(args)
        return original(*args, **kwargs)

    setattr(module, name, spy)
    try:
        yield calls
    finally:
        setattr(module, name, original)


def diagnose_with_context(data, system: str, **kwargs):
    """``diagnose(data, system, finish="prediction", **kwargs)`` and the finish's fitting context
    (the diagnosis' fitter: segments, layout, fixed parameters), which the diagnosis drops once it
    has finished: (result, context, wall seconds). The finish is wrapped while it runs, so
    whatever the diagnosis does before it is the diagnosis as shipped (wrapped rather than given a
    hook: the diagnosis keeps no option for this; one ablation at a time, not thread-safe)."""
    with _spying(_finish, "prediction_finish") as calls:
        t0 = time.perf_counter()
        res = diagnose(data, system, finish="prediction", **kwargs)
        wall = time.perf_counter() - t0
    return res, calls[-1][0], wall


def rotor_laws_held_out(data, system: str, **kwargs) -> dict:
    """Method step 11 asked on every joint with a cable's spring (``cable_laws="always"``) in
    ``diagnose(data, system, finish="prediction", **kwargs)``, and each law's fit scored, beside
    the model as diagnosed that it was fitted onto, on the diagnosis' held-out segments from
    measured start states (as the diagnosis scores its own errors): {"verdict", "reason",
    "diagnosed_heldout_rmse", "seconds", "laws": {law: effects, cable, validation gain and t,
    held-out RMSE}}. Wrapped while it runs, as :func:`diagnose_with_context` is."""
    with _spying(_cable_search._laws, "fit_laws") as calls:
        res, fx, wall = diagnose_with_context(data, system, cable_laws="always", **kwargs)
    (law,) = res.rotor_laws
    ctx, diagnosed = calls[-1][:2]

    def held_out(theta, cable) -> float:
        return window_errors(ctx, theta, cable, fx.held_segs)[1]

    laws = {
        name: {
            "effects": {c.key: float(f.theta[fx.layout.index(c.key)]) for c in f.effects},
            "cable": list(f.cable),
            "validation_gain": f.evidence.improvement,
            "validation_t": f.evidence.z,
            "heldout_rmse": held_out(f.theta, f.cable),
        }
        for name, f in law.fits.items()
    }
    return {
        "verdict": law.verdict,
        "reason": law.reason,
        "diagnosed_heldout_rmse": held_out(diagnosed, (0.0, 0.0)),
        "seconds": wall,
        "laws": laws,
    }


def fold_of(segment) -> int:
    """A segment's fold: its index on its log (the ``[k]`` of its name) modulo 3, as the
    diagnosis holds out every third segment (fold 2 is its held-out set)."""
    return int(segment.name.rsplit("[", 1)[1].rstrip("]")) % FOLDS


#: MuJoCo's friction loss with its default solver parameters: the reference acceleration −b·q̇,
#: b = 2 / (d_max·timeconst) (solreffriction 0.02 s, solimp d_max 0.95), and impedance d = 0.9
#: (solimp d_0 at zero violation): the constraint supplies only d of the force that would reach
#: the reference, so a loaded joint creeps instead of sticking
MUJOCO_RELAXATION, MUJOCO_IMPEDANCE = 0.95 * 0.02 / 2, 0.9


def soft_friction_dynamics(model, limit, q, qd, u):
    """q̈ with MuJoCo's soft friction loss: the Karnopp law of
    :func:`~furuta_gym.lagrangian.forward_dynamics_with_dry_friction` with MuJoCo's relaxation
    and its holding force scaled by MuJoCo's impedance."""
    return forward_dynamics_with_dry_friction(model, limit, q, qd, u, MUJOCO_RELAXATION, MUJOCO_IMPEDANCE)


def _law_field(layout, theta, law, n: int):
    """ẋ(x, u) of θ with the library's dry friction under ``law``."""
    model = layout.model(theta, dry_friction=False)
    kind, value = law

    def field(x, u):
        q, qd = x[:n], x[n:]
        limit = layout.dry_friction_limit(theta, qd)
        if kind == "karnopp":  # the diagnosis' stick-slip, relaxing over ``value`` s, not one substep
            return jnp.concatenate([qd, forward_dynamics_with_dry_friction(model, limit, q, qd, u, value)])
        if kind == "mujoco":
            return jnp.concatenate([qd, soft_friction_dynamics(model, limit, q, qd, u)])
        smooth = solve_mass_matrix(model.mass_matrix(q), -limit * jnp.tanh(qd / value))
        return jnp.concatenate([qd, forward_dynamics(model, q, qd, u) + smooth])

    return model, field


@contextlib.contextmanager
def friction_law(law):
    """The diagnosis' window predictor (and so its output-error fit) under another dry-friction
    law while inside; ``None`` leaves it alone. The predictor is swapped for the while, since the
    finish's output-error fit takes none as an argument (one ablation at a time)."""
    if law is None:
        yield
        return
    original = _windows._predictor

    def predictor(layout, dt, length, substeps, start_iterations=0):
        assert start_iterations == 0, "the finish refits with start_iterations 0"
        n = get_spec(layout.system).n_dof

        def one(theta, x, u, q_measured):
            model, field = _law_field(layout, theta, law, n)
            return rollout_zoh(model, x, u, dt, substeps, field)[1:, :n]

        key = f"predict-{law[0]}-{law[1]}"
        return _fit._compiled(key, layout, dt, length, substeps, 0, build=lambda: jax.jit(jax.vmap(one)))

    _windows._predictor = predictor
    try:
        yield
    finally:
        _windows._predictor = original


def refit(fx, theta, chosen, dyn, win) -> np.ndarray:
    """θ of the finish's output-error refit from ``theta`` with ``chosen`` free on windows ``win``
    (under input dynamics ``dyn``), as the finish refits."""
    return _finish._refit(fx, theta, chosen, dyn, win)[0]


def refit_start(fx, res):
    """The finish's start: the diagnosed θ with its inconsistent effects and every joint's
    Coulomb friction at their tested values, the candidates it frees and its input dynamics."""
    dyn, extra_dynamics = _finish._refit_dynamics(res)
    found = [Candidate(e.name, e.joint) for e in res.significant] + extra_dynamics
    extra = _finish._extra_candidates(fx.layout, res)
    start = np.array(res.theta_after, dtype=float)
    for c, coefficient in extra:
        start[fx.layout.index(c.key)] = coefficient
    return start, found + [c for c, _ in extra], dyn


def refit_delay(fx, theta, chosen, dyn, windows):
    """The delay on a grid about ``dyn`` by the training windows' error at θ, then θ refitted at
    the best one (the finish holds the delay; here it moves with the rest). ``windows(d)``: the
    training windows under input dynamics ``d``."""
    if dyn.kind == "none":
        return theta, chosen, dyn
    grid = [dyn] + [dataclasses.replace(dyn, seconds=dyn.seconds + s) for s in DELAY_STEPS]
    sums = [_windows.window_square_sums(fx.layout, theta, windows(d), fx.substeps).sum() for d in grid]
    best = grid[int(np.argmin(sums))]
    if best == dyn:
        return theta, chosen, dyn
    theta, chosen, _, _ = _finish._refit(fx, theta, chosen, best, windows(best))
    return theta, chosen, best


def at_body_boundary(fx, res, theta) -> float | None:
    """The J1b nearest a fitted one that rigid bodies have (J1 − Jc²/J1b > 0, J2 − J1b > point
    mass), ``BOUNDARY_MARGIN`` inside; None when the fit's values already have rigid bodies."""
    if _finish._rigid_failure(res.system, theta, fx.layout) is None:
        return None
    b = {name: float(theta[i]) for i, name in enumerate(fx.layout.base)}
    lowest = b["Jc"] ** 2 / b["J1"] * (1 + BOUNDARY_MARGIN)
    return float(np.clip(b["J1b"], lowest, max(lowest, b["J2"] * (1 - BOUNDARY_MARGIN) - 1e-9)))


def refit_j1b(fx, res, start, chosen, dyn, win):
    """The refit with J1b free; held at the body boundary it crossed, and the rest refitted."""
    j = fx.layout.index("J1b")
    fixed = set(fx.fixed_idx)
    fx.fixed_idx = fixed - {j}
    try:
        theta, chosen, _, _ = _finish._refit(fx, start, chosen, dyn, win)
    finally:
        fx.fixed_idx = fixed
    boundary = at_body_boundary(fx, res, theta)
    if boundary is not None:
        theta = np.array(theta, dtype=float)
        theta[j] = boundary
        theta, chosen, _, _ = _finish._refit(fx, theta, chosen, dyn, win)
    return theta, chosen


def refit_dead_band(fx, fit, dyn, windows, dead_bands):
    """The refit at each input dead band of ``dead_bands`` (from the same start), kept where its
    training windows' sum of squares is least: the dead band fitted with the rest on a grid.
    ``fit(d, win)``: the refit's (θ, kept candidates) under input dynamics ``d`` on windows
    ``win``; ``windows(d)``: the training windows under ``d``."""
    best = None
    for band in dead_bands:
        d = DeadBandInput(dyn.kind, dyn.seconds, float(band))
        win = windows(d)
        theta, kept = fit(d, win)
        total = _finish._fit_total(fx, theta, win)
        if best is None or total < best[0]:
            best = (total, theta, kept, d, win)
    assert best is not None, "dead_bands holds one value at least"
    return best[1:]


@contextlib.contextmanager
def _restoring(fx, settings):
    try:
        yield
    finally:
        fx.settings = settings


def _fit_once(fx, res, variant: Variant, start, chosen, dyn, win):
    """The variant's refit from ``start`` under input dynamics ``dyn`` on ``win``: (θ, kept)."""
    if variant.free_j1b:
        return refit_j1b(fx, res, start, chosen, dyn, win)
    theta, chosen, _, _ = _finish._refit(fx, start, chosen, dyn, win)
    return theta, chosen


def refit_finish_dead_band(fx, res, variant: Variant, start, chosen, dyn, windows):
    """The variant's refit, then the finish's dead band search from it on the training windows
    ``windows(dynamics)``: (θ, kept, input dynamics, training windows)."""
    theta, chosen = _fit_once(fx, res, variant, start, chosen, dyn, windows(dyn))
    found = _finish._fit_dead_band(fx, (theta, chosen, [], False), dyn, windows)
    if found is not None:
        (theta, chosen, _, _), dyn = found
    return theta, chosen, dyn, windows(dyn)


def fit_and_score(fx, res, variant: Variant, train, held, given=None) -> dict:
    """Refit on the ``train`` segments as the variant says; per-window squared errors on ``held``
    under each placement of its windows (``sums``: the diagnosis' own, ``sums_<placement>``)."""
    start, chosen, dyn = refit_start(fx, res)
    if variant.start == "given":
        assert given is not None, f"{variant.name}: a given start needs ``given``"
        start, dyn = given(fx, start)
    elif variant.start == "nominal":
        nb = len(fx.layout.base)
        start[:nb] = np.where([i in fx.fixed_idx for i in range(nb)], start[:nb], fx.layout.nominal()[:nb])
    starts = log_starts(fx.segs, fx.settings.reading.trim_seconds)
    windows = lambda d: drawn(placed_windows(train, fx.L, d, variant.placement, starts), variant.max_windows)  # noqa: E731
    win = windows(dyn)
    settings = fx.settings
    if variant.max_nfev is not None or variant.start_iterations:
        fx.settings = settings.replaced(
            oe_max_nfev=variant.max_nfev or settings.output_error.oe_max_nfev,
            start_iterations=variant.start_iterations,
        )
    with friction_law(variant.law), _restoring(fx, settings):
        if not variant.refit:
            theta = start
        elif variant.finish_dead_band:
            theta, chosen, dyn, win = refit_finish_dead_band(fx, res, variant, start, chosen, dyn, windows)
        elif variant.dead_bands:
            fit = lambda d, w: _fit_once(fx, res, variant, start, chosen, d, w)  # noqa: E731
            theta, chosen, dyn, win = refit_dead_band(fx, fit, dyn, windows, variant.dead_bands)
        else:
            theta, chosen = _fit_once(fx, res, variant, start, chosen, dyn, win)
        if variant.refit_delay:
            theta, chosen, dyn = refit_delay(fx, theta, chosen, dyn, windows)
        sums = {
            "sums" if p == "segments" else f"sums_{p}": _windows.window_square_sums(
                fx.layout, theta, placed_windows(held, fx.L, dyn, p, starts), fx.substeps
            )
            for p in PLACEMENTS
        }
    return {
        **sums,
        "theta": {name: float(theta[i]) for i, name in enumerate(fx.layout.base)},
        "effects": {c.key: float(theta[fx.layout.index(c.key)]) for c in chosen if not c.kind.input_dynamics},
        "delay": dyn.seconds,
        "input_dynamics": dyn.kind,
        **({"dead_band": dyn.dead_band} if isinstance(dyn, DeadBandInput) else {}),
        "train_windows": int(win.x0.shape[0]) if variant.refit else 0,
    }


def run_variant(fx, res, variant: Variant, given=None) -> dict:
    """Every fold held out in turn (refit on the other two, or on the next one only)."""
    folds = [[s for s in fx.segs if fold_of(s) == k] for k in range(FOLDS)]
    assert list(map(id, folds[FOLDS - 1])) == list(map(id, fx.held_segs)), "fold 2: the diagnosis' held-out set"
    per_fold, t0 = [], time.perf_counter()
    for k in range(FOLDS):
        others = [(k + 1) % FOLDS] if variant.one_fold else [m for m in range(FOLDS) if m != k]
        train = [s for s in fx.segs if fold_of(s) in others]  # in the diagnosis' order, as the finish's
        per_fold.append(fit_and_score(fx, res, variant, train, folds[k], given))
    listed = lambda f: {k: v.tolist() if k.startswith("sums") else v for k, v in f.items()}  # noqa: E731
    return {
        "name": variant.name,
        "label": variant.label,
        "placement": variant.placement,
        "per_fold": [listed(f) for f in per_fold],
        "wall_seconds": round(time.perf_counter() - t0, 1),
    }


#: position RMSE over every joint from per-window sums of squares
rmse = _windows.position_rmse


def _pooled(doc: dict, key: str) -> dict[str, np.ndarray]:
    return {
        v: np.concatenate([f[key] for f in r["per_fold"]])
        for v, r in doc["variants"].items()
        if all(key in f for f in r["per_fold"])
    }


def _change(base, sums) -> dict:
    ev = _trace_mod.Evidence.of_sums(base, sums)
    return {
        "improvement": float(ev.improvement),
        "z_score": float(ev.z),
        "passes_rule": bool(ev.passes(RULE.search.min_improvement, RULE.search.z_threshold)),
    }


def summarise(doc: dict, length: int, n: int) -> None:
    """Pooled held-out RMSE, fold 2's (the finish's own held-out windows) and the change against
    the current finish, with the diagnosis' rule for a gain (relative drop of the sum of squares,
    t of per-window log ratios); the same on the held-out windows of each other placement
    (``by_placement``). ``vs_finish``: the same change against the finish as shipped now
    (:data:`FINISH`), where both variants' sums are at hand."""
    pooled = _pooled(doc, "sums")
    base = pooled.get("current")
    for v, r in doc["variants"].items():
        r["heldout_rmse"] = rmse(pooled[v], length, n)
        r["fold_rmse"] = [rmse(f["sums"], length, n) for f in r["per_fold"]]
        if base is not None and v != "current":
            change = _change(base, pooled[v])
            r["vs_current"] = {k: change[k] for k in ("improvement", "z_score")}
            r["passes_rule"] = change["passes_rule"]
        if FINISH in pooled and v not in ("current", FINISH):
            r["vs_finish"] = _change(pooled[FINISH], pooled[v])
    for placement in PLACEMENTS[1:]:
        pooled = _pooled(doc, f"sums_{placement}")
        base = pooled.get("current")
        for v, sums in pooled.items():
            entry = {"heldout_rmse": rmse(sums, length, n), "windows": int(sums.size)}
            if base is not None and v != "current":
                entry |= _change(base, sums)
            if FINISH in pooled and v not in ("current", FINISH):
                entry["vs_finish"] = _change(pooled[FINISH], sums)
            doc["variants"][v].setdefault("by_placement", {})[placement] = entry
