"""What a diagnosis returns: each effect's evidence, the held-out errors, the fitted parameters,
and the diagnosed rig as a plant (:class:`DiagnosisResult`)."""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from ..effects import EFFECT_KINDS, Effect, EffectKind, WithEffects, can_join, merge_spring_rests
from ..envs import Plant
from . import _finish, _fit
from ._intervals import Interval
from ._library import ParameterLayout
from ._report import format_table
from ._settings import DiagnosisSettings

# 2: intervals ("parameter_intervals", "interval_method", each effect's "interval"); 1 had no key
SCHEMA_VERSION = 2


@dataclasses.dataclass
class EffectEvidence:
    """One library effect tested against the residual."""

    name: str
    joint: str
    coefficient: float | None
    unit: str
    significant: bool
    improvement: float | None  # relative drop of the held-out residual sum of squares (CV)
    z_score: float | None  # weighted t of per-block held-out log ratios, as a normal quantile (CV)
    status: str  # "selected", "inconsistent", "tested", "not confirmed", "equivalent", "absorbed", "not identifiable"
    note: str = ""
    resolved: bool = True  # False: its size is below what the sensor resolves (one count, one sample)
    interval: Interval | None = None  # 95 % interval of an added effect's coefficient (see _intervals)
    play: float | None = None  # a law with memory's second parameter (a moving rest's play)

    @property
    def kind(self) -> EffectKind:
        return EFFECT_KINDS[self.name]

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "joint": self.joint,
            "coefficient": None if self.coefficient is None else float(self.coefficient),
            "unit": self.unit,
            "significant": bool(self.significant),
            "evidence": {
                "heldout_residual_reduction": _f(self.improvement),
                "z_score": _f(self.z_score),
            },
            "status": self.status,
            "note": self.note,
            "resolved": bool(self.resolved),
            "interval": None if self.interval is None else self.interval.to_json(),
            **({} if self.play is None else {self.kind.second_parameter: float(self.play)}),
        }


def _f(x):
    return None if x is None or not np.isfinite(x) else float(x)


@dataclasses.dataclass
class ErrorSummary:
    """Held-out errors of one model. ``trajectory_rmse`` (rad or m) over open-loop windows."""

    trajectory_rmse: float
    trajectory_rmse_per_joint: dict[str, float]
    residual_rms: float
    residual_rms_per_joint: dict[str, float]
    window_seconds: float
    n_windows: int

    def to_json(self) -> dict:
        return {
            "trajectory_rmse": _f(self.trajectory_rmse),
            "trajectory_rmse_per_joint": {k: _f(v) for k, v in self.trajectory_rmse_per_joint.items()},
            "residual_rms": _f(self.residual_rms),
            "residual_rms_per_joint": {k: _f(v) for k, v in self.residual_rms_per_joint.items()},
            "window_seconds": self.window_seconds,
            "n_windows": self.n_windows,
        }


def _as_effects(evidence: Sequence[EffectEvidence]) -> list[Effect]:
    """Fitted effects in :mod:`furuta_gym.effects` vocabulary, a spring's rest merged in."""
    assert all(e.coefficient is not None for e in evidence)  # only fitted effects come here
    return merge_spring_rests(
        [
            Effect(e.name, e.joint, float(e.coefficient or 0.0), **({} if e.play is None else {"play": e.play}))
            for e in evidence
        ]
    )


