"""Settings objects renamed to ``*Settings`` (CONTRIBUTING.md, "Conventions"): each old public name
still imports, as the object it was renamed to, with one DeprecationWarning naming the new name."""

import importlib
import warnings

import pytest

from furuta_gym._deprecated import MOVED, RENAMED
from furuta_gym.sensors import Sensors

OLD_NAMES = [(module, old) for module, names in RENAMED.items() for old in names]


@pytest.mark.parametrize(("module", "old"), OLD_NAMES)
def test_old_name_serves_the_new_object_with_one_warning(module, old):
    mod = importlib.import_module(module)
    target, instead = RENAMED[module][old]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        served = getattr(mod, old)
    assert served is getattr(mod, target)
    assert [w.category for w in caught] == [DeprecationWarning]
    assert instead in str(caught[0].message) and old in str(caught[0].message)
    assert old not in mod.__all__ and (target.startswith("_") or target in mod.__all__)


@pytest.mark.parametrize(("module", "name"), [(m, n) for m, names in MOVED.items() for n in names])
def test_a_moved_name_serves_the_object_of_its_new_module_with_one_warning(module, name):
    mod, where = importlib.import_module(module), MOVED[module][name]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        served = getattr(mod, name)
    assert served is getattr(importlib.import_module(where), name)
    assert [w.category for w in caught] == [DeprecationWarning]
    assert f"use {where}.{name}" in str(caught[0].message)
    assert name not in mod.__all__


def test_from_import_of_an_old_name_warns_at_the_importer():
    with pytest.warns(DeprecationWarning, match="use TrainSettings") as record:
        from furuta_gym.training import TrainConfig  # noqa: F401
    assert record[0].filename == __file__


def test_unknown_names_are_still_attribute_errors():
    import furuta_gym.rl

    with pytest.raises(AttributeError, match="no attribute 'PPOConfigs'"):
        _ = furuta_gym.rl.PPOConfigs  # pyright: ignore[reportAttributeAccessIssue]


def test_the_old_sensor_options_read_as_the_one_sensor_model():
    """An old manifest's ``"sensor"`` record (the options' fields) reads as the Sensors it meant."""
    from furuta_gym.training.datagen import read_sensor_record, sensor_record

    old = {
        "quantize": True,
        "noise_std": 0.0,
        "velocity": "filter",
        "velocity_noise_std": 0.0,
        "sensor_rate_hz": 500.0,
        "filter_omega0": 100.0,
        "filter_xi": 0.8,
        "counts_per_rev": 2048,
    }
    sensors, rate = read_sensor_record(old)
    assert rate == 500.0
    assert sensors == Sensors.qube(measurement_noise=(0.0, 0.0))
    new = Sensors(position_resolution=1e-4, measurement_noise=(1e-3, 2e-3, 0.0, 0.1))
    assert read_sensor_record(sensor_record(new, 1000.0)) == (new, 1000.0)


def test_every_committed_manifest_still_reads_its_sensor():
    import json
    from pathlib import Path

    from furuta_gym.training.datagen import read_sensor_record

    manifests = sorted((Path(__file__).resolve().parent.parent / "results").rglob("manifest.json"))
    records = [json.loads(p.read_text()).get("sensor") for p in manifests]
    assert sum(r is not None for r in records) >= 10
    for path, record in zip(manifests, records, strict=True):
        if record is not None:
            sensors, rate = read_sensor_record(record)
            assert isinstance(sensors, Sensors) and rate == 500.0, path
