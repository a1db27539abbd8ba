"""Test-wide setup: float64 switched on explicitly (as the README tells users), headless GL."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import furuta_gym  # noqa: E402

furuta_gym.enable_x64()
