"""Simulated rigs and the logs they give: measured-like datasets with a known undeclared effect,
for tests, demos, benchmarks and trying a diagnosis (:func:`furuta_gym.diagnose.diagnose`) on a
rig whose truth is known.

The plant is the MuJoCo ground truth with the effects written into it
(:class:`furuta_gym.envs.MujocoBackend`, a plant variant; Coulomb friction and stiction
as the exact sgn law, an actuator lag as MuJoCo's actuator dynamics) — or, with
``plant="analytic"``, the analytic model plus :class:`furuta_gym.effects.WithEffects` (dry
friction smoothed by tanh(v/1e-3)) and :class:`furuta_gym.effects.ActuatorLag` — integrated with
RK4 and the input held over each sample period, as a digital controller drives hardware. An input
delay is the plant seeing the command whole samples late. What the user would log is then
produced: encoder-quantised angles at 500 Hz for the Furuta (2048 counts/rev), positions with
small Gaussian noise at 100 Hz for the N-MSD; no velocities.

Experiments (``excitation=``):

* ``"chirp"`` (default): random initial states and a random chirp input (both systems).
* ``"sine_sweep"`` (Furuta): from near rest, hanging, one open-loop sine of random amplitude and
  frequency, switched off for rest periods: with dry friction against a cable spring the rotor
  comes to rest off zero and sticks there.
* ``"sticky_sweep"`` (Furuta): open-loop sine sweeps of 10 s segments at 0.3–1.1 V and 1–20 Hz,
  pendulum hanging, in which a rotor held by dry friction mostly repeats its encoder count: every
  third segment is a large swing followed by a slow low-amplitude chirp (the rotor left off the
  cable's neutral creeps and oscillates around where the swing left it), the others chirps of
  random amplitude and band (at high frequency the rotor moves a few counts in all). The segments
  are one rig's, recorded one after another: each starts near zero, and a cable whose neutral
  moves remembers where the last one left it, as in ``"rotor_releases"``.
* ``"rotor_releases"`` (Furuta): at 0 V, pendulum hanging, the rotor carried 0.5–2 rad (either
  sign) from where it rests and let go from rest, once per trajectory; the trajectories are one
  rig's releases in order (the hand is not simulated, but a cable whose neutral moves remembers
  where it carried the rotor: :meth:`MujocoBackend.move`).
* ``"closed_loop_prbs"`` (Furuta): upright balancing as in the MIT rig logs: a PD controller on
  the quantised angles tracking a rotor reference that ramps back and forth and a ±0.01 rad
  pendulum reference, plus a ±0.5 V feed-forward, saturated at ±10 V. The logged u is the plant
  input, so it correlates with the measurement (quantisation) noise, as closed-loop data do.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from typing import Mapping, Sequence

import jax
import numpy as np
from scipy.signal import lfilter

from ._x64 import ensure_x64
from .data import Trajectory
from .effects import ActuatorLag, Effect, WithEffects, actuator_lag_time
from .envs import MujocoBackend
from .models import SYSTEM_DEFINITIONS, analytic_model, system_definition
from .signals import ENCODER_COUNTS_PER_REV, chirp, quantize_encoder
from .simulate import rk4_zoh_step, rollout_zoh

__all__ = [
    "measured_like",
    "sticky_rig",
    "moving_rest_rig",
    "breakaway_rig",
    "ClosedLoopBalancing",
    "EXCITATIONS",
    "BALANCE_GAINS",
]

EXCITATIONS = ("chirp", "sine_sweep", "sticky_sweep", "rotor_releases", "closed_loop_prbs")

#: experiments whose trajectories are one rig's, recorded one after another: a cable whose neutral
#: moves remembers where the rotor was carried between them, as the diagnosis reads such logs
RECORDED_BACK_TO_BACK = ("sticky_sweep", "rotor_releases")
#: rad: the rotor is carried no further from zero than this (a cable limits its travel)
RELEASE_TRAVEL = 2.5

#: the MIT rig logs' balance gains (their alpha = 0 upright), V/rad and V·s/rad. In our convention
#: u = kp_theta·α + kd_theta·α̇ − kp_alpha·(β − π) − kd_alpha·β̇: of the 16 sign patterns the only
#: one whose linearised loop is stable (eigenvalues −10.6 ± 18.6j, −10.2, −7.3).
BALANCE_GAINS = {"kp_theta": 6.0, "kd_theta": 1.8, "kp_alpha": 30.0, "kd_alpha": 2.5}


def _inputs(system: str, t: np.ndarray, rng: np.random.Generator, forced: bool) -> np.ndarray:
    if not forced:
        return np.zeros_like(t)
    amplitude, start, end, offset_range = system_definition(system).chirp_ranges
    amp = rng.uniform(*amplitude)
    f0, f1 = rng.uniform(*start), rng.uniform(*end)
    offset = 0.0 if offset_range is None else rng.uniform(*offset_range)
    return offset + chirp(t, f0, f1, t[-1], amplitude=amp, phase=rng.uniform(0, 2 * np.pi))


def _sine_with_rests(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One sine (0.3–2 V, 0.2–3 Hz), on for 60–80 % of each 3–8 s cycle (at most the record)
    and 0 V for the rest: in the pauses a rotor with dry friction against a cable spring stops
    off zero and sticks, once the pendulum's swing no longer drags it (hence pauses of ~1–3 s).

    The sine is switched at its zero crossings only (whole half-periods), so switching kicks
    neither rotor nor pendulum: the rotor stops where the voltage left it, near its excursion.
    """
    amp, freq, phase = rng.uniform(0.3, 2.0), rng.uniform(0.2, 3.0), rng.uniform(0, 2 * np.pi)
    cycle, duty = min(rng.uniform(3.0, 8.0), t[-1]), rng.uniform(0.6, 0.8)
    angle = 2 * np.pi * freq * t + phase
    half_start = np.maximum((np.floor(angle / np.pi) * np.pi - phase) / (2 * np.pi * freq), 0.0)
    on = (half_start % cycle) < duty * cycle
    return np.where(on, amp * np.sin(angle), 0.0)


