"""Test-wide setup: float64 switched on explicitly (as the README tells users), headless GL."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
# the training commands turn on a persistent compilation cache in ~/.cache: tests stay hermetic
os.environ.setdefault("FURUTA_GYM_COMPILATION_CACHE", "0")

import furuta_gym  # noqa: E402

furuta_gym.enable_x64()
