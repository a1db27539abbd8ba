"""The diagnosis's settings: every knob of :func:`~.diagnose` with its per-system default, in one
group per step of the pipeline. A knob's name is unique across the groups, so ``diagnose(...,
z_threshold=4)`` and :meth:`DiagnosisSettings.replaced` name a knob without its group."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..models import system_definition

__all__ = ["DiagnosisSettings", "ReadingSettings", "SearchSettings", "RestSettings", "OutputErrorSettings"]


@dataclasses.dataclass(frozen=True)
class ReadingSettings:
    """How the logs become fit data (``_prepare``)."""

    velocity: str = "zero_phase"  # or "derivative_filter" (the paper's causal filter)
    velocity_cutoff_hz: float | None = None
    input_hold: str = "zoh"  # "zoh" (digital controller) or "linear"
    segment_seconds: float | None = None  # cut trajectories into segments of about this length
    trim_seconds: float = 0.05  # trimmed off each segment's ends
    holdout_every: int = 3  # every k-th segment is held out for before/after errors


@dataclasses.dataclass(frozen=True)
class SearchSettings:
    """What counts as evidence for an effect, and how far the search goes (``_trace``,
    ``_candidates``, ``_input_search``)."""

    interval: float | None = None  # equation-error interval ΔT, s
    block_seconds: float = 0.5
    # how blocks count in the t of log ratios: "regressor" (by the energy of the candidate's own
    # regressor there: where it does not act, a block says nothing) or "uniform" (every block alike)
    evidence_weighting: str = "regressor"
    z_threshold: float = 3.0  # t of per-block held-out log ratios (see _trace)
    min_improvement: float = 0.03  # minimum relative drop of held-out residual sum of squares
    member_z_threshold: float = 2.0  # each member of a pair, given the other
    max_effects: int = 4
    pair_pool: int = 4  # when no single effect passes, pairs among this many largest gains
    # a tested candidate that removes at least this share of the held-out residual but fails the
    # consistency test is reported "inconsistent", with where it helps and where it hurts
    inconsistent_gain: float = 0.10
    identify_t: float = 3.0  # a base parameter whose nominal size moves the residual less is held
    veto_t: float = 2.0  # an added effect is dropped if its refit predicts significantly worse
    max_delay: float = 0.05  # bound of the input delay / lag search, s


@dataclasses.dataclass(frozen=True)
class RestSettings:
    """Where a joint does not move: what its rests say of dry friction (``_rests``), and which
    equations its stops leave out."""

    # windows of this length at one encoder count; a stiction is added from rests when they held
    # the joint against this multiple of its Coulomb level
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
    # Method step 11 (the cable whose rest moves, the large breakaway): "auto" where the data ask
    # for it, "always" on every joint whose spring has a law with memory (a user who knows a
    # cable is there asks both laws, and gets each one's fit and evidence)
    cable_laws: str = "auto"


@dataclasses.dataclass(frozen=True)
class OutputErrorSettings:
    """The open-loop windows and the output-error fits on them (``_windows``)."""

    oe: bool = True
    window: float | None = None  # open-loop window for trajectory_rmse and the OE fit, s
    oe_max_windows: int = 24
    oe_max_nfev: int = 15
    # Gauss-Newton steps on each window's start velocity in the output-error fits (the stiction test
    # always takes at least one; everywhere on the closed-loop logs it gave less accurate coefficients)
    start_iterations: int = 0


@dataclasses.dataclass(frozen=True)
class DiagnosisSettings:
    """Knobs of :func:`diagnose` with per-system defaults (``None`` → default), by step:
    :attr:`reading`, :attr:`search`, :attr:`rests`, :attr:`output_error`."""

    reading: ReadingSettings = ReadingSettings()
    search: SearchSettings = SearchSettings()
    rests: RestSettings = RestSettings()
    output_error: OutputErrorSettings = OutputErrorSettings()

    @staticmethod
    def knobs() -> dict[str, str]:
        """Every knob's name and the group that holds it."""
        return {f.name: group for group, cls in _GROUPS.items() for f in dataclasses.fields(cls)}

    def replaced(self, **knobs: Any) -> "DiagnosisSettings":
        """These settings with ``knobs`` changed, each named alone (``z_threshold=4``) or a whole
        group (``rests=RestSettings(...)``); one error names what is not a knob."""
        where = self.knobs()
        unknown = sorted(set(knobs) - set(where) - set(_GROUPS))
        if unknown:
            raise ValueError(f"unknown diagnosis settings {unknown}; known: {sorted(where)}")
        groups = {name: knobs.get(name, getattr(self, name)) for name in _GROUPS}
        for name, value in knobs.items():
            if name in where:
                groups[where[name]] = dataclasses.replace(groups[where[name]], **{name: value})
        return DiagnosisSettings(**groups)

    def flat(self) -> dict[str, Any]:
        """Every knob by its name (a result's record of its settings)."""
        return {k: v for name in _GROUPS for k, v in dataclasses.asdict(getattr(self, name)).items()}

    def resolved(self, system: str, dt: float) -> "DiagnosisSettings":
        """Checked, with the per-system defaults of ``system`` filled in."""
        _check(self)
        definition = system_definition(system)
        return self.replaced(
            interval=self.search.interval or 0.1,
            window=self.output_error.window or definition.diagnosis_window,
            segment_seconds=self.reading.segment_seconds or definition.diagnosis_segment_seconds,
        )


_GROUPS = {
    "reading": ReadingSettings,
    "search": SearchSettings,
    "rests": RestSettings,
    "output_error": OutputErrorSettings,
}


def _check(settings: DiagnosisSettings) -> None:
    """One error for a knob outside its range."""
    rests, start = settings.rests, settings.output_error.start_iterations
    if rests.stop_dwell is not None and not rests.stop_dwell > 0:
        raise ValueError(f"stop_dwell: expected a positive time in s or None, got {rests.stop_dwell!r}")
    if rests.held_stop is not None and not rests.held_stop >= 1:
        raise ValueError(f"held_stop: expected a number of counts >= 1 or None, got {rests.held_stop!r}")
    weighting = settings.search.evidence_weighting
    if weighting not in ("regressor", "uniform"):
        raise ValueError(f"evidence_weighting: expected 'regressor' or 'uniform', got {weighting!r}")
    if settings.rests.cable_laws not in ("auto", "always"):
        raise ValueError(f"cable_laws: expected 'auto' or 'always', got {settings.rests.cable_laws!r}")
    if isinstance(start, bool) or not isinstance(start, (int, np.integer)) or start < 0:
        raise ValueError(f"start_iterations: expected an integer >= 0, got {start!r}")