@dataclasses.dataclass
class DiagnosisResult:
    """What :func:`diagnose` found. ``effects`` are ordered by evidence, strongest first."""

    system: str
    effects: list[EffectEvidence]
    error_before: ErrorSummary
    error_after: ErrorSummary
    parameters_before: dict[str, float]
    parameters_after: dict[str, float]
    parameter_units: dict[str, str]
    fixed: dict[str, float]
    notes: list[str]
    settings: DiagnosisSettings
    layout: ParameterLayout = dataclasses.field(repr=False)
    theta_before: np.ndarray = dataclasses.field(repr=False)
    theta_after: np.ndarray = dataclasses.field(repr=False)
    input_dynamics: _fit.InputDynamics = _fit.NO_INPUT_DYNAMICS
    test_before: ErrorSummary | None = None  # on logs never used by any fit or decision (``test=``)
    test_after: ErrorSummary | None = None
    # 95 % intervals of ``parameters_after`` (None: fixed, or held rather than fitted) and how
    # they were made; the effects' own are on each EffectEvidence
    intervals: dict[str, Interval | None] = dataclasses.field(default_factory=dict)
    interval_method: dict | None = None
    # ``diagnose(..., finish="prediction")``: the plant refitted for prediction and whether it was
    # kept, beside the report (which it does not change)
    prediction: _finish.PredictionFinish | None = None
    # kept for figures
    _segments: list = dataclasses.field(default_factory=list, repr=False)
    _test_segments: list = dataclasses.field(default_factory=list, repr=False)
    # the fitting context, kept only until a prediction-first finish has used it
    _fitter: object = dataclasses.field(default=None, repr=False, compare=False)
    # Method step 11: what a joint's rests and the two cable laws' fits said (issue 64)
    rotor_laws: list = dataclasses.field(default_factory=list)

    @property
    def delay_after(self) -> float:
        """The fitted input delay, s (0 unless an input delay was found)."""
        return self.input_dynamics.seconds if self.input_dynamics.kind == "delay" else 0.0

    @property
    def significant(self) -> list[EffectEvidence]:
        return [e for e in self.effects if e.significant]

    @property
    def found(self) -> list[Effect]:
        """The significant effects in :mod:`furuta_gym.effects` vocabulary. A spring and a constant
        torque on one joint are one spring with a rest position (−k·q + τ0 = −k·(q − τ0/k))."""
        return _as_effects(self.significant)

    @property
    def inconsistent(self) -> list[EffectEvidence]:
        """Effects that lower the held-out error overall but not consistently across the held-out
        groups (status ``inconsistent``): not claimed as found, and not in :attr:`found`."""
        return [e for e in self.effects if e.status == "inconsistent" and e.coefficient is not None]

    @property
    def model_before(self):
        """The fitted declared model (lumped parameters, or the given model), a Lagrangian system."""
        return self.layout.model(np.asarray(self.theta_before))

    @property
    def model_after(self):
        """The declared model plus the found memoryless effects, as ``WithEffects`` (a cable with
        memory lives in the plant: :meth:`plant`)."""
        base_theta = np.array(self.theta_after, dtype=float)
        base_theta[len(self.layout.base) :] = 0.0
        effects = [e for e in self.found if not e.kind.input_dynamics and not e.kind.has_memory]
        return WithEffects(self.layout.model(base_theta), effects)

    def plant(self, include_inconsistent: bool = False, prediction_first: bool = False) -> Plant:
        """The diagnosed rig as a simulator: the fitted lumped parameters and the found effects
        (input delay or lag included) as a :class:`~furuta_gym.envs.Plant`, for
        ``gym.make(..., plant=res)``, ``MujocoBackend(plant=...)`` and
        :func:`~furuta_gym.envs.save_mjcf`. A diagnosis of a given (learned) model has none: use
        :attr:`model_after` as ``dynamics=``.

        ``include_inconsistent``: the :attr:`inconsistent` effects too, at their tested
        coefficients (no refit; one of the wrong physical sign, or a stiction without its
        Coulomb friction, is left out) — a plant chosen for prediction, not a claim about the rig: such
        an effect helped the held-out data as a whole but not most of its groups (a cable spring
        that acts only in the runs whose rotor wanders far). docs/diagnose.md measures both plants
        on real runs never fitted.

        ``prediction_first``: the plant of the prediction-first finish (:attr:`prediction`; needs
        ``diagnose(..., finish="prediction")``): the refit when it predicted the held-out windows
        better, else this default plant. It already holds the inconsistent effects, refitted."""
        if self.layout.learned is not None:
            raise ValueError(
                "a diagnosis of a given model has no MuJoCo plant (its M and V are a "
                "network's); pass res.model_after as dynamics= instead"
            )
        if prediction_first:
            if include_inconsistent:
                raise ValueError(
                    "plant: prediction_first and include_inconsistent are alternatives (the "
                    "prediction-first plant refits the inconsistent effects); pass one"
                )
            if self.prediction is None:
                raise ValueError("plant(prediction_first=True): run diagnose(..., finish='prediction') first")
            return self.prediction.plant
        added = [e for e in self.inconsistent if can_join(e, self.significant)] if include_inconsistent else []
        effects = _as_effects(self.significant + added)
        names = ", ".join(f"{e.name}:{e.joint}" for e in self.found) or "no effect"
        extra = ", ".join(f"{e.name}:{e.joint}" for e in added)
        source = f"diagnosis ({names}" + (f"; inconsistent, included: {extra}" if extra else "") + ")"
        return Plant(effects=effects, lumped=self.parameters_after, system=self.system, source=source)

    def to_json(self) -> dict:
        return {
            "schema_version": SCHEMA_VERSION,
            "system": self.system,
            "effects": [e.to_json() for e in self.effects],
            "error_before": self.error_before.to_json(),
            "error_after": self.error_after.to_json(),
            "parameters_before": self.parameters_before,
            "parameters_after": self.parameters_after,
            "parameter_units": self.parameter_units,
            "parameter_intervals": {
                k: None if self.intervals.get(k) is None else self.intervals[k].to_json() for k in self.parameters_after
            },
            "interval_method": self.interval_method,
            "test_error_before": None if self.test_before is None else self.test_before.to_json(),
            "test_error_after": None if self.test_after is None else self.test_after.to_json(),
            "fixed_parameters": self.fixed,
            "notes": self.notes,
            "settings": self.settings.flat(),
            "plant": None if self.layout.learned is not None else self.plant().to_json(),
            "prediction_finish": None if self.prediction is None else self.prediction.to_json(),
            **({"rotor_laws": [r.to_json(self.layout) for r in self.rotor_laws]} if self.rotor_laws else {}),
        }

    def table(self) -> str:

        return format_table(self)
