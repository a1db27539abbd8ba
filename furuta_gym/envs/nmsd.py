"""``furuta_gym/NMSD-v0``: drive a nonlinear mass-spring-damper to a target position."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar, Mapping

import numpy as np

from ..effects import Effect
from ._base import LagrangianEnv
from ._settings import LEGACY_KEYWORDS, EnvArgumentError
from ._tasks import NMSDReach

__all__ = ["NMSDEnv", "Target", "DEFAULT_TARGET_RANGE"]

#: targets drawn by ``target="random"`` (m): the force limit holds the mass up to ~1.2 m
DEFAULT_TARGET_RANGE = (-1.0, 1.0)


@dataclasses.dataclass(frozen=True)
class Target:
    """The N-MSD task's settings (``task=Target(...)``): the ``position`` to reach in m (a number;
    ``"random"``: uniform in :data:`DEFAULT_TARGET_RANGE` at every reset; ``(low, high)``: uniform
    in that range per reset) and whether the agent sees it (``observe``: appended to the
    observation)."""

    position: float | str | tuple[float, float] = 0.5
    observe: bool = False

    def __post_init__(self):
        if isinstance(self.position, str) or (
            np.ndim(self.position) == 1 and not isinstance(self.position, (int, float))
        ):
            object.__setattr__(
                self, "position", self.position if isinstance(self.position, str) else _target_range(self.position)
            )
            _target_range(self.position)
        else:
            object.__setattr__(self, "position", _check_target(self.position, "Target.position"))
        if not isinstance(self.observe, (bool, np.bool_)):
            raise EnvArgumentError(f"Target.observe must be a bool, got {self.observe!r}")
        object.__setattr__(self, "observe", bool(self.observe))

    @property
    def range(self) -> tuple[float, float] | None:
        """(low, high) of a target drawn per reset; None for a fixed target."""
        return None if isinstance(self.position, float) else _target_range(self.position)


class NMSDEnv(LagrangianEnv):
    r"""Position a 1 kg mass on a hardening spring with nonlinear damping (Laiche et al. 2026, §5).

    ## Description
    m·p̈ = u − k1·p − k2·p³ − b1·ṗ − b2·ṗ³ with m = 1 kg, k1 = 10 N/m, k2 = 5 N/m³, b1 = 0.5 N·s/m,
    b2 = 0.1 N·s³/m³. The agent applies a force at 100 Hz to bring the mass to ``target`` and hold
    it there. ``dynamics=`` swaps the world as for ``Furuta-v0``.

    ## Action Space
    ``Box(-max_force, max_force, (1,), dtype)`` (max_force = ``Actuation.max_action``, default
    20 N), or ``Box(-1, 1, (1,), dtype)`` with ``Spaces(normalize_action=True)``.

    | Num | Action | Min        | Max       | Joint | Unit      |
    |-----|--------|------------|-----------|-------|-----------|
    | 0   | force  | −max_force | max_force | p     | force (N) |

    Out-of-range actions are clipped to ±max_force; NaN/inf raises ValueError.

    ## Observation Space
    ``Box(-inf, inf, (2,), dtype)`` (default float64), ``(3,)`` with ``Target(observe=True)``:

    | Num | Observation   | Min  | Max | Joint | Unit           |
    |-----|---------------|------|-----|-------|----------------|
    | 0   | position p    | -Inf | Inf | p     | position (m)   |
    | 1   | velocity ṗ    | -Inf | Inf | p     | velocity (m/s) |
    | 2   | target (only with ``Target(observe=True)``) | -Inf | Inf | | position (m) |

    The target is fixed per episode: ``task=Target(position)`` (m, default 0.5; ``"random"``:
    uniform in [−1, 1] m drawn at every reset from the env's seeded generator; ``(low, high)``:
    uniform in that range per reset) or ``reset(options={"target": ...})`` (overrides the draw
    for that episode). A random target needs ``Target(observe=True)`` for a policy to see it.
    ``Spaces.observation`` must be ``"raw"`` (no angle to wrap).

    ## Rewards
    :class:`furuta_gym.envs.NMSDReach`: at target tol(p − target, ±2 cm, margin 0.5 m) × small
    control (4 + tol(u/max_force))/5 × small velocity (1 + tol(ṗ, margin 1 m/s))/2, in [0, 1].

    ## Starting State
    At rest at p = 0 plus uniform noise of ``Episode.reset_noise_scale`` (default 0.01), or
    ``options={"state": [p, ṗ]}``.

    ## Episode End
    Terminated only on divergence (non-finite or |component| > 1e4, ``info["diverged"]``);
    truncated after ``Episode.seconds`` (default 10 s = 1 000 steps).

    ## Info
    ``time``, ``energy`` (½mṗ² + ½k1p² + ¼k2p⁴, J), ``diverged``, ``state``, ``action``,
    ``target``.

    ## Arguments
    The keywords of ``Furuta-v0`` (`dynamics`, `kernel`, `plant`, `task`, `episode`, `actuation`,
    `sensors`, `spaces`, `camera`, `render_mode`) with these differences:

    | Setting                      | Default       | Description |
    |------------------------------|---------------|-------------|
    | `task`                       | `Target()`    | `Target(position=0.5, observe=False)`: the target (m, `"random"` or `(low, high)`) and whether it is observed |
    | `Plant.presets`              | `()`          | `"coulomb"`, `"quadratic_drag"`, `"stiff_spring"`, `"weak_actuator"`, `"delay"` |
    | `Episode.frame_skip`         | `1`           | 10 ms RK4 steps per action (default 100 Hz) |
    | `Actuation.max_action`       | `20.0` (N)    | force limit; `Actuation.delay` is a multiple of 10 ms |
    | `Sensors.position_resolution`| `None`        | quantise the observed position (m); `encoder_counts` is refused (no angle) |

    The older plain keywords work as for ``Furuta-v0`` (with ``max_force=`` for the limit,
    ``target=`` and ``observe_target=`` for the ``Target``), each with a ``DeprecationWarning``.
    The batched JAX env supports neither a random target nor an observed one: with them
    ``make_vec`` gives a SyncVectorEnv of single envs.
    """

    system: ClassVar[str] = "nmsd"
    env_id: ClassVar[str] = "furuta_gym/NMSD-v0"
    vector_entry_point: ClassVar[str | None] = "furuta_gym.envs.vector:nmsd_vector_entry_point"
    action_limit_name: ClassVar[str] = "max_force"
    plant_presets: ClassVar[Mapping[str, tuple[Effect, ...]]] = {
        "nominal": (),
        "coulomb": (Effect("coulomb_friction", "p", 0.5),),
        "quadratic_drag": (Effect("quadratic_drag", "p", 0.3),),
        "stiff_spring": (Effect("spring", "p", 5.0),),
        "weak_actuator": (Effect("input_gain", "u", -0.2),),
        "delay": (Effect("input_delay", "u", 0.02),),
    }
    default_max_action: ClassVar[float] = 20.0
    task_settings_type: ClassVar[type | None] = Target
    legacy_keywords: ClassVar[Mapping[str, tuple[str, str]]] = {
        **LEGACY_KEYWORDS,
        "target": ("task", "position"),
        "observe_target": ("task", "observe"),
    }
    #: (low, high) of a random target per reset, None for a fixed target
    _target_range: tuple[float, float] | None = None
    reset_option_names: ClassVar[tuple[str, ...]] = ("state", "target")
    default_camera_config: ClassVar[dict] = {
        "distance": 2.8,
        "elevation": -25.0,
        "azimuth": 90.0,
        "lookat": (0.0, 0.0, 0.2),
    }

    def _configure(self) -> None:
        self.observe_target = self.task_settings.observe
        self._target_range = self.task_settings.range

    def _extra_observation_size(self) -> int:
        return 1 if self.observe_target else 0

    def _extra_observation(self) -> list[float]:
        return [self.task.target] if self.observe_target else []

    def _make_task(self):
        # a random target per reset: the middle of the range until the first reset
        target = self.task_settings.position if self._target_range is None else 0.5 * sum(self._target_range)
        return NMSDReach(target=target, max_force=self.max_action)

    def _options(self, options):
        target = options.get("target")
        if target is None and self._target_range is not None:
            target = float(self.np_random.uniform(*self._target_range))
        if target is not None:
            self.task = dataclasses.replace(self.task, target=_check_target(target, "options['target']"))

    def per_episode_state_features(self) -> list[str]:
        features = super().per_episode_state_features()
        if self._target_range is not None:
            features.append("a random target per reset (Target('random') or a range)")
        return features

    def presentation_options(self) -> list[str]:
        observed = ["Target(observe=True) (observe_target=True)"] if self.observe_target else []
        return super().presentation_options() + observed

    def _info(self, diverged):
        info = super()._info(diverged)
        info["target"] = self.task.target
        return info

    def _update_scene(self, model, data):
        model.site_pos[model.site("target").id, 0] = self.task.target


def _check_target(target: Any, name: str) -> float:
    try:
        value = float(target)
    except (TypeError, ValueError):
        value = math.nan
    if not abs(value) < 1e3:
        raise EnvArgumentError(f"{name} must be a finite position in m (|target| < 1000), got {target!r}")
    return value


def _target_range(target: Any) -> tuple[float, float]:
    """``"random"`` → :data:`DEFAULT_TARGET_RANGE`; ``(low, high)`` → itself, checked."""
    if isinstance(target, str):
        if target != "random":
            raise EnvArgumentError(f"target must be a position in m, 'random' or a (low, high) range, got {target!r}")
        return DEFAULT_TARGET_RANGE
    if len(target) != 2:
        raise EnvArgumentError(f"a target range must be (low, high) in m, got {target!r}")
    low, high = (_check_target(t, "target range bound") for t in target)
    if not low <= high:
        raise EnvArgumentError(f"a target range must have low <= high, got {target!r}")
    return (low, high)
