"""Training and test data for the two benchmark systems, generated as in the paper's appendix.

Laiche et al. 2026, appendix "Data Generation", with the choices the paper leaves open made
explicit (every number lives in :class:`NMSDRecipe` / :class:`FurutaRecipe`):

N-MSD (100 Hz)
    * train: one 60 s trajectory under a linear chirp 0.1 → 1.1 Hz from p0 ~ U(−1, 1),
      ṗ0 ~ U(−5, 5), cut into 30 segments of 2 s (201 samples; adjacent segments share their
      boundary sample).
    * test_chirp: 3 × 25 s under the same chirp band (0.1 → 1.1 Hz swept over the 25 s), new x0.
    * test_square: 3 × 15 s under one 3 s-wide square pulse starting at 1 s, new x0.
    * Amplitude (not in the paper): 5 N for both inputs; p then stays within ≈ ±1 m and ṗ within
      ≈ ±4 m/s, the range of the initial conditions.

Furuta (100 Hz)
    * train: 64 free (u = 0) trajectories of 1 s (101 samples) from α, β ~ U(−π, π),
      α̇, β̇ ~ U(−5, 5). The simulation recipe gives no duration; we use the 1 s of the
      paper's experimental recipe (same count, same rate).
    * test_free: 6 × 6 s free, α, β ~ U(−π, π), α̇, β̇ ~ U(−20, 20).
    * test_forced: 3 × 20 s under a linear chirp 0.5 Hz at t = 0 → 6 Hz at t = 20 s, x0 drawn
      as for test_free. Amplitude (not in the paper): 2 V — inside the 5 V limit; from rest the
      pendulum then swings up to ≈ ±1.6 rad near its resonance (≈ 1.7 Hz) without going over.
    * scale_fit: one extra forced trajectory (same chirp, 20 s, x0 as for training) for the
      post-training scale fit (free data cannot identify the Lagrangian's scale).

Input convention: the recorded input samples at 100 Hz *are* the plant input, linearly
interpolated between samples — exactly what the trajectory loss and the evaluation assume, so the
true model reproduces its own data to the solver tolerance. Ground truth: the MuJoCo model
(``assets/*.xml``) when its backend is available, else the analytic model with tight tolerances
(they agree to ~1e-6); the manifest records which one was used.

Sensors (options, applied at ``sensor_rate_hz`` = 500 Hz, then subsampled to 100 Hz): encoder
quantisation (Furuta, 2048 counts/rev), Gaussian position noise, and velocities either exact or
from the paper's derivative filter F(s) = ω0²s/(s² + 2ξω0s + ω0²), ω0 = 100, ξ = 0.8, warmed up on
a constant-velocity history ending at x0 (so no start-up transient).

Everything is written through :func:`furuta_gym.data.save_trajectories`, so generated and measured
data go through the same loader.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from pathlib import Path
from typing import Callable, Literal, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial import cKDTree

from .. import __version__, ensure_x64
from ..data import Trajectory, save_trajectories
from ..envs import MujocoBackend
from ..lagrangian import vector_field
from ..models import analytic_model
from ..signals import (
    ENCODER_COUNTS_PER_REV,
    chirp,
    derivative_filter,
    multisine,
    quantize_encoder,
    random_steps,
    square_pulse,
)
from ..systems import get_spec

__all__ = [
    "DATA_RATE_HZ",
    "NMSDRecipe",
    "FurutaRecipe",
    "SensorOptions",
    "GroundTruth",
    "AnalyticGroundTruth",
    "MujocoGroundTruth",
    "default_ground_truth",
    "recipe_for",
    "generate_datasets",
    "write_datasets",
    "generate",
    "DATASET_NAMES",
    "VALIDATION_NAMES",
    "generate_validation",
    "sample_overlap",
]

DATA_RATE_HZ = 100.0

#: Dataset names per system, in the order they are generated and written.
DATASET_NAMES = {
    "nmsd": ("train", "test_chirp", "test_square"),
    "furuta": ("train", "test_free", "test_forced", "scale_fit"),
}

#: Validation datasets per system (:func:`generate_validation`): excitations and initial states of
#: their own, inside the training distribution, so that no validation sample is close to a test
#: sample (:func:`sample_overlap`). Recipe choices are scored on these, never on the test sets.
VALIDATION_NAMES = {
    "nmsd": ("val_multisine", "val_steps"),
    "furuta": ("val_free", "val_forced", "val_scale_fit"),
}


@dataclasses.dataclass(frozen=True)
class NMSDRecipe:
    """The N-MSD datasets (paper appendix; amplitude and test counts are our choice)."""

    train_duration: float = 60.0
    segment_duration: float = 2.0
    chirp_f0: float = 0.1
    chirp_f1: float = 1.1
    amplitude: float = 5.0  # N, chirp and pulse
    p0_range: float = 1.0
    pd0_range: float = 5.0
    n_test_chirp: int = 3
    test_chirp_duration: float = 25.0
    n_test_square: int = 3
    test_square_duration: float = 15.0
    pulse_start: float = 1.0
    pulse_width: float = 3.0
    # validation (generate_validation): x0 inside the training trajectory's range
    val_p0_range: float = 0.5
    val_pd0_range: float = 2.5
    n_val_multisine: int = 3
    val_multisine_duration: float = 25.0
    val_multisine_tones: int = 8
    n_val_steps: int = 3
    val_steps_duration: float = 15.0
    val_steps_hold: tuple[float, float] = (1.0, 3.0)

    @classmethod
    def small(cls) -> "NMSDRecipe":
        """A scaled-down recipe for quick pipeline runs (10 segments, 1 + 1 short tests)."""
        return cls(
            train_duration=20.0,
            n_test_chirp=1,
            test_chirp_duration=10.0,
            n_test_square=1,
            test_square_duration=10.0,
            n_val_multisine=1,
            val_multisine_duration=10.0,
            n_val_steps=1,
            val_steps_duration=10.0,
        )


@dataclasses.dataclass(frozen=True)
class FurutaRecipe:
    """The simulated Furuta datasets (paper appendix; see the module docstring for choices)."""

    n_train: int = 64
    train_duration: float = 1.0
    angle_range: float = np.pi
    train_velocity_range: float = 5.0
    n_test_free: int = 6
    test_free_duration: float = 6.0
    test_velocity_range: float = 20.0
    n_test_forced: int = 3
    test_forced_duration: float = 20.0
    chirp_f0: float = 0.5
    chirp_f1: float = 6.0
    chirp_t1: float = 20.0  # the paper's "target time"
    amplitude: float = 2.0  # V
    n_scale_fit: int = 1
    scale_fit_duration: float = 20.0
    # "steps": random ±amplitude steps of its own; "chirp": the test chirp, as before the recipe
    # was frozen (a scale-fit trajectory then follows the forced test trajectories once both
    # forget their start)
    scale_fit_input: Literal["chirp", "steps"] = "steps"
    # validation (generate_validation): x0 in the training ranges, inputs other than the chirp;
    # free ones end before the pendulum settles (~3 s), where every free trajectory meets the others
    n_val_free: int = 12
    val_free_duration: float = 2.0
    n_val_forced: int = 3
    val_forced_duration: float = 20.0
    val_multisine_tones: int = 12
    val_scale_fit_duration: float = 20.0
    val_steps_hold: tuple[float, float] = (0.25, 1.0)

    @classmethod
    def small(cls) -> "FurutaRecipe":
        """A scaled-down recipe for quick pipeline runs (16 train, 2 free + 1 forced short tests)."""
        return cls(
            n_train=16,
            n_test_free=2,
            test_free_duration=3.0,
            n_test_forced=1,
            test_forced_duration=10.0,
            scale_fit_duration=10.0,
            n_val_free=4,
            n_val_forced=1,
            val_forced_duration=10.0,
            val_scale_fit_duration=10.0,
        )


RECIPE_CLASS = {"furuta": FurutaRecipe, "nmsd": NMSDRecipe}


def recipe_for(system: str, small: bool = False):
    """The default (or ``small``) recipe of ``"nmsd"`` / ``"furuta"``."""
    cls = RECIPE_CLASS[get_spec(system).name]
    return cls.small() if small else cls()


@dataclasses.dataclass(frozen=True)
class SensorOptions:
    """How the generated states are "measured".

    ``quantize``: round angles to the encoder resolution (Furuta only; the N-MSD has no encoder).
    ``noise_std``: Gaussian noise on positions (rad or m), per sensor sample.
    ``velocity``: ``"exact"`` (simulated velocities, as the paper's simulated data) or
    ``"filter"`` (the paper's derivative filter on the measured positions, as its experiments).
    ``velocity_noise_std``: Gaussian noise added to exact velocities (rad/s or m/s).
    ``sensor_rate_hz``: rate at which quantisation, noise and the filter act (QUBE: 500 Hz); the
    data are subsampled from it to 100 Hz.
    """

    quantize: bool = False
    noise_std: float = 0.0
    velocity: Literal["exact", "filter"] = "exact"
    velocity_noise_std: float = 0.0
    sensor_rate_hz: float = 500.0
    filter_omega0: float = 100.0
    filter_xi: float = 0.8
    counts_per_rev: int = ENCODER_COUNTS_PER_REV

    def __post_init__(self):
        if self.velocity not in ("exact", "filter"):
            raise ValueError(f"velocity must be 'exact' or 'filter', got {self.velocity!r}")
        if self.noise_std < 0 or self.velocity_noise_std < 0:
            raise ValueError(
                f"noise_std and velocity_noise_std must be ≥ 0, got {self.noise_std}, "
                f"{self.velocity_noise_std}"
            )
        ratio = self.sensor_rate_hz / DATA_RATE_HZ
        if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(
                f"sensor_rate_hz must be an integer multiple of {DATA_RATE_HZ:g} Hz, "
                f"got {self.sensor_rate_hz}"
            )
        if self.velocity_noise_std > 0 and self.velocity == "filter":
            raise ValueError("velocity_noise_std applies to exact velocities, not velocity='filter'")

    @property
    def oversample(self) -> int:
        return int(round(self.sensor_rate_hz / DATA_RATE_HZ))

    @property
    def is_exact(self) -> bool:
        return (
            not self.quantize
            and self.noise_std == 0
            and self.velocity == "exact"
            and self.velocity_noise_std == 0
        )


# --------------------------------------------------------------------------------------------
# Ground truth: x0 (B, 2n), sample times t (T,) on the sensor grid, inputs u (B, T, m) on the
# same grid (linearly interpolated in between) -> states (B, T, 2n).
# --------------------------------------------------------------------------------------------

GroundTruth = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


class AnalyticGroundTruth:
    """The pinned analytic model, integrated with classic RK4 at ``substeps`` steps per sensor
    sample, the input linear within each step (so the scheme stays fourth order).

    At the default 4 substeps of a 500 Hz sensor grid (h = 0.5 ms) it agrees with diffrax Tsit5
    at rtol 1e-10 / atol 1e-12 to ~1e-10 on these datasets, and is ~10× faster to run.
    """

    name = "analytic"

    def __init__(self, system: str, substeps: int = 4):
        ensure_x64()
        self.system = get_spec(system).name
        self.model = analytic_model(self.system)
        self.substeps = substeps
        self._compiled = None

    def _build(self):
        model, S = self.model, self.substeps

        def interval(x, inputs):
            u0, u1, dt = inputs
            h = dt / S

            def sub(i, x):
                a = i / S
                ua = u0 + (u1 - u0) * a
                um = u0 + (u1 - u0) * (a + 0.5 / S)
                ub = u0 + (u1 - u0) * (a + 1.0 / S)
                k1 = vector_field(model, x, ua)
                k2 = vector_field(model, x + 0.5 * h * k1, um)
                k3 = vector_field(model, x + 0.5 * h * k2, um)
                k4 = vector_field(model, x + h * k3, ub)
                return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)

            x = jax.lax.fori_loop(0, S, sub, x)
            return x, x

        def chunk(x0, us, dt):
            # one fixed-length chunk of sample intervals: compiled once for every dataset
            _, xs = jax.lax.scan(
                interval, x0, (us[:-1], us[1:], jnp.full(us.shape[0] - 1, dt))
            )
            return xs

        return jax.jit(jax.vmap(chunk, in_axes=(0, 0, None)))

    _CHUNK = 100  # sample intervals per compiled call
    _BATCH = 8  # batch padded to a multiple of this, so few shapes ever compile

    def __call__(self, x0s, t, us):
        if self._compiled is None:
            self._compiled = self._build()
        x0s, us = np.asarray(x0s, dtype=float), np.asarray(us, dtype=float)
        dt = float(t[1] - t[0])
        if np.max(np.abs(np.diff(t) - dt)) > 1e-9 * max(1.0, dt):
            raise ValueError("t: the ground truth needs a uniform sample grid")
        B, T = us.shape[0], us.shape[1]
        Bp = -(-B // self._BATCH) * self._BATCH
        n_chunks = -(-(T - 1) // self._CHUNK)
        Tp = n_chunks * self._CHUNK + 1
        # pad the batch with copies of the first row and the time axis with the last input
        x_pad = np.concatenate([x0s, np.repeat(x0s[:1], Bp - B, axis=0)])
        u_pad = np.concatenate([us, np.repeat(us[:1], Bp - B, axis=0)])
        u_pad = np.concatenate([u_pad, np.repeat(u_pad[:, -1:], Tp - T, axis=1)], axis=1)
        out = np.empty((Bp, Tp, x0s.shape[1]))
        out[:, 0] = x_pad
        x = jnp.asarray(x_pad)
        for c in range(n_chunks):
            a = c * self._CHUNK
            xs = self._compiled(x, jnp.asarray(u_pad[:, a : a + self._CHUNK + 1]), dt)
            out[:, a + 1 : a + self._CHUNK + 1] = np.asarray(xs)
            x = xs[:, -1]
        return out[:B, :T]


class MujocoGroundTruth:
    """The MuJoCo model in ``assets/`` (through the envs' :class:`MujocoBackend`), RK4 at
    ``substeps`` steps per sensor sample.

    The input held over each MuJoCo step is the linear interpolation of the samples at the step's
    midpoint (midpoint rule), which tracks the linearly interpolated input to second order.
    """

    name = "mujoco"

    def __init__(self, system: str, substeps: int = 4):
        self.system = get_spec(system).name
        self.substeps = int(substeps)
        self._backend = MujocoBackend(self.system, substeps=1)

    def __call__(self, x0s, t, us):
        dt = float(t[1] - t[0])
        backend = self._backend
        backend.model.opt.timestep = dt / self.substeps
        out = np.empty((x0s.shape[0], len(t), x0s.shape[1]))
        fractions = (np.arange(self.substeps) + 0.5) / self.substeps
        for b in range(x0s.shape[0]):
            backend.reset(np.asarray(x0s[b], dtype=float))
            out[b, 0] = x0s[b]
            u_b = us[b]
            for k in range(len(t) - 1):
                for f in fractions:
                    x = backend.step((1.0 - f) * u_b[k] + f * u_b[k + 1])
                out[b, k + 1] = x
        return out


def default_ground_truth(system: str, kind: str = "auto") -> GroundTruth:
    """``"mujoco"``, ``"analytic"`` or ``"auto"`` (MuJoCo when its backend exists)."""
    if kind not in ("auto", "mujoco", "analytic"):
        raise ValueError(f"ground truth must be 'auto', 'mujoco' or 'analytic', got {kind!r}")
    if kind in ("auto", "mujoco"):
        try:
            return MujocoGroundTruth(system)
        except ImportError:
            if kind == "mujoco":
                raise
    return AnalyticGroundTruth(system)


# --------------------------------------------------------------------------------------------
# Recipes -> clean trajectories on the sensor grid
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass
class _Clean:
    """Noise-free states on the sensor grid."""

    t: np.ndarray  # (T,)
    x: np.ndarray  # (T, 2n)
    u: np.ndarray  # (T, m)
    name: str


def _grid(duration: float, rate: float) -> np.ndarray:
    n = int(round(duration * rate))
    return np.arange(n + 1) / rate


def _inputs_at(u_fn, t_data: np.ndarray, oversample: int) -> np.ndarray:
    """Input sampled at the data rate, linearly interpolated onto the sensor grid."""
    u_data = np.asarray(u_fn(t_data), dtype=float)
    t_fine = np.arange((len(t_data) - 1) * oversample + 1) / (oversample / (t_data[1] - t_data[0]))
    t_fine = t_data[0] + t_fine
    return t_fine, np.interp(t_fine, t_data, u_data)


def _run(gt: GroundTruth, x0s, duration, u_fn, oversample, names) -> list[_Clean]:
    t_data = _grid(duration, DATA_RATE_HZ)
    t_fine, u_fine = _inputs_at(u_fn, t_data, oversample)
    us = np.broadcast_to(u_fine[None, :, None], (len(x0s), len(t_fine), 1)).copy()
    xs = gt(np.asarray(x0s, dtype=float), t_fine, us)
    return [_Clean(t=t_fine, x=xs[b], u=us[b], name=names[b]) for b in range(len(x0s))]


def _uniform(rng, n, ranges):
    ranges = np.asarray(ranges, dtype=float)
    return rng.uniform(-ranges, ranges, size=(n, len(ranges)))


def _rng(seed: int, dataset: str) -> np.random.Generator:
    # one independent stream per dataset, stable under recipe changes of the other datasets
    digest = int(hashlib.sha256(dataset.encode()).hexdigest()[:8], 16)
    return np.random.default_rng([seed, digest])


def _nmsd_clean(recipe: NMSDRecipe, gt, seed, oversample) -> dict[str, list[_Clean]]:
    r = recipe
    ranges = (r.p0_range, r.pd0_range)
    out = {}
    # training: one long chirp trajectory cut into segments
    x0 = _uniform(_rng(seed, "train"), 1, ranges)
    (long,) = _run(
        gt,
        x0,
        r.train_duration,
        lambda t: chirp(t, r.chirp_f0, r.chirp_f1, r.train_duration, r.amplitude),
        oversample,
        ["train"],
    )
    n_seg = int(round(r.train_duration / r.segment_duration))
    seg_len = int(round(r.segment_duration * DATA_RATE_HZ)) * oversample
    out["train"] = [
        _Clean(
            t=long.t[k * seg_len : (k + 1) * seg_len + 1] - long.t[k * seg_len],
            x=long.x[k * seg_len : (k + 1) * seg_len + 1],
            u=long.u[k * seg_len : (k + 1) * seg_len + 1],
            name=f"seg{k:02d}",
        )
        for k in range(n_seg)
    ]
    x0s = _uniform(_rng(seed, "test_chirp"), r.n_test_chirp, ranges)
    out["test_chirp"] = _run(
        gt,
        x0s,
        r.test_chirp_duration,
        lambda t: chirp(t, r.chirp_f0, r.chirp_f1, r.test_chirp_duration, r.amplitude),
        oversample,
        [f"chirp{k}" for k in range(r.n_test_chirp)],
    )
    x0s = _uniform(_rng(seed, "test_square"), r.n_test_square, ranges)
    out["test_square"] = _run(
        gt,
        x0s,
        r.test_square_duration,
        lambda t: square_pulse(t, r.pulse_start, r.pulse_width, r.amplitude),
        oversample,
        [f"square{k}" for k in range(r.n_test_square)],
    )
    return out


def _furuta_clean(recipe: FurutaRecipe, gt, seed, oversample) -> dict[str, list[_Clean]]:
    r = recipe
    train_ranges = (r.angle_range, r.angle_range, r.train_velocity_range, r.train_velocity_range)
    test_ranges = (r.angle_range, r.angle_range, r.test_velocity_range, r.test_velocity_range)

    def u_chirp(t):
        return chirp(t, r.chirp_f0, r.chirp_f1, r.chirp_t1, r.amplitude)

    def u_free(t):
        return np.zeros_like(t)

    out = {}
    x0s = _uniform(_rng(seed, "train"), r.n_train, train_ranges)
    out["train"] = _run(
        gt, x0s, r.train_duration, u_free, oversample, [f"free{k:02d}" for k in range(r.n_train)]
    )
    x0s = _uniform(_rng(seed, "test_free"), r.n_test_free, test_ranges)
    out["test_free"] = _run(
        gt, x0s, r.test_free_duration, u_free, oversample, [f"free{k}" for k in range(r.n_test_free)]
    )
    x0s = _uniform(_rng(seed, "test_forced"), r.n_test_forced, test_ranges)
    out["test_forced"] = _run(
        gt,
        x0s,
        r.test_forced_duration,
        u_chirp,
        oversample,
        [f"chirp{k}" for k in range(r.n_test_forced)],
    )
    if r.scale_fit_input == "steps":
        out["scale_fit"] = _run_each(
            gt, "scale_fit_input", seed, r.n_scale_fit, train_ranges, r.scale_fit_duration,
            lambda rng: lambda t: random_steps(t, r.val_steps_hold, r.amplitude, rng), oversample,
        )
        return out
    x0s = _uniform(_rng(seed, "scale_fit"), r.n_scale_fit, train_ranges)
    out["scale_fit"] = _run(
        gt,
        x0s,
        r.scale_fit_duration,
        u_chirp,
        oversample,
        [f"scale{k}" for k in range(r.n_scale_fit)],
    )
    return out


def _nmsd_validation(recipe: NMSDRecipe, gt, seed, oversample) -> dict[str, list[_Clean]]:
    r = recipe
    ranges = (r.val_p0_range, r.val_pd0_range)
    out = {}
    for name, n, duration, make_u in (
        ("val_multisine", r.n_val_multisine, r.val_multisine_duration,
         lambda rng: lambda t: multisine(t, r.chirp_f0, r.chirp_f1, r.val_multisine_tones, r.amplitude, rng)),
        ("val_steps", r.n_val_steps, r.val_steps_duration,
         lambda rng: lambda t: random_steps(t, r.val_steps_hold, r.amplitude, rng)),
    ):
        out[name] = _run_each(gt, name, seed, n, ranges, duration, make_u, oversample)
    return out


def _furuta_validation(recipe: FurutaRecipe, gt, seed, oversample) -> dict[str, list[_Clean]]:
    r = recipe
    ranges = (r.angle_range, r.angle_range, r.train_velocity_range, r.train_velocity_range)
    free = _uniform(_rng(seed, "val_free"), r.n_val_free, ranges)
    out = {"val_free": _run(gt, free, r.val_free_duration, np.zeros_like, oversample,
                            [f"free{k}" for k in range(r.n_val_free)])}
    out["val_forced"] = _run_each(
        gt, "val_forced", seed, r.n_val_forced, ranges, r.val_forced_duration,
        lambda rng: lambda t: multisine(t, r.chirp_f0, r.chirp_f1, r.val_multisine_tones, r.amplitude, rng),
        oversample,
    )
    out["val_scale_fit"] = _run_each(
        gt, "val_scale_fit", seed, 1, ranges, r.val_scale_fit_duration,
        lambda rng: lambda t: random_steps(t, r.val_steps_hold, r.amplitude, rng), oversample,
    )
    return out


def _run_each(gt, name, seed, n, ranges, duration, make_u, oversample) -> list[_Clean]:
    """``n`` trajectories of dataset ``name``, each with its own x0 and its own draw of the input
    signal ``make_u(rng)`` (one seeded stream per dataset)."""
    rng = _rng(seed, name)
    x0s = _uniform(rng, n, ranges)
    return [
        _run(gt, x0s[k : k + 1], duration, make_u(rng), oversample, [f"{name}{k}"])[0]
        for k in range(n)
    ]


# --------------------------------------------------------------------------------------------
# Sensor model: clean sensor-rate states -> measured 100 Hz trajectories
# --------------------------------------------------------------------------------------------


def _measure(
    clean: _Clean, n_dof: int, angular: Sequence[bool], options: SensorOptions, rng
) -> Trajectory:
    q_true, qd_true = clean.x[:, :n_dof], clean.x[:, n_dof:]
    q = q_true.copy()
    if options.noise_std > 0:
        q = q + rng.normal(0.0, options.noise_std, size=q.shape)
    if options.quantize:
        for j, is_angle in enumerate(angular):
            if is_angle:
                q[:, j] = quantize_encoder(q[:, j], options.counts_per_rev)
    dt_fine = float(clean.t[1] - clean.t[0])
    if options.velocity == "filter":
        qd = _warm_filter(q, qd_true[0], dt_fine, options)
    else:
        qd = qd_true.copy()
        if options.velocity_noise_std > 0:
            qd = qd + rng.normal(0.0, options.velocity_noise_std, size=qd.shape)
    k = options.oversample
    return Trajectory(
        t=np.round(clean.t[::k], 10), q=q[::k], u=clean.u[::k], qd=qd[::k], name=clean.name
    )


def _warm_filter(q: np.ndarray, qd0: np.ndarray, dt: float, options: SensorOptions) -> np.ndarray:
    """The paper's derivative filter, run after a 0.2 s constant-velocity history ending at x0,
    so the estimate starts on the true velocity instead of a start-up transient."""
    n_warm = int(round(0.2 / dt))
    back = (np.arange(-n_warm, 0) * dt)[:, None]
    history = q[0][None, :] + back * qd0[None, :]
    filtered = derivative_filter(
        np.concatenate([history, q], axis=0), dt, options.filter_omega0, options.filter_xi
    )
    return filtered[n_warm:]


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------


def generate_datasets(
    system: str,
    *,
    seed: int = 0,
    small: bool = False,
    recipe=None,
    sensor: SensorOptions | None = None,
    ground_truth: GroundTruth | str = "auto",
) -> dict[str, list[Trajectory]]:
    """Generate the paper's datasets of ``system`` (``"nmsd"``/``"furuta"``) in memory.

    Returns ``{dataset name: [Trajectory, ...]}`` with the names of :data:`DATASET_NAMES`,
    sampled at 100 Hz with velocities. Seeded: the same arguments give the same numbers.
    ``recipe`` overrides :func:`recipe_for` (``small`` picks the scaled-down one);
    ``ground_truth`` is a name for :func:`default_ground_truth` or a callable
    ``(x0s (B, 2n), t (T,), us (B, T, m)) -> states (B, T, 2n)``.
    """
    return _generate(system, "test", seed=seed, small=small, recipe=recipe, sensor=sensor,
                     ground_truth=ground_truth)


def generate_validation(
    system: str,
    *,
    seed: int = 0,
    small: bool = False,
    recipe=None,
    sensor: SensorOptions | None = None,
    ground_truth: GroundTruth | str = "auto",
) -> dict[str, list[Trajectory]]:
    """The validation datasets of ``system`` (:data:`VALIDATION_NAMES`), with the arguments of
    :func:`generate_datasets`. Furuta: ``val_free`` (12 × 2 s free from the *training* state
    ranges, ending before the pendulum settles where all free trajectories meet), ``val_forced`` (3 × 20 s, a 12-tone multisine over the chirp's 0.5–6 Hz band, new
    phases per trajectory) and ``val_scale_fit`` (20 s of random ±2 V steps held 0.25–1 s);
    N-MSD: ``val_multisine`` (3 × 25 s, 8 tones over 0.1–1.1 Hz) and ``val_steps`` (3 × 15 s of
    random ±5 N steps held 1–3 s), from x0 inside the training trajectory's range. Their overlap
    with the test sets is measured by ``experiments/validation_overlap.py`` (docs/reproduce.md)."""
    return _generate(system, "validation", seed=seed, small=small, recipe=recipe, sensor=sensor,
                     ground_truth=ground_truth)


_MAKERS = {
    ("nmsd", "test"): _nmsd_clean,
    ("furuta", "test"): _furuta_clean,
    ("nmsd", "validation"): _nmsd_validation,
    ("furuta", "validation"): _furuta_validation,
}
_NOISE_STREAM = {"test": 7919, "validation": 7927}  # sensor-noise streams, one per kind


def _generate(system, kind, *, seed, small, recipe, sensor, ground_truth):
    spec = get_spec(system)
    sensor = sensor or SensorOptions()
    if sensor.quantize and not any(spec.angular):
        raise ValueError(
            f"quantize: {spec.name} has no encoder angles to quantise (its joints are "
            f"{spec.joint_names}); use noise_std for a position sensor's resolution"
        )
    recipe = recipe if recipe is not None else recipe_for(spec.name, small)
    expected = RECIPE_CLASS[spec.name]
    if not isinstance(recipe, expected):
        raise ValueError(f"recipe for {spec.name} must be a {expected.__name__}, got {recipe!r}")
    gt = default_ground_truth(spec.name, ground_truth) if isinstance(ground_truth, str) else ground_truth
    clean = _MAKERS[spec.name, kind](recipe, gt, seed, sensor.oversample)
    names = (DATASET_NAMES if kind == "test" else VALIDATION_NAMES)[spec.name]
    out = {}
    for name, trajs in clean.items():
        rng = np.random.default_rng([seed, _NOISE_STREAM[kind], names.index(name)])
        out[name] = [_measure(c, spec.n_dof, spec.angular, sensor, rng) for c in trajs]
    return out


def sample_overlap(
    samples: Sequence[Trajectory],
    reference: Sequence[Trajectory],
    tolerances: Sequence[float],
    angular: Sequence[bool] | None = None,
    *,
    same_time: bool = True,
) -> float:
    """Fraction of the samples of ``samples`` whose state is within ``tolerances`` (one per state
    variable, ``inf`` to ignore one) of a sample of ``reference`` — how much of a validation set
    repeats a test set. ``same_time=True``: the reference sample at the same time of some
    reference trajectory (a trajectory that follows a test trajectory, as under a shared input);
    ``False``: at any time (coverage of the same region of state space, which trajectories of one
    damped system share whatever their excitation). Variables flagged in ``angular`` are compared
    modulo 2π."""
    tol = np.asarray(tolerances, dtype=float)
    keep = np.isfinite(tol)
    wrap = np.zeros(len(tol), bool) if angular is None else np.asarray(angular, bool)

    def scaled(x):
        return x[..., keep] / tol[keep]

    hits = total = 0
    if same_time:
        for tr in samples:
            a = scaled(tr.x)
            found = np.zeros(len(a), bool)
            for ref in reference:
                n = min(len(a), len(ref.x))
                found[:n] |= _aligned_close(a[:n], scaled(ref.x[:n]), wrap[keep], 2 * np.pi / tol[keep])
            hits, total = hits + found.sum(), total + len(a)
        return float(hits / max(total, 1))
    a = np.concatenate([scaled(tr.x) for tr in samples])
    b = np.concatenate([scaled(tr.x) for tr in reference])
    # copies of the reference shifted by ±2π on each wrapped variable compare across the wrap
    for i in np.flatnonzero(wrap[keep]):
        shift = np.eye(b.shape[1])[i] * 2 * np.pi / tol[keep][i]
        b = np.concatenate([b, b + shift, b - shift])
    distance, _ = cKDTree(b).query(a, k=1, p=np.inf, distance_upper_bound=1.0)
    return float(np.mean(np.isfinite(distance)))


def _aligned_close(a, b, wrap, period) -> np.ndarray:
    """Per sample: |a − b| ≤ 1 on every (scaled) variable, wrapped ones modulo their period."""
    diff = np.abs(a - b)
    diff = np.where(wrap, np.minimum(np.mod(diff, period), period - np.mod(diff, period)), diff)
    return (diff <= 1.0).all(axis=1)


def write_datasets(
    out_dir: str | Path,
    datasets: dict[str, list[Trajectory]],
    system: str,
    *,
    metadata: dict | None = None,
    overwrite: bool = False,
) -> dict[str, Path]:
    """Write each dataset to ``out_dir/<name>.csv`` plus ``manifest.json`` (recipe, seed, options,
    ground truth, sha256 of every file). Refuses to overwrite existing files unless asked."""
    out_dir = Path(out_dir)
    paths = {name: out_dir / f"{name}.csv" for name in datasets}
    manifest_path = out_dir / "manifest.json"
    if not overwrite:
        existing = [str(p) for p in [*paths.values(), manifest_path] if p.exists()]
        if existing:
            raise FileExistsError(
                f"{existing[0]}: exists; refusing to overwrite generated data "
                f"(choose another --out or pass overwrite)"
            )
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    for name, trajs in datasets.items():
        save_trajectories(paths[name], trajs, system, overwrite=overwrite)
        files[name] = {
            "path": paths[name].name,
            "n_trajectories": len(trajs),
            "samples_per_trajectory": sorted({len(tr) for tr in trajs}),
            "sha256": hashlib.sha256(paths[name].read_bytes()).hexdigest(),
        }
    manifest = {"system": get_spec(system).name, "files": files, **(metadata or {})}
    manifest_path.write_text(json.dumps(manifest, indent=2, default=_json_default) + "\n")
    return paths


def _json_default(o):
    if dataclasses.is_dataclass(o):
        return dataclasses.asdict(o)
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)


def generate(
    system: str,
    out_dir: str | Path,
    *,
    seed: int = 0,
    small: bool = False,
    sensor: SensorOptions | None = None,
    ground_truth: GroundTruth | str = "auto",
    overwrite: bool = False,
    split: str = "test",
) -> dict[str, Path]:
    """:func:`generate_datasets` then :func:`write_datasets`; returns ``{name: csv path}``.
    ``split="validation"``: the training set and the validation datasets
    (:func:`generate_validation`) instead of the test sets, which are then never written."""
    sensor = sensor or SensorOptions()
    spec = get_spec(system)
    gt = default_ground_truth(spec.name, ground_truth) if isinstance(ground_truth, str) else ground_truth
    recipe = recipe_for(spec.name, small)
    t0 = time.perf_counter()
    if split not in ("test", "validation"):
        raise ValueError(f"split must be 'test' or 'validation', got {split!r}")
    datasets = generate_datasets(
        spec.name, seed=seed, small=small, recipe=recipe, sensor=sensor, ground_truth=gt
    )
    if split == "validation":
        datasets = {"train": datasets["train"], **generate_validation(
            spec.name, seed=seed, small=small, recipe=recipe, sensor=sensor, ground_truth=gt)}
    metadata = {
        "seed": seed,
        **({"split": split} if split != "test" else {}),
        "small": small,
        "rate_hz": DATA_RATE_HZ,
        "recipe": recipe,
        "sensor": sensor,
        "ground_truth": getattr(gt, "name", type(gt).__name__),
        "input_convention": "u samples linearly interpolated between samples",
        "furuta_gym_version": __version__,
        "seconds": round(time.perf_counter() - t0, 2),
    }
    return write_datasets(out_dir, datasets, spec.name, metadata=metadata, overwrite=overwrite)