def _sticky_segment(t: np.ndarray, rng: np.random.Generator, swing: bool) -> np.ndarray:
    """One ``sticky_sweep`` segment (see :func:`measured_like`): a swing-then-creep segment, or a
    linear chirp of 0.3–1.1 V between two frequencies in 1–20 Hz."""
    if not swing:
        f0, f1 = np.sort(rng.uniform(1.0, 20.0, 2))
        return chirp(t, f0, f1, t[-1], amplitude=rng.uniform(0.3, 1.1), phase=rng.uniform(0, 2 * np.pi))
    # whole periods of a 1–1.5 Hz swing at 0.9–1.1 V, then a 1–3 Hz chirp at 0.3–0.6 V
    f_swing = rng.uniform(1.0, 1.5)
    swing_end = np.ceil(rng.uniform(2.0, 3.5) * f_swing) / f_swing
    pause = rng.uniform(0.5, 1.0)
    slow = t - swing_end - pause
    f0, f1 = rng.uniform(1.0, 1.5), rng.uniform(2.0, 3.0)
    creep = chirp(slow, f0, f1, t[-1] - swing_end - pause, amplitude=rng.uniform(0.3, 0.6))
    big = rng.uniform(0.9, 1.1) * np.sin(2 * np.pi * f_swing * t)
    return np.where(t < swing_end, big, np.where(slow >= 0, creep, 0.0))


def sticky_rig(seed: int) -> list[Effect]:
    """A rotor that sticks, drawn from ``seed`` (for ``excitation="sticky_sweep"``): Coulomb
    friction 3e-4–8e-4 N·m with a breakaway 2–3× that level (stiction ΔF = breakaway − Coulomb)
    and a cable spring of 1.5e-3–2.5e-3 N·m/rad whose rest position is within ±0.1 rad."""
    rng = np.random.default_rng([seed, 43])
    coulomb, breakaway = rng.uniform(3e-4, 8e-4), rng.uniform(2.0, 3.0)
    return [
        Effect("spring", "alpha", rng.uniform(1.5e-3, 2.5e-3), reference=rng.uniform(-0.1, 0.1)),
        Effect("coulomb_friction", "alpha", coulomb),
        Effect("stiction", "alpha", (breakaway - 1.0) * coulomb),
    ]


