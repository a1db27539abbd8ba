"""Residual diagnosis of measured data: fit, residual, trace the missing effect, refit, report.

``diagnose(data, system)`` fits the declared analytic model's lumped parameters (equation error on
the integral inverse residual, refined by output error), tests a library of candidate effects
(:mod:`furuta_gym.effects`) against the residual on held-out data, adds the significant ones,
refits and reports the held-out errors before and after; ``finish="prediction"`` also refits the
final model for prediction beside the report. See ``docs/diagnose.md``.
"""

from .._deprecated import deprecated_names
from ._diagnose import diagnose
from ._drift import REST_LAWS, Rest, RestDrift, rest_drift
from ._finish import PredictionFinish
from ._fit import InputDynamics
from ._library import Candidate, LumpedModel, layout_for, nominal_base
from ._report import write_figures as write_report_figures, write_json as write_report_json
from ._rests import RestBound, Stop, held_at_rest, stop_excursions
from ._result import DiagnosisResult, EffectEvidence, ErrorSummary
from ._settings import DiagnosisSettings

__all__ = [
    "diagnose",
    "DiagnosisResult",
    "DiagnosisSettings",
    "EffectEvidence",
    "ErrorSummary",
    "InputDynamics",
    "PredictionFinish",
    "LumpedModel",
    "Candidate",
    "layout_for",
    "nominal_base",
    "held_at_rest",
    "RestBound",
    "Stop",
    "stop_excursions",
    "rest_drift",
    "RestDrift",
    "Rest",
    "REST_LAWS",
    "write_report_figures",
    "write_report_json",
]

__getattr__ = deprecated_names(__name__)  # measured_like and the rigs moved to furuta_gym.rigs
