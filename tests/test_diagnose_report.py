"""The ``--report DIR`` folder of a diagnosis (furuta_gym.diagnose._report.write_figures)."""

import dataclasses
import struct

import numpy as np
import pytest

import furuta_gym

furuta_gym.enable_x64()

from furuta_gym.diagnose import diagnose  # noqa: E402
from furuta_gym.diagnose._report import (  # noqa: E402
    REPORT_FILES,
    _plot_residual_vs_effect,
    residual_series,
    write_figures,
)
from furuta_gym.diagnose._result import EffectEvidence  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.rigs import measured_like  # noqa: E402

SIZE = dict(n_trajectories=6, duration=5.0)
FRICTION = [Effect("coulomb_friction", "alpha", 1e-3)]


@pytest.fixture(scope="module")
def res():
    data = measured_like("furuta", FRICTION, seed=1, **SIZE)
    test = measured_like("furuta", FRICTION, n_trajectories=2, duration=5.0, seed=101)
    return diagnose(data, "furuta", test=test)


def _png_size(path):
    """(width, height) from the PNG header; fails unless the file is a PNG."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR", path
    return struct.unpack(">II", head[16:24])


def _check_folder(paths, directory):
    assert [p.name for p in paths] == list(REPORT_FILES)
    for p in paths:
        assert p.parent == directory and p.exists()
        if p.suffix == ".png":
            w, h = _png_size(p)
            assert 300 <= w <= 2500 and 250 <= h <= 2500, (p.name, w, h)
            assert 10_000 < p.stat().st_size < 300_000, (p.name, p.stat().st_size)


def test_report_folder_holds_the_figures_and_the_table(res, tmp_path):
    assert any(e.significant and (e.name, e.joint) == ("coulomb_friction", "alpha") for e in res.effects)
    out = tmp_path / "report"
    paths = write_figures(res, out)
    _check_folder(paths, out)
    text = (out / "summary.txt").read_text()
    assert text == res.table() + "\n"
    assert "SIGNIFICANT" in text and "test-log errors" in text


def test_residual_series_after_is_smaller_on_the_test_logs(res):
    kept = [s.A for s in res._segments]
    before = residual_series(res, res._test_segments, "before")
    after = residual_series(res, res._test_segments, "after")
    assert len(before) == len(after) == len(res._test_segments)
    for (tb, rb), (ta, ra), seg in zip(before, after, res._test_segments, strict=True):
        assert np.array_equal(tb, ta) and rb.shape == ra.shape == (tb.size, 2)
        assert seg.t[0] < tb[0] < tb[-1] < seg.t[-1]
        assert np.array_equal(np.isnan(rb), np.isnan(ra))  # rest intervals are the same for both
    rms = lambda series, j: np.sqrt(np.nanmean(np.concatenate([r[:, j] for _, r in series]) ** 2))  # noqa: E731
    # the friction acts on the rotor: its residual drops a lot, the pendulum's does not grow
    assert rms(after, 0) < 0.5 * rms(before, 0)
    assert rms(after, 1) < 1.1 * rms(before, 1)
    # the result's own segments keep the regressors diagnose left in them
    assert all(a is s.A for a, s in zip(kept, res._segments, strict=True))
    with pytest.raises(ValueError, match="before"):
        residual_series(res, res._test_segments, "later")


def test_existing_report_is_never_overwritten(res, tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    # one existing target is enough: nothing at all is written
    (out / "summary.txt").write_text("mine\n")
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_figures(res, out)
    assert sorted(p.name for p in out.iterdir()) == ["summary.txt"]
    assert (out / "summary.txt").read_text() == "mine\n"
    paths = write_figures(res, out, overwrite=True)
    stamps = {p: p.stat().st_mtime_ns for p in paths}
    with pytest.raises(FileExistsError):
        write_figures(res, out)
    assert {p: p.stat().st_mtime_ns for p in paths} == stamps


def test_effects_without_a_column_do_not_break_the_figure(res, tmp_path):
    for name in ("actuator_lag", "made_up_effect"):
        ev = EffectEvidence(name, "u", 0.01, "s", True, 0.5, 5.0, "selected")
        fig = _plot_residual_vs_effect(dataclasses.replace(res, effects=[ev]))
        fig.savefig(tmp_path / f"{name}.png", dpi=60)
        assert (tmp_path / f"{name}.png").stat().st_size > 1000
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    assert any("no column" in t for t in texts)


def test_report_without_a_significant_effect(tmp_path):
    res = diagnose(measured_like("furuta", [], seed=1, **SIZE), "furuta")
    assert not res.significant and not res._test_segments
    out = tmp_path / "report"
    _check_folder(write_figures(res, out), out)
    assert "none: no effect is significant" in (out / "summary.txt").read_text()