def moving_rest_rig(seed: int) -> list[Effect]:
    """A rotor on a cable whose rest moves, drawn from ``seed`` (issue 64's case (a)): a
    ``hysteretic_spring`` of 1.5e-3–2.5e-3 N·m/rad with a play of 0.1–0.8 rad, Coulomb friction
    1e-4–3e-4 N·m and a modest breakaway, 1.5× that level (v_s 0.02 rad/s)."""
    rng = np.random.default_rng([seed, 64, 1])
    stiffness, play, coulomb = rng.uniform(1.5e-3, 2.5e-3), rng.uniform(0.1, 0.8), rng.uniform(1e-4, 3e-4)
    return [
        Effect("hysteretic_spring", "alpha", stiffness, play=play),
        Effect("coulomb_friction", "alpha", coulomb),
        Effect("stiction", "alpha", 0.5 * coulomb, stribeck_velocity=0.02),
    ]


def breakaway_rig(seed: int) -> list[Effect]:
    """A rotor held by friction far above its sliding level, drawn from ``seed`` (issue 64's case
    (b)): a fixed cable spring of 1.5e-3–2.5e-3 N·m/rad with its rest within ±0.1 rad, Coulomb
    friction 1e-4–3e-4 N·m and a breakaway 5–10× that level (stiction ΔF = breakaway − Coulomb,
    v_s 0.02 rad/s so that it holds only a rotor at rest)."""
    rng = np.random.default_rng([seed, 64, 2])
    stiffness, reference = rng.uniform(1.5e-3, 2.5e-3), rng.uniform(-0.1, 0.1)
    coulomb, breakaway = rng.uniform(1e-4, 3e-4), rng.uniform(5.0, 10.0)
    return [
        Effect("spring", "alpha", stiffness, reference=reference),
        Effect("coulomb_friction", "alpha", coulomb),
        Effect("stiction", "alpha", (breakaway - 1.0) * coulomb, stribeck_velocity=0.02),
    ]


def _release_start(rotor: float, rng: np.random.Generator) -> np.ndarray:
    """Where a hand lets the rotor go from ``rotor`` (rad): 0.5–2 rad away, either sign (turned
    back if that would carry it beyond :data:`RELEASE_TRAVEL`), at rest, the pendulum hanging."""
    step = rng.choice((-1.0, 1.0)) * rng.uniform(0.5, 2.0)
    if abs(rotor + step) > RELEASE_TRAVEL:
        step = -step
    return np.array([rotor + step, rng.uniform(-0.02, 0.02), 0.0, 0.0])


def _telegraph(n: int, dt: float, rng, level: float, unit: float, most: int) -> np.ndarray:
    """±level, the sign switching after random holds of 1..``most`` × ``unit`` seconds."""
    out, k, sign = np.empty(n), 0, rng.choice((-1.0, 1.0))
    while k < n:
        hold = int(rng.integers(1, most + 1)) * max(1, round(unit / dt))
        out[k : k + hold] = sign * level
        k, sign = k + hold, -sign
    return out


def _smoothed(x: np.ndarray, keep: float = 5.0 / 7.0) -> np.ndarray:
    """The rig's first-order smoothing of its references and excitation (≈ 6 ms at 500 Hz)."""
    return np.asarray(lfilter([1.0 - keep], [1.0, -keep], x))


