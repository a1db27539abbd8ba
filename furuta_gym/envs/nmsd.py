"""``furuta_gym/NMSD-v0``: drive a nonlinear mass-spring-damper to a target position."""

from __future__ import annotations

from typing import ClassVar

from ._base import EnvArgumentError, LagrangianEnv
from ._tasks import NMSDReach

__all__ = ["NMSDEnv"]


class NMSDEnv(LagrangianEnv):
    r"""Position a 1 kg mass on a hardening spring with nonlinear damping (Laiche et al. 2026, §5).

    ## Description
    m·p̈ = u − k1·p − k2·p³ − b1·ṗ − b2·ṗ³ with m = 1 kg, k1 = 10 N/m, k2 = 5 N/m³, b1 = 0.5 N·s/m,
    b2 = 0.1 N·s³/m³. The agent applies a force at 100 Hz to bring the mass to ``target`` and hold
    it there. ``dynamics=`` swaps the world as for ``Furuta-v0``.

    ## Action Space
    ``Box(-max_force, max_force, (1,), float64)``

    | Num | Action | Min        | Max       | Joint | Unit      |
    |-----|--------|------------|-----------|-------|-----------|
    | 0   | force  | −max_force | max_force | p     | force (N) |

    Out-of-range actions are clipped to ±``max_force`` (default 20 N); NaN/inf raises ValueError.

    ## Observation Space
    ``Box(-inf, inf, (2,), float64)``:

    | Num | Observation   | Min  | Max | Joint | Unit           |
    |-----|---------------|------|-----|-------|----------------|
    | 0   | position p    | -Inf | Inf | p     | position (m)   |
    | 1   | velocity ṗ    | -Inf | Inf | p     | velocity (m/s) |

    The target is fixed per episode (``target`` kwarg or ``reset(options={"target": ...})``)
    and not part of the observation.

    ## Rewards
    :class:`furuta_gym.envs.NMSDReach`: at target tol(p − target, ±2 cm, margin 0.5 m) × small
    control (4 + tol(u/max_force))/5 × small velocity (1 + tol(ṗ, margin 1 m/s))/2, in [0, 1].

    ## Starting State
    At rest at p = 0 plus uniform noise of ``reset_noise_scale`` (default 0.01), or
    ``options={"state": [p, ṗ]}``.

    ## Episode End
    Terminated only on divergence (non-finite or |component| > 1e4, ``info["diverged"]``);
    truncated after ``episode_seconds`` (default 10 s = 1 000 steps).

    ## Info
    ``time``, ``energy`` (½mṗ² + ½k1p² + ¼k2p⁴, J), ``diverged``, ``state``, ``action``,
    ``target``.

    ## Arguments
    As ``Furuta-v0`` (``dynamics``, ``kernel``, ``frame_skip`` — 10 ms RK4 steps, default 1 = 100 Hz —,
    ``episode_seconds``, ``reset_noise_scale``, ``plant`` — ``"coulomb"``, ``"quadratic_drag"``,
    ``"stiff_spring"``, ``"weak_actuator"``, ``"delay"`` —, ``effects``, ``randomize``,
    ``position_resolution`` (m), ``measurement_noise``, ``velocity``, ``actuation_delay``
    (a multiple of 10 ms), ``actuation_delay_steps``, ``render_mode``, ``width``, ``height``),
    with ``max_force`` (N, default 20) instead of ``max_voltage``, and ``target`` (m, default 0.5).
    """

    system: ClassVar[str] = "nmsd"
    default_frame_skip: ClassVar[int] = 1
    default_episode_seconds: ClassVar[float] = 10.0
    action_limit_name: ClassVar[str] = "max_force"
    default_action_limit: ClassVar[float] = 20.0
    task_defaults: ClassVar[dict] = {"target": 0.5}
    reset_option_names: ClassVar[tuple[str, ...]] = ("state", "target")
    default_camera_config: ClassVar[dict] = {
        "distance": 2.8,
        "elevation": -25.0,
        "azimuth": 90.0,
        "lookat": (0.0, 0.0, 0.2),
    }

    def _make_task(self, target):
        target = float(target)
        if not abs(target) < 1e3:
            raise EnvArgumentError(f"target must be a finite position in m, got {target!r}")
        return NMSDReach(target=target, max_force=self.max_action)

    def _options(self, options):
        if options.get("target") is not None:
            self._task_kwargs = {"target": options["target"]}
            self.task = self._make_task(**self._task_kwargs)

    def _energy(self, x):
        if not hasattr(self, "_p"):
            self._p = self.physical_parameters()
        p = self._p
        pos, vel = x
        return 0.5 * p["m"] * vel * vel + 0.5 * p["k1"] * pos * pos + 0.25 * p["k2"] * pos**4

    def _on_parameters(self, p):
        self._p = p

    def _info(self, diverged):
        info = super()._info(diverged)
        info["target"] = self.task.target
        return info

    def _update_scene(self, model, data):
        model.site_pos[model.site("target").id, 0] = self.task.target
