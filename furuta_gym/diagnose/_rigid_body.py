"""The rigid-body check of a diagnosis: fitted lumped values that no rigid bodies have (MuJoCo
refuses such a plant) are refitted with one parameter held at its declared value, when the data
do not contradict it."""

from __future__ import annotations

from ..models import system_definition
from ._result import DiagnosisResult

#: A refit with one lumped parameter held at its declared value replaces a fit whose values no
#: rigid bodies have when its held-out error is at most this much larger.
RIGID_BODY_TOLERANCE = 0.05


def _with_rigid_bodies(result: "DiagnosisResult", refit) -> "DiagnosisResult":
    """``result``, or, when its fitted values have no rigid bodies (MuJoCo refuses the plant), the
    refit with the failed condition's least determined parameter held at its declared value, if
    that predicts the held-out data as well (:data:`RIGID_BODY_TOLERANCE`). Said in the notes."""
    definition = system_definition(result.system)
    if definition.body_conditions is None:
        return result
    failed = [c for c in definition.body_conditions(result.parameters_after) if not c.holds]
    free = [p for p in failed[0].parameters if p not in result.fixed] if failed else []
    if not free:
        return result
    held = max(free, key=lambda name: _relative_uncertainty(result, name))
    declared = definition.lumped.nominal()[held]
    unit = result.parameter_units.get(held, "")
    again = refit({held: declared})
    worse = again.error_after.trajectory_rmse / result.error_after.trajectory_rmse
    why = (
        f"fitted free, {held} = {result.parameters_after[held]:.4g} {unit} gives {failed[0].expression} = "
        f"{failed[0].value:.3g} ≤ 0, which no rigid bodies have (MuJoCo refuses such a plant)"
    )
    if worse <= 1.0 + RIGID_BODY_TOLERANCE and not any(
        not c.holds for c in definition.body_conditions(again.parameters_after)
    ):
        again.notes.append(
            f"{held}: held at its declared value {declared:.4g} {unit}, which the data do not "
            f"contradict: {why}; held-out error {again.error_after.trajectory_rmse:.4g} held, "
            f"{result.error_after.trajectory_rmse:.4g} free"
        )
        return again
    result.notes.append(
        f"{why}; holding {held} at its declared value predicts the held-out data {worse:.2f}× "
        "as badly, so the fit stands: its plant runs on dynamics='analytic' only"
    )
    return result


def _relative_uncertainty(result: "DiagnosisResult", name: str) -> float:
    """The 95 % half-width of ``name`` relative to its value (inf: unbounded or not reported)."""
    interval = result.intervals.get(name)
    value = abs(result.parameters_after[name])
    if interval is None or value == 0:
        return float("inf")
    return 0.5 * (interval.upper - interval.lower) / value