@dataclasses.dataclass(frozen=True)
class ClosedLoopBalancing:
    """The ``"closed_loop_prbs"`` experiment as an object, for ``measured_like(excitation=...)``:
    the string is this object with its defaults, which are the MIT rig logs' (read off the logs).

    Upright balancing by PD on the encoder angles, u = kp_theta·(α − r_α) + kd_theta·α̇ −
    kp_alpha·(β − π − r_β) − kd_alpha·β̇ + feed-forward, saturated at ``voltage_limit``; the
    velocities are a first-order filtered difference of the quantised angles (cut-off
    ``velocity_cutoff`` rad/s; a raw difference turns one count into 1.5 rad/s). :meth:`signals`
    draws one run's references and feed-forward; a subclass may override it to change or record
    them.
    """

    gains: Mapping[str, float] = dataclasses.field(default_factory=lambda: dict(BALANCE_GAINS))
    velocity_cutoff: float = 100.0  # rad/s
    rotor_rate: float = 0.25  # rad/s, the rotor reference's ramp, direction held 0.25–1 s
    pendulum_reference: float = 0.01  # rad, ±, held 0.1–0.8 s
    feedforward: float = 0.5  # V, ±, held 0.1–0.6 s
    voltage_limit: float = 10.0  # V

    def __post_init__(self):
        if set(self.gains) != set(BALANCE_GAINS):
            raise ValueError(
                f"ClosedLoopBalancing: gains needs exactly {sorted(BALANCE_GAINS)}, got {sorted(self.gains)}"
            )
        for name in ("velocity_cutoff", "voltage_limit", "rotor_rate", "pendulum_reference", "feedforward"):
            value, strict = getattr(self, name), name in ("velocity_cutoff", "voltage_limit")
            if not (math.isfinite(value) and (value > 0 if strict else value >= 0)):
                raise ValueError(f"ClosedLoopBalancing: {name} must be {'> 0' if strict else '>= 0'}, got {value!r}")

    def signals(self, n: int, dt: float, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One run's (rotor reference, pendulum reference, feed-forward) per sample, all smoothed."""
        ramp = _smoothed(_telegraph(n, dt, rng, self.rotor_rate, 0.25, 4))
        rotor = np.cumsum(ramp) * dt
        pendulum = _smoothed(_telegraph(n, dt, rng, self.pendulum_reference, 0.1, 8))
        feed = _smoothed(_telegraph(n, dt, rng, self.feedforward, 0.1, 6))
        return rotor, pendulum, feed


class _Plant:
    """The plant behind its actuator (input delay of whole samples, actuator lag) at one sample
    period ``dt``: rolled out open loop (:meth:`roll`) or stepped by a controller (:meth:`step`)."""

    def __init__(self, system: str, effects: Sequence[Effect], plant: str, dt: float, substeps: int, fine: bool):
        self.dt = dt
        self.shift = int(round(sum(e.coefficient for e in effects if e.kind.input_dynamics == "delay") / dt))
        tau = actuator_lag_time(effects)
        mem = [e for e in effects if e.kind.input_dynamics != "delay"]
        self.backend, self.lag = None, None
        if plant == "mujoco":
            # the lag is native. ``fine``: ``substeps`` RK4 steps per sample, as the analytic
            # plant; else one MJCF step (2 ms / 10 ms), as the chirp data always had
            n = substeps if fine else 1
            self.backend = MujocoBackend(system, n, mem, timestep=dt / n if fine else None)
            assert abs(self.backend.control_dt - dt) < 1e-12
        elif plant == "analytic":
            mem = [e for e in mem if e.kind.input_dynamics != "lag"]
            base = analytic_model(system)
            model = WithEffects(base, mem, coulomb_smoothing=1e-3) if mem else base
            self._rollout = jax.jit(lambda x0, us: rollout_zoh(model, x0, us, dt, substeps))
            self._period = jax.jit(lambda x, u: rk4_zoh_step(model, x, u, dt, substeps))
            self.lag = ActuatorLag(tau) if tau > 0 else None
        else:
            raise ValueError(f"plant must be 'mujoco' or 'analytic', got {plant!r}")

    def roll(self, x0: np.ndarray, u: np.ndarray, carried: bool = False) -> np.ndarray:
        """States at every sample time under the commanded samples ``u`` (T,); ``xs[0] = x0``.
        ``carried``: the plant was carried to ``x0`` from where the last roll left it, so a
        cable's moving neutral remembers that (MuJoCo; the analytic plant has no such memory)."""
        T, s = len(u), self.shift
        u_plant = np.concatenate([np.full(s, u[0]), u[: T - s]]) if s else u
        if self.backend is not None:
            (self.backend.move if carried else self.backend.reset)(np.asarray(x0))
            steps = [self.backend.step(np.asarray(u_k)) for u_k in u_plant[:-1, None]]
            return np.stack([np.asarray(x0)] + steps)
        if self.lag is not None:  # open loop: the lag's held means can be computed up front
            self.lag.reset()
            u_plant = np.array([self.lag.advance(u_k, self.dt)[0] for u_k in u_plant])
        return np.asarray(self._rollout(x0, u_plant[:-1, None]))

    def reset(self, x0: np.ndarray) -> None:
        self.x, self._queue = np.asarray(x0, dtype=np.float64), None
        if self.backend is not None:
            self.backend.reset(self.x)
        if self.lag is not None:
            self.lag.reset()

    def step(self, u: np.ndarray) -> np.ndarray:
        """Hold the command ``u`` (shape (1,)) for one sample; return the next state."""
        if self.shift:  # as in roll, the first command stands for the ones before the start
            if self._queue is None:
                self._queue = collections.deque([u] * self.shift)
            self._queue.append(u)
            u = self._queue.popleft()
        if self.backend is not None:
            self.x = self.backend.step(u)
        else:
            if self.lag is not None:
                u = self.lag.advance(u, self.dt)
            self.x = np.asarray(self._period(self.x, u))
        return self.x


def _balance(sim: _Plant, t: np.ndarray, rng: np.random.Generator, experiment: ClosedLoopBalancing, sense):
    """One closed-loop upright run of ``experiment``: (``sense``d angles (T, 2), plant input (T,),
    true velocities (T, 2)). The command is held until the next sample."""
    dt, g = t[1] - t[0], experiment.gains
    x = np.array(
        [rng.uniform(-0.1, 0.1), np.pi + rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05)]
    )
    rotor_ref, pendulum_ref, feed = experiment.signals(len(t), dt, rng)
    sim.reset(x)
    smooth = 1.0 - math.exp(-experiment.velocity_cutoff * dt)
    q_prev, v = sense(x[:2]), np.zeros(2)
    qs, us, qds = np.empty((len(t), 2)), np.empty(len(t)), np.empty((len(t), 2))
    limit = experiment.voltage_limit
    for k in range(len(t)):
        q = sense(x[:2])
        v += smooth * ((q - q_prev) / dt - v)
        q_prev = q
        tilt = (q[1] - np.pi + np.pi) % (2 * np.pi) - np.pi  # β − π wrapped to [−π, π)
        pd = (
            g["kp_theta"] * (q[0] - rotor_ref[k])
            + g["kd_theta"] * v[0]
            - g["kp_alpha"] * (tilt - pendulum_ref[k])
            - g["kd_alpha"] * v[1]
        )
        qs[k], us[k], qds[k] = q, np.clip(pd + feed[k], -limit, limit), x[2:]
        if k + 1 < len(t):
            x = sim.step(us[k : k + 1])
    return qs, us, qds


