"""The fit step: one dataset's fitting context (:class:`_Fitter`: regressors, windows, the
equation-error fit and its output-error refinement, held-out errors), the declared model's fit,
and how a refit's predictions are compared."""

from __future__ import annotations

import numpy as np

from ..data import DataError
from ..models import system_definition
from . import _fit, _trace as _trace_mod, _windows
from ._intervals import FitOrigin
from ._library import Candidate, is_physical
from ._problem import Problem, fit_equation_error, free_columns
from ._result import ErrorSummary


class _Fitter:
    """One dataset's fitting context: segments (fit / held-out / test), regressors, windows."""

    def __init__(self, spec, layout, segs, test_segs, theta_fixed, fixed_idx, settings, notes):
        self.spec, self.layout, self.settings, self.notes = spec, layout, settings, notes
        self.segs, self.test_segs = segs, test_segs
        self.fit_segs = [s for s in segs if not s.held_out]
        self.held_segs = [s for s in segs if s.held_out]
        self.theta_fixed, self.fixed_idx = theta_fixed, set(fixed_idx)
        self.declared_fixed_idx = set(fixed_idx)  # before any weakly identified parameter is held
        dt = segs[0].dt
        self.stride = max(1, int(round(settings.search.interval / dt)))
        self.L = int(round(settings.output_error.window / dt))
        self.substeps = system_definition(spec.name).diagnosis_substeps
        self.alternative = ""  # the input dynamics' other kind and how it fitted (a note)
        self.resolution: dict[str, float] = {}  # encoder count per quantised joint (sensor_resolution)
        self.origins: dict[bytes, FitOrigin] = {}  # which fit each returned θ is (for its intervals)
        self.c_input = _fit.input_direction(layout, theta_fixed)
        self.weights = np.ones(spec.n_dof)
        self.build(_fit.NO_INPUT_DYNAMICS)
        all_fit_win = _windows.make_windows(self.fit_segs, self.L)
        if _windows.make_windows(self.held_segs, self.L) is None or all_fit_win is None:
            raise DataError("too short: no complete open-loop window in the fit or held-out segments")
        # fit-set windows: a random subset drives the output-error fit, the rest validates effects
        order = np.random.default_rng(0).permutation(all_fit_win.x0.shape[0])
        k = settings.output_error.oe_max_windows
        self.oe_idx = np.sort(order[:k])
        self.val_idx = np.sort(order[k:]) if order.size > k else self.oe_idx

    def build(self, dynamics: _fit.InputDynamics, segs=None) -> None:
        _fit.build_regressors(
            self.segs + self.test_segs if segs is None else segs,
            self.layout,
            self.theta_fixed,
            self.stride,
            self.settings.reading.input_hold,
            self.settings.search.block_seconds,
            dynamics,
            self.settings.rests.exclude_rest,
            self.settings.rests.stop_dwell,
            self.settings.rests.held_stop,
        )
        if segs is None:
            self.fit_prob = Problem(self.fit_segs, self.c_input)
            self.held_prob = Problem(self.held_segs, self.c_input)
            self.dynamics = dynamics

    def comparer(self, prob=None) -> _trace_mod.Comparer:
        """Cross-validated comparisons on the fit segments (``prob``: their problem with a column
        replaced, :meth:`Problem.with_column`), blocks labelled by their recording."""
        return _trace_mod.Comparer(
            self.fit_prob if prob is None else prob,
            self.layout,
            self.theta_fixed,
            self.fixed_idx,
            self.weights,
            weighting=self.settings.search.evidence_weighting,
            recordings=[s.name.rsplit("[", 1)[0] for s in self.fit_segs],
        )

    def fit_ee(self, effects: list[Candidate]):
        free = free_columns(self.layout, effects, self.fixed_idx)
        th, _ = fit_equation_error(self.fit_prob, self.layout, free, self.theta_fixed, self.weights, False)
        return th, free

    def weakly_identified(self, theta, free) -> dict[str, float]:
        """Free base parameters these data cannot pin down, with their t values: a change by
        the parameter's nominal size moves the weighted residual, beyond what the other free
        parameters can absorb, by less than ``identify_t`` residual standard deviations (near
        upright the sin²β inertia term; a damping below what the data resolve)."""
        X = (self.fit_prob.R * self.weights[None, :, None]).reshape(-1, self.layout.size)
        sigma = float(np.std(X @ theta))
        nominal = self.layout.nominal()
        out = {}
        for j in np.flatnonzero(free[: len(self.layout.base)]):
            others = free.copy()
            others[j] = False
            A, c = X[:, others], X[:, j]
            c_perp = c - A @ np.linalg.lstsq(A, c, rcond=None)[0]
            t = abs(nominal[j]) * np.linalg.norm(c_perp) / max(sigma, 1e-300)
            if t < self.settings.search.identify_t:
                out[self.layout.base[j]] = float(t)
        return out

    def fit_windows(self, dynamics, idx) -> _windows.Windows:
        return _windows.make_windows(self.fit_segs, self.L, dynamics).take(idx)

    def window_rmse(self, theta, win) -> float:
        return _windows.window_errors(
            self.layout, theta, win, self.substeps, self.settings.output_error.start_iterations
        )[1]

    def validation_rmse(self, theta, dynamics) -> float:
        return self.window_rmse(theta, self.fit_windows(dynamics, self.val_idx))

    def validation_sums(self, theta, dynamics, start_iterations: int | None = None) -> np.ndarray:
        """Per-window squared position errors on the fit-set validation windows."""
        win = self.fit_windows(dynamics, self.val_idx)
        start = self.settings.output_error.start_iterations if start_iterations is None else start_iterations
        return _windows.window_square_sums(self.layout, theta, win, self.substeps, start)

    def validation_predictions(self, theta, dynamics, start_iterations: int) -> np.ndarray:
        """(W, L, n): predicted positions of the fit-set validation windows."""
        return _windows.predict_windows(
            self.layout, theta, self.fit_windows(dynamics, self.val_idx), self.substeps, start_iterations
        )

    def record(self, theta, origin: FitOrigin) -> np.ndarray:
        """Remember which fit ``theta`` came from (its intervals are that fit's); returns it."""
        self.origins[np.asarray(theta, dtype=float).tobytes()] = origin
        return theta

    def origin(self, theta) -> FitOrigin | None:
        return self.origins.get(np.asarray(theta, dtype=float).tobytes())

    def refine(self, theta0, free, dynamics, tag):
        """Output-error refinement of an equation-error estimate, kept only if it also predicts
        better on fit-set validation windows it did not see. Records which fit the returned θ is
        (:meth:`record`): the output-error one, or the equation-error one (its base parameters
        held at nominal when the refinement started from, and kept, the nominal values)."""
        ee = FitOrigin("equation_error", theta0, free, dynamics)
        if not self.settings.output_error.oe:
            return self.record(theta0, ee)
        win = self.fit_windows(dynamics, self.oe_idx)
        # start from the equation-error estimate unless it is non-physical or predicts worse than
        # the nominal model (closed-loop data: u correlates with the measurement noise, which
        # biases the equation error far more than velocity noise does)
        nb = len(self.layout.base)
        nominal = theta0.copy()
        nominal[:nb] = np.where(free[:nb], self.layout.nominal()[:nb], theta0[:nb])
        start, label, start_origin = theta0, "equation-error", ee
        if not is_physical(self.layout, theta0) or self.window_rmse(nominal, win) < self.window_rmse(theta0, win):
            start, label = nominal, "nominal"
            start_origin = ee.holding(
                np.flatnonzero(free[:nb]),
                "the nominal value kept (the refinement "
                "started from the nominal parameters and did not predict better)",
            )
            self.notes.append(
                "the equation-error estimate was non-physical or predicted worse than the "
                f"nominal model ({tag}); output error started from the nominal parameters"
            )
        th, ok = _windows.oe_fit(
            self.layout,
            start,
            free,
            win,
            self.substeps,
            max_nfev=self.settings.output_error.oe_max_nfev,
            start_iterations=self.settings.output_error.start_iterations,
        )
        if not ok:
            self.notes.append(f"output-error refinement did not improve on the {label} start ({tag})")
            return self.record(th, start_origin)
        if is_physical(self.layout, start) and self.validation_rmse(start, dynamics) < self.validation_rmse(
            th, dynamics
        ):
            self.notes.append(
                f"the {label} estimate predicts better on validation windows than the "
                f"output-error refinement; kept ({tag})"
            )
            return self.record(start, start_origin)
        return self.record(
            th, FitOrigin("output_error", th, free, dynamics, self.settings.output_error.start_iterations)
        )

    def errors(self, theta, segs, prob) -> ErrorSummary:
        r = prob.R @ theta
        win = _windows.make_windows(segs, self.L, self.dynamics)
        assert win is not None  # the segments were cut to hold windows of this length
        per_q, comb = _windows.window_errors(self.layout, theta, win, self.substeps)
        names = self.spec.joint_names
        return ErrorSummary(
            trajectory_rmse=comb,
            trajectory_rmse_per_joint={j: float(v) for j, v in zip(names, per_q, strict=True)},
            residual_rms=float(np.sqrt(np.mean(r**2))),
            residual_rms_per_joint={j: float(v) for j, v in zip(names, np.sqrt(np.mean(r**2, axis=0)), strict=True)},
            window_seconds=self.settings.output_error.window,
            n_windows=int(win.x0.shape[0]),
        )

    def test_errors(self, theta) -> ErrorSummary | None:
        if not self.test_segs:
            return None
        return self.errors(theta, self.test_segs, Problem(self.test_segs, self.c_input))


