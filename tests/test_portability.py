"""Small portability guarantees: the headless GL default only where it is valid, MAT v7.3 files
give the package's data error."""

from __future__ import annotations

import numpy as np
import pytest

from furuta_gym.cli import headless_gl_default
from furuta_gym.data import DataError, load_trajectories


def test_egl_is_chosen_only_on_headless_linux_and_never_over_the_user():
    assert headless_gl_default({}, "linux") == {"MUJOCO_GL": "egl"}
    assert headless_gl_default({"DISPLAY": ":0"}, "linux") == {}
    assert headless_gl_default({"MUJOCO_GL": "osmesa"}, "linux") == {}
    assert headless_gl_default({}, "darwin") == {}
    assert headless_gl_default({}, "win32") == {}


def test_a_mat_v73_file_gets_one_clear_data_error(tmp_path):
    # a v7.3 MAT file is HDF5 with a MATLAB header; scipy refuses it with NotImplementedError
    path = tmp_path / "log.mat"
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    path.write_bytes(header.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM" + b"\x00" * 384)
    with pytest.raises(DataError, match=r"log\.mat: a MATLAB v7\.3"):
        load_trajectories(path, "nmsd")


def test_a_corrupt_mat_file_gets_a_data_error(tmp_path):
    path = tmp_path / "bad.mat"
    path.write_bytes(np.arange(10, dtype=np.uint8).tobytes())
    with pytest.raises(DataError, match=r"bad\.mat"):
        load_trajectories(path, "nmsd")
