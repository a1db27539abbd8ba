"""The diagnosis's settings: every knob of :func:`~.diagnose` with its per-system default."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..models import system_definition


@dataclasses.dataclass(frozen=True)
class DiagnosisSettings:
    """Knobs of :func:`diagnose` with per-system defaults (``None`` → default)."""

    velocity: str = "zero_phase"  # or "derivative_filter" (the paper's causal filter)
    velocity_cutoff_hz: float | None = None
    interval: float | None = None  # equation-error interval ΔT, s
    window: float | None = None  # open-loop window for trajectory_rmse and the OE fit, s
    input_hold: str = "zoh"  # "zoh" (digital controller) or "linear"
    holdout_every: int = 3  # every k-th segment is held out for before/after errors
    segment_seconds: float | None = None  # cut trajectories into segments of about this length
    z_threshold: float = 3.0  # t of per-block held-out log ratios (see _trace)
    min_improvement: float = 0.03  # minimum relative drop of held-out residual sum of squares
    max_effects: int = 4
    pair_pool: int = 4  # when no single effect passes, pairs among this many largest gains
    member_z_threshold: float = 2.0  # each member of a pair, given the other
    block_seconds: float = 0.5
    # how blocks count in the t of log ratios: "regressor" (by the energy of the candidate's own
    # regressor there: where it does not act, a block says nothing) or "uniform" (every block alike)
    evidence_weighting: str = "regressor"
    # a tested candidate that removes at least this share of the held-out residual but fails the
    # consistency test is reported "inconsistent", with where it helps and where it hurts
    inconsistent_gain: float = 0.10
    # rests bound dry friction from below (``_rests``): windows of this length at one encoder count;
    # a stiction is added from rests when they held the joint against this multiple of its Coulomb level
    rest_window: float = 0.2
    min_breakaway_ratio: float = 1.25
    exclude_rest: bool = True  # leave a joint's equations out where its encoder does not move
    # ... and, given a time in s, also where it stays on one count that long within an interval
    # (a stop: dry friction holds it with an unknown force, and the estimated momentum and sgn(q̇)
    # are guesses); one period of the velocity estimate's bandwidth, 40 ms at 25 Hz, on sticky
    # sweeps. Off (None) by default: on closed-loop logs it costs the input lag's evidence
    stop_dwell: float | None = None
    # ... or, given a number of counts, where it stops for longer than a free joint could: over the
    # stop, the model's forces other than dry friction would have moved it by more than that many
    # counts (through a reversal or a slow pass a free joint stays within one), so friction held it.
    # Stops that are motion keep their equations (under feedback nearly all are). On by default
    # (2 counts, issue 43: the whole grid and the shipped runs find what they found without it, and
    # the sticky sweeps' spring is right on one more log); None turns it off
    held_stop: float | None = 2.0
    identify_t: float = 3.0  # a base parameter whose nominal size moves the residual less is held
    veto_t: float = 2.0  # an added effect is dropped if its refit predicts significantly worse
    max_delay: float = 0.05
    oe: bool = True
    oe_max_windows: int = 24
    oe_max_nfev: int = 15
    trim_seconds: float = 0.05
    # Gauss-Newton steps on each window's start velocity in the output-error fits (the stiction test
    # always takes at least one; everywhere on the closed-loop logs it gave less accurate coefficients)
    start_iterations: int = 0

    def resolved(self, system: str, dt: float) -> "DiagnosisSettings":
        definition = system_definition(system)
        if self.stop_dwell is not None and not self.stop_dwell > 0:
            raise ValueError(f"stop_dwell: expected a positive time in s or None, got {self.stop_dwell!r}")
        if self.held_stop is not None and not self.held_stop >= 1:
            raise ValueError(f"held_stop: expected a number of counts >= 1 or None, got {self.held_stop!r}")
        if self.evidence_weighting not in ("regressor", "uniform"):
            raise ValueError(f"evidence_weighting: expected 'regressor' or 'uniform', got {self.evidence_weighting!r}")
        if (
            isinstance(self.start_iterations, bool)
            or not isinstance(self.start_iterations, (int, np.integer))
            or self.start_iterations < 0
        ):
            raise ValueError(f"start_iterations: expected an integer >= 0, got {self.start_iterations!r}")
        return dataclasses.replace(
            self,
            interval=self.interval or 0.1,
            window=self.window or definition.diagnosis_window,
            segment_seconds=self.segment_seconds or definition.diagnosis_segment_seconds,
        )
