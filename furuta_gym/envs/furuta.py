"""``furuta_gym/Furuta-v0``: swing up and balance the Quanser QUBE-Servo 2 rotary pendulum."""

from __future__ import annotations

from typing import ClassVar, Mapping

from ..effects import Effect
from ._base import LagrangianEnv
from ._tasks import FurutaSwingUp

__all__ = ["FurutaEnv"]


class FurutaEnv(LagrangianEnv):
    r"""Swing-up and balance of a Furuta pendulum (Quanser QUBE-Servo 2; Laiche et al. 2026, §5).

    ## Description
    A DC motor turns a horizontal rotor arm (angle α about the vertical); a pendulum hangs from the
    arm's tip (angle β about the arm's axis, β = 0 hanging down, β = π upright, positive β moves
    the tip the way positive α moves the arm). The agent applies a motor voltage at 500 Hz to
    swing the pendulum up and balance it with the rotor near its start. The world is chosen by
    ``dynamics=``: the MuJoCo ground truth (default), the analytic model in JAX, a learned
    checkpoint, or any Lagrangian model — spaces, reward, ``info`` and rendering are the same.

    ## Action Space
    ``Box(-max_voltage, max_voltage, (1,), dtype)`` (max_voltage = ``Actuation.max_action``, default
    5 V; ``dtype`` default float64), or with ``Spaces(normalize_action=True)``
    ``Box(-1, 1, (1,), dtype)``: the action is a fraction of
    ``max_voltage`` (clipped to [−1, 1], then scaled; ``info["action"]`` is in volts).

    | Num | Action        | Min          | Max         | Joint | Unit        |
    |-----|---------------|--------------|-------------|-------|-------------|
    | 0   | motor voltage | −max_voltage | max_voltage | alpha | voltage (V) |

    Out-of-range actions are **clipped** to ±``max_voltage`` (default 5 V, the paper's limit;
    the hardware takes 10 V). A NaN or infinite action raises ``ValueError`` (a policy bug should
    not silently become a voltage). Positive voltage drives positive α.

    ## Observation Space
    Chosen by ``Spaces.observation`` (in ``Spaces.dtype``, default float64); always of the measured state
    (the true state unless ``sensors=`` says otherwise, see Arguments), while ``info["state"]`` is the
    true raw (α, β, α̇, β̇).

    ``"raw"`` (default): ``Box(-inf, inf, (4,))``, the state as integrated (α keeps
    counting turns).

    | Num | Observation                 | Min  | Max | Joint | Unit                     |
    |-----|-----------------------------|------|-----|-------|--------------------------|
    | 0   | rotor angle α               | -Inf | Inf | alpha | angle (rad)              |
    | 1   | pendulum angle β (0 = down) | -Inf | Inf | beta  | angle (rad)              |
    | 2   | rotor velocity α̇            | -Inf | Inf | alpha | angular velocity (rad/s) |
    | 3   | pendulum velocity β̇         | -Inf | Inf | beta  | angular velocity (rad/s) |

    ``"wrapped"``: ``Box((4,))``, angles wrapped to (−π, π].

    | Num | Observation       | Min  | Max | Unit    |
    |-----|-------------------|------|-----|---------|
    | 0   | α wrapped         | −π   | π   | rad     |
    | 1   | β wrapped (0 = down, ±π = up) | −π | π | rad |
    | 2   | α̇                 | −1e4 | 1e4 | rad/s   |
    | 3   | β̇                 | −1e4 | 1e4 | rad/s   |

    ``"trig"``: ``Box((6,))``, continuous across the wrap.

    | Num | Observation | Min  | Max | Unit  |
    |-----|-------------|------|-----|-------|
    | 0   | cos α       | −1   | 1   |       |
    | 1   | sin α       | −1   | 1   |       |
    | 2   | cos β       | −1   | 1   | (−1 = up) |
    | 3   | sin β       | −1   | 1   |       |
    | 4   | α̇           | −1e4 | 1e4 | rad/s |
    | 5   | β̇           | −1e4 | 1e4 | rad/s |

    The velocity bounds are ``task.state_bound`` (a larger true velocity ends the episode as a
    divergence; with sensor noise the observed velocity is clipped to them).

    ## Rewards
    dm_control style, a product of smooth factors in [0, 1] on the true next state
    (:class:`furuta_gym.envs.FurutaSwingUp`): upright (1 − cos β)/2 × centred
    (1 + tol(wrap(α), margin π/2))/2 with α wrapped to (−π, π] (2π-periodic) × small control (4 + tol(u/max_voltage))/5 × small velocity
    (1 + tol(β̇, margin 5 rad/s))/2. 1 only upright, at rest, centred, with no voltage; 0 hanging.

    ## Starting State
    Hanging at rest plus uniform noise in [−s, s] on all four components
    (s = ``Episode.reset_noise_scale``, default 0.01), or exactly ``reset(options={"state": [α, β, α̇, β̇]})``.

    ## Episode End
    * Termination: only on **divergence** — a non-finite state or a velocity beyond
      ``task.state_bound`` = 1e4 rad/s (angles are not bounded: the rotor may turn for ever, only
      a non-finite angle diverges): ``terminated=True``, ``info["diverged"]=True``,
      and the observation is the last good one (no NaN ever leaves the env; stepping further
      keeps returning it).
    * Truncation: after ``Episode.seconds`` (default 10 s = 5 000 steps at 500 Hz).

    ## Info
    ``time`` (s), ``energy`` (J, T + V of the paper's model at the plant's parameters),
    ``diverged`` (bool), ``state`` (true (α, β, α̇, β̇), useful with sensor options),
    ``action`` (the clipped voltage commanded this step).

    ## Arguments (``gymnasium.make("furuta_gym/Furuta-v0", **kwargs)``)
    The same keywords for every system and for the batched env; settings are objects from
    :mod:`furuta_gym.envs` (frozen, each field checked when the object is built):

    | Keyword       | Type                 | Default        | Description |
    |---------------|----------------------|----------------|-------------|
    | `dynamics`    | str / model          | `"mujoco"`     | `"mujoco"`, `"analytic"`, a checkpoint path, or an `AbstractLagrangianSystem` |
    | `kernel`      | str                  | `"auto"`       | model backends: `"c"` (the JAX step lowered to C), `"xla"` (jitted), `"auto"` (C when a compiler exists); docs/envs.md |
    | `plant`       | `Plant` / str / list | `Plant()`      | the device: presets, extra effects, randomisation (below); `plant="coulomb"` is short for `Plant("coulomb")`; a diagnosis (`plant=res`), its JSON or its MJCF gives the diagnosed rig (`env.plant.source` says which) |
    | `task`        | None                 | `None`         | the swing-up has no task settings (N-MSD: `Target`) |
    | `episode`     | `Episode`            | `Episode()`    | control period, horizon, start noise |
    | `actuation`   | `Actuation`          | `Actuation()`  | action limit and input delay |
    | `sensors`     | `Sensors`            | `Sensors()`    | encoder quantisation, noise, velocity (default: the true state) |
    | `spaces`      | `Spaces`             | `Spaces()`     | observation layout, dtype, normalised action |
    | `camera`      | `Camera`             | `Camera()`     | frame size |
    | `render_mode` | str / None           | `None`         | `"rgb_array"` or `"human"` |

    | Field                                | Default     | Description |
    |--------------------------------------|-------------|-------------|
    | `Plant.presets`                      | `()`        | preset name(s): `"cable_spring"`, `"coulomb"`, `"quadratic_drag"`, `"weak_motor"`, `"delay"` |
    | `Plant.effects`                      | `()`        | extra `furuta_gym.effects.Effect`s on the plant (any backend) |
    | `Plant.randomize`                    | `None`      | per reset: relative spread for all parameters (not g) or `{name: spread}` |
    | `Episode.frame_skip`                 | `1`         | 2 ms RK4 steps per action: control period = 2 ms × frame_skip (500 Hz) |
    | `Episode.seconds`                    | `10.0`      | truncation time in s (None: never) |
    | `Episode.reset_noise_scale`          | `0.01`      | uniform start noise (rad, rad/s) |
    | `Actuation.max_action`               | `5.0` (V)   | action limit; actions are clipped to it |
    | `Actuation.delay`, `.delay_steps`    | `0.0`, `0`  | input delay in s (a multiple of 2 ms) plus whole control periods |
    | `Sensors.encoder_counts`             | `None`      | quantise observed angles to 2π/counts (hardware: 2048) |
    | `Sensors.position_resolution`        | `None`      | quantise non-angular joints (none here: the Furuta has encoders) |
    | `Sensors.measurement_noise`          | `0.0`       | Gaussian std, scalar or one per component (4,) |
    | `Sensors.velocity`                   | `"exact"`   | `"filter"`: the paper's derivative filter on the measured angles |
    | `Spaces.observation`                 | `"raw"`     | `"raw"`, `"wrapped"` or `"trig"`; see Observation Space |
    | `Spaces.dtype`                       | `"float64"` | dtype of both spaces and the observations (physics always float64) |
    | `Spaces.normalize_action`            | `False`     | `True`: actions in [−1, 1], scaled to ±max_action |
    | `Camera.width`, `.height`            | `480`       | frame size in pixels |

    For example ``gymnasium.make("furuta_gym/Furuta-v0", sensors=Sensors(encoder_counts=2048,
    velocity="filter"), actuation=Actuation(max_action=3.0))``. The older plain keywords
    (``max_voltage=``, ``frame_skip=``, ``episode_seconds=``, ``reset_noise_scale=``, ``effects=``,
    ``randomize=``, ``encoder_counts=``, ``position_resolution=``, ``measurement_noise=``,
    ``velocity=``, ``actuation_delay=``, ``actuation_delay_steps=``, ``observation=``,
    ``normalize_action=``, ``dtype=``, ``width=``, ``height=``) still work: each sets its field,
    on top of the objects given, with a ``DeprecationWarning`` naming the new spelling.

    Documented warnings of ``gymnasium.utils.env_checker.check_env`` with the defaults: the
    infinite observation bounds (the raw state is unbounded) and "we recommend using a symmetric
    and normalized space" (the action is in volts by design); ``Spaces("trig")`` (or
    ``"wrapped"``) with ``normalize_action=True`` has none.

    ## RL preset ``furuta_gym/FurutaSwingUp-v0``
    This env with ``episode=Episode(frame_skip=10, seconds=None)`` (50 Hz,
    ``metadata["render_fps"]`` = 50, one frame per control period; the 500-step (10 s) horizon is
    Gymnasium's ``max_episode_steps``) and ``spaces=Spaces("trig", "float32",
    normalize_action=True)``. Any keyword overrides it (an older plain keyword sets its one field).
    ``render_mode="human"`` needs a display; without
    one (DISPLAY/WAYLAND_DISPLAY unset on Linux) the constructor raises a clear ValueError rather
    than letting GLFW abort the process, so run ``check_env(..., skip_render_check=True)``
    headless.
    """

    system: ClassVar[str] = "furuta"
    env_id: ClassVar[str] = "furuta_gym/Furuta-v0"
    vector_entry_point: ClassVar[str | None] = "furuta_gym.envs.vector:furuta_vector_entry_point"
    default_max_action: ClassVar[float] = 5.0
    action_limit_name: ClassVar[str] = "max_voltage"
    # magnitudes visible within a few seconds that leave the pendulum controllable
    plant_presets: ClassVar[Mapping[str, tuple[Effect, ...]]] = {
        "nominal": (),
        # the encoder/motor cable pulls the rotor back towards its mounting angle
        "cable_spring": (Effect("spring", "alpha", 2e-3),),
        # dry friction on both bearings, applied as an honest −F·sgn(q̇) law
        "coulomb": (Effect("coulomb_friction", "alpha", 1e-3), Effect("coulomb_friction", "beta", 1e-4)),
        # aerodynamic drag on the swinging pendulum
        "quadratic_drag": (Effect("quadratic_drag", "beta", 2e-6),),
        # the motor produces 20 % less torque than its data sheet says
        "weak_motor": (Effect("input_gain", "u", -0.2),),
        # 4 ms of transport delay on the voltage (two control periods at 500 Hz)
        "delay": (Effect("input_delay", "u", 0.004),),
    }
    default_camera_config: ClassVar[dict] = {
        "distance": 0.42,
        "elevation": -20.0,
        "azimuth": 135.0,
        "lookat": (0.0, 0.0, 0.09),
    }

    def _make_task(self):
        return FurutaSwingUp(max_voltage=self.max_action)
