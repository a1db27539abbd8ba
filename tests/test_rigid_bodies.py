"""A diagnosis whose fitted lumped values no rigid bodies have (MuJoCo refuses the plant) holds the
least determined parameter of the failed condition at its declared value, when the held-out data
allow it, and says so; otherwise the fit stands and the note says why."""

import dataclasses
import types

import pytest

from furuta_gym.diagnose._intervals import Interval
from furuta_gym.diagnose._rigid_body import _with_rigid_bodies
from furuta_gym.models import system_definition

NOMINAL = system_definition("furuta").lumped.nominal()


def _result(error: float, **changes):
    params = {**NOMINAL, **changes}
    intervals = {k: Interval(0.9 * v, 1.1 * v, "output_error") for k, v in params.items()}
    intervals["J1b"] = Interval(-5e-5, 4.3e-4, "output_error")  # balancing logs hardly see J1b
    return types.SimpleNamespace(
        system="furuta",
        parameters_after=params,
        fixed={"G": NOMINAL["G"]},
        intervals=intervals,
        parameter_units={"J1b": "kg m^2"},
        notes=[],
        error_after=types.SimpleNamespace(trajectory_rmse=error),
    )


def test_an_unrealizable_fit_gets_its_least_determined_parameter_held_when_the_data_allow():
    free = _result(0.0045, J1b=1.9e-4)  # above J2 = 1.33e-4: no rigid pendulum
    asked = []

    def refit(held):
        asked.append(held)
        return _result(0.00443, **held)

    got = _with_rigid_bodies(free, refit)
    assert asked == [{"J1b": pytest.approx(NOMINAL["J1b"])}]
    assert got.parameters_after["J1b"] == NOMINAL["J1b"]
    assert "J1b: held at its declared value" in got.notes[0] and "J2 - J1b" in got.notes[0]


def test_the_fit_stands_when_holding_the_parameter_predicts_worse():
    free = _result(0.0045, J1b=1.9e-4)
    got = _with_rigid_bodies(free, lambda held: _result(0.0060, **held))
    assert got is free and got.parameters_after["J1b"] == 1.9e-4
    assert "1.33× as badly" in got.notes[0] and "dynamics='analytic' only" in got.notes[0]


def test_a_realizable_fit_is_never_refitted():
    free = _result(0.0045, J1=3.5e-4)
    assert _with_rigid_bodies(free, lambda held: pytest.fail("refitted")) is free


def test_the_bodies_condition_names_what_fails():
    conditions = system_definition("furuta").body_conditions({**NOMINAL, "J1b": 1.9e-4})
    failed = [dataclasses.astuple(c)[0] for c in conditions if not c.holds]
    assert failed == ["J2 - J1b"]
    assert all(c.holds for c in system_definition("furuta").body_conditions(NOMINAL))
