"""Rendering an env: the system's MJCF scene posed at the backend's state, whatever the backend."""

from __future__ import annotations

import os
import sys
from typing import Any, Callable, Mapping, Sequence

import gymnasium

from ._settings import Camera, EnvArgumentError

__all__ = ["check_render_mode", "SceneRenderer"]


def check_render_mode(render_mode: str | None, modes: Sequence[str]) -> str | None:
    """``render_mode`` if it is None or one of ``modes`` and can open here, else an EnvArgumentError."""
    if render_mode is not None and render_mode not in modes:
        raise EnvArgumentError(f"render_mode must be None or one of {list(modes)}, got {render_mode!r}")
    if (
        render_mode == "human"
        and sys.platform.startswith("linux")
        and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    ):
        # GLFW would abort the whole process (an assertion in C) without a display
        raise EnvArgumentError(
            "render_mode='human' opens a window and needs a display (DISPLAY/WAYLAND_DISPLAY "
            "are unset); use render_mode='rgb_array' on a headless machine"
        )
    return render_mode


class SceneRenderer:
    """Frames of a backend's MuJoCo scene through Gymnasium's MuJoCo renderer, made on first use
    and remade when the backend's scene is another model."""

    def __init__(self, camera: Camera, camera_config: Mapping[str, Any]):
        self.camera, self.camera_config = camera, dict(camera_config)
        self._renderer = None

    def render(self, backend, render_mode: str | None, update_scene: Callable) -> Any:
        """An (height, width, 3) uint8 frame ("rgb_array") or a window ("human")."""
        if render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' to gymnasium.make"
            )
            return None
        model, data = backend.scene()
        update_scene(model, data)
        if self._renderer is None or self._renderer.model is not model:
            from gymnasium.envs.mujoco.mujoco_rendering import MujocoRenderer  # noqa: PLC0415  a window's GL context only when one is shown

            self.close()
            self._renderer = MujocoRenderer(
                model, data, dict(self.camera_config), self.camera.width, self.camera.height
            )
        return self._renderer.render(render_mode)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
