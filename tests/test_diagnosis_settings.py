"""The diagnosis' settings: one group per step, each knob named once across the groups."""

import dataclasses

import pytest

from furuta_gym.diagnose import DiagnosisSettings, diagnose
from furuta_gym.diagnose._settings import RestSettings


def test_every_knob_has_one_group_and_a_short_list_of_groups():
    groups = dataclasses.fields(DiagnosisSettings)
    sizes = [len(dataclasses.fields(getattr(DiagnosisSettings(), g.name))) for g in groups]
    assert len(groups) == 4
    assert len(DiagnosisSettings.knobs()) == sum(sizes) == 29  # no name in two groups
    assert max(sizes) <= 12


def test_a_knob_is_changed_by_its_name_alone_or_with_its_whole_group():
    s = DiagnosisSettings().replaced(z_threshold=4.0, held_stop=None, window=0.2)
    assert (s.search.z_threshold, s.rests.held_stop, s.output_error.window) == (4.0, None, 0.2)
    assert s.reading == DiagnosisSettings().reading  # the rest as it was
    whole = DiagnosisSettings().replaced(rests=RestSettings(rest_window=0.3), stop_dwell=0.04)
    assert (whole.rests.rest_window, whole.rests.stop_dwell, whole.rests.held_stop) == (0.3, 0.04, 2.0)
    assert DiagnosisSettings().replaced(**s.flat()) == s


def test_an_unknown_knob_is_one_error_that_lists_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown diagnosis settings \['z_treshold'\]; known: .*'z_threshold'"):
        DiagnosisSettings().replaced(z_treshold=4.0)
    with pytest.raises(ValueError, match="z_treshold"):
        diagnose([], "furuta", z_treshold=4.0)


def test_resolving_fills_the_systems_defaults_and_checks_ranges():
    s = DiagnosisSettings().resolved("furuta", 0.002)
    assert (s.search.interval, s.output_error.window) == (0.1, 0.5)
    assert s.reading.segment_seconds is not None and s.reading.segment_seconds > 0
    with pytest.raises(ValueError, match="start_iterations"):
        DiagnosisSettings().replaced(start_iterations=-1).resolved("furuta", 0.002)