def _open_loop(system: str, excitation: str, k: int, t: np.ndarray, rng, forced: bool):
    """(start state, input) of trajectory ``k`` of an open-loop sweep or chirp experiment."""
    if excitation in ("sine_sweep", "sticky_sweep"):
        q0 = [rng.uniform(-0.1, 0.1), rng.uniform(-0.05, 0.05)]
        x0 = np.array([*q0, *rng.uniform(-0.01, 0.01, 2)])
        u = _sine_with_rests(t, rng) if excitation == "sine_sweep" else _sticky_segment(t, rng, k % 3 == 0)
        return x0, u
    x0 = np.array([rng.uniform(lo, hi) for lo, hi in system_definition(system).chirp_initial_ranges])
    return x0, _inputs(system, t, rng, forced)


def _sensor(quantize: bool, flicker: float, seed: int):
    """The encoder: quantised angles, the rotor's one count up on a ``flicker`` share of the
    samples (issue 64 item 5: a count's flicker under a resting rotor cuts every rest on one count
    short), drawn from its own stream so that the logs without it are unchanged; or exact angles."""
    if not quantize:
        return lambda q: q
    if not flicker:
        return quantize_encoder
    flickers = np.random.default_rng([seed, 64])

    def sense(q):
        q = np.array(quantize_encoder(q))
        q[..., 0] += (2 * np.pi / ENCODER_COUNTS_PER_REV) * (flickers.random(q.shape[:-1]) < flicker)
        return q

    return sense


def _named_experiment(excitation) -> tuple[str, ClosedLoopBalancing]:
    """(the experiment's name, the closed loop's settings) of ``measured_like``'s ``excitation``."""
    if isinstance(excitation, ClosedLoopBalancing):
        return "closed_loop_prbs", excitation
    if excitation not in EXCITATIONS:
        raise ValueError(f"excitation must be one of {list(EXCITATIONS)} or a ClosedLoopBalancing, got {excitation!r}")
    return excitation, ClosedLoopBalancing()