def _prediction_evidence(sums_before, sums_after, weights=None) -> _trace_mod.Evidence:
    """How much better a refit predicts the validation windows (per-window log ratios, weighted
    by ``weights``: None, every window alike)."""
    if not np.all(np.isfinite(sums_after)):
        return _trace_mod.Evidence(-np.inf, -np.inf, int(sums_after.size))
    return _trace_mod.Evidence.of_sums(sums_before, sums_after, weights)


def _square_sums(predicted: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """(W,) squared position errors per window (inf where a prediction blew up)."""
    ss = np.sum((predicted - measured) ** 2, axis=(1, 2))
    return np.where(np.isfinite(ss), ss, np.inf)


def _fit_declared(fx: _Fitter) -> np.ndarray:
    """The declared model: equation error (weights from its own residual), then output error;
    parameters these data cannot pin down are held at their nominal values."""
    th_ee, free_base = fx.fit_ee([])
    fx.weights = 1.0 / np.maximum(np.sqrt(np.mean((fx.fit_prob.R @ th_ee) ** 2, axis=0)), 1e-300)
    th_ee, _ = fx.fit_ee([])
    weak = fx.weakly_identified(th_ee, free_base)
    if weak:
        fx.fixed_idx |= {fx.layout.index(k) for k in weak}
        fx.notes.append(
            "not identifiable from these data, held at nominal: "
            + ", ".join(f"{k} (t {t:.1f} < {fx.settings.search.identify_t})" for k, t in weak.items())
        )
        th_ee, free_base = fx.fit_ee([])
    return fx.refine(th_ee, free_base, _fit.NO_INPUT_DYNAMICS, "declared model")