def measured_like(
    system: str,
    effects: Sequence[Effect] = (),
    *,
    n_trajectories: int = 6,
    duration: float = 5.0,
    seed: int = 0,
    forced: bool = True,
    noise: float | None = None,
    plant: str = "mujoco",
    substeps: int = 10,
    excitation: str | ClosedLoopBalancing = "chirp",
    quantize: bool = True,
    true_velocities: bool = False,
    flicker: float = 0.0,
) -> list[Trajectory]:
    """Trajectories of the pinned model with ``effects`` added, as a sensor would log them.

    ``excitation="chirp"`` (both systems; ``forced=False``: no input): random initial states
    (Furuta: α0 ~ U(−1, 1), β0 ~ U(−π, π), velocities ~ U(−3, 3); N-MSD: p0 ~ U(−1, 1),
    ṗ0 ~ U(−3, 3)) and random chirp inputs. Furuta only:

    * ``"sine_sweep"``: near rest, hanging (α0 ~ U(−0.1, 0.1), β0 ~ U(−0.05, 0.05), velocities
      ~ U(−0.01, 0.01)); one sine of 0.3–2 V at 0.2–3 Hz, on for 60–80 % of each 3–8 s cycle
      (switched at zero crossings), 0 V in between.
    * ``"rotor_releases"``: u = 0; each trajectory a release from rest, the rotor carried 0.5–2 rad
      (either sign) from where the previous one left it (the first from α ~ U(−0.1, 0.1)), the
      pendulum hanging (β0 ~ U(−0.02, 0.02)); the plant keeps its memory between them, as between a sweep's segments.
    * ``"closed_loop_prbs"``: upright balancing from β0 = π ± 0.05, α0 = ±0.1, velocities ±0.05;
      PD on the encoder angles (:data:`BALANCE_GAINS`, filtered-difference velocities) tracking
      references plus a ±0.5 V feed-forward as the MIT logs do, saturated at ±10 V; u is the
      saturated command. ``excitation=ClosedLoopBalancing(...)`` is the same experiment with
      other gains, filter, references, feed-forward or voltage limit.

    ``quantize=False`` logs the Furuta's exact angles (and the balancing controller sees them):
    the same experiment without the encoder's resolution, to tell the sensor's limits from the
    method's. ``flicker``: the rotor's encoder a count up on that share of the samples.
    ``true_velocities=True`` attaches the simulator's velocities as ``qd`` (no sensor measures
    them: to tell what velocity estimation costs).

    ``input_delay`` is applied as the plant seeing the command ``round(d/dt)`` samples late,
    ``actuator_lag`` after it. The plant takes one MJCF step per sample for ``"chirp"`` (as it
    always did) and ``substeps`` RK4 steps per sample otherwise (the analytic plant always).
    """
    ensure_x64()
    excitation, experiment = _named_experiment(excitation)
    definition = system_definition(system)
    if excitation not in definition.excitations:
        owners = [d.title for d in SYSTEM_DEFINITIONS.values() if excitation in d.excitations]
        raise ValueError(
            f"excitation={excitation!r} is an experiment of {' and '.join(owners)}; "
            f"{definition.title} has {list(definition.excitations)}"
        )
    rng = np.random.default_rng(seed)
    dt = definition.sample_period
    t = np.arange(int(round(duration / dt)) + 1) * dt
    # the new experiments integrate MuJoCo finely too: under RK4 the sgn law lets a rotor held by dry friction against
    # a spring creep at a rate ∝ the step (an encoder count every fraction of a second at 2 ms), where a real rotor sticks
    sim = _Plant(system, effects, plant, dt, substeps, fine=excitation != "chirp")
    sense = _sensor(quantize, flicker, seed)
    out, rotor = [], None  # the releases' rotor, drawn only for them (other streams unchanged)
    for k in range(n_trajectories):
        if excitation == "closed_loop_prbs":
            q, u, qd = _balance(sim, t, rng, experiment, sense)
        else:
            if excitation == "rotor_releases":
                rotor = rng.uniform(-0.1, 0.1) if rotor is None else rotor
                x0, u = _release_start(rotor, rng), np.zeros_like(t)
            else:
                x0, u = _open_loop(system, excitation, k, t, rng, forced)
            xs = sim.roll(x0, u, carried=excitation in RECORDED_BACK_TO_BACK and k > 0)
            rotor = float(xs[-1, 0])
            q, qd = xs[:, : definition.spec.n_dof], xs[:, definition.spec.n_dof :]
            if definition.encoders:
                q = sense(q)
            else:
                q = q + rng.normal(0.0, 1e-3 if noise is None else noise, q.shape)
        qd = np.array(qd) if true_velocities else None
        out.append(Trajectory(t=t.copy(), q=np.asarray(q), u=u[:, None], qd=qd, name=str(k)))
    return out
