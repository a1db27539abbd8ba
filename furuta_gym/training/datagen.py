"""Training and test data for the two benchmark systems, generated as in the paper's appendix.

Laiche et al. 2026, appendix "Data Generation", with the choices the paper leaves open made
explicit (every number lives in :class:`NMSDRecipe` / :class:`FurutaRecipe`, each in its system's
module with the code that draws its datasets, ``_nmsd_data.py`` / ``_furuta_data.py``):

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

Sensors (the one sensor model, :class:`furuta_gym.sensors.Sensors`, the envs' and the
controllers'; applied at ``sensor_rate_hz`` = 500 Hz, then subsampled to 100 Hz): encoder
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
from typing import Literal, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial import KDTree

from .. import __version__, ensure_x64
from .._deprecated import deprecated_names
from .._versions import installed_versions
from ..data import Trajectory, save_trajectories
from ..envs import MujocoBackend
from ..lagrangian import vector_field
from ..models import analytic_model
from ..sensors import Sensors
from ..signals import ENCODER_COUNTS_PER_REV, derivative_filter, quantize_joints
from ..systems import get_spec
from ._furuta_data import FURUTA_DATA, FurutaRecipe
from ._nmsd_data import NMSD_DATA, NMSDRecipe
from ._sampling import DATA_RATE_HZ, Clean, GroundTruth
from ._system_data import SystemData

__all__ = [
    "DATA_RATE_HZ",
    "NMSDRecipe",
    "FurutaRecipe",
    "SENSOR_RATE_HZ",
    "sensor_record",
    "read_sensor_record",
    "GroundTruth",
    "AnalyticGroundTruth",
    "MujocoGroundTruth",
    "default_ground_truth",
    "recipe_for",
    "generate_datasets",
    "write_datasets",
    "generate",
    "data_package_versions",
    "SystemData",
    "SYSTEM_DATA",
    "system_data",
    "DATASET_NAMES",
    "VALIDATION_NAMES",
    "generate_validation",
    "sample_overlap",
]

#: Each system's datasets (:class:`SystemData`): a third system is one module and one entry here.
SYSTEM_DATA: dict[str, SystemData] = {d.system: d for d in (NMSD_DATA, FURUTA_DATA)}

#: Dataset names per system, in the order they are generated and written.
DATASET_NAMES = {name: d.test_names for name, d in SYSTEM_DATA.items()}

#: Validation datasets per system (:func:`generate_validation`): excitations and initial states of
#: their own, inside the training distribution, so that no validation sample is close to a test
#: sample (:func:`sample_overlap`). Recipe choices are scored on these, never on the test sets.
VALIDATION_NAMES = {name: d.validation_names for name, d in SYSTEM_DATA.items()}


def system_data(system: str) -> SystemData:
    """The :class:`SystemData` of ``"furuta"`` or ``"nmsd"``; a clear error for anything else."""
    return SYSTEM_DATA[get_spec(system).name]


def recipe_for(system: str, small: bool = False):
    """The default (or ``small``) recipe of ``"nmsd"`` / ``"furuta"``."""
    cls = system_data(system).recipe
    return cls.small() if small else cls()


#: the rate the generators' sensor model samples at by default (the QUBE's), Hz
SENSOR_RATE_HZ = 500.0


@dataclasses.dataclass(frozen=True)
class _SensorOptions:
    """The data generators' sensor settings before they took the one sensor model
    (:class:`~furuta_gym.sensors.Sensors`) and a ``sensor_rate_hz``: served under their old
    name, ``SensorOptions``, with a DeprecationWarning, and read from old manifests
    (:func:`read_sensor_record`). Fields: ``quantize`` (angles to ``counts_per_rev``),
    ``noise_std`` / ``velocity_noise_std`` (position / exact-velocity noise), ``velocity``,
    ``filter_omega0``, ``filter_xi`` and ``sensor_rate_hz``."""

    quantize: bool = False
    noise_std: float = 0.0
    velocity: Literal["exact", "filter"] = "exact"
    velocity_noise_std: float = 0.0
    sensor_rate_hz: float = SENSOR_RATE_HZ
    filter_omega0: float = 100.0
    filter_xi: float = 0.8
    counts_per_rev: int = ENCODER_COUNTS_PER_REV

    def __post_init__(self):
        if self.velocity_noise_std > 0 and self.velocity == "filter":
            raise ValueError("velocity_noise_std applies to exact velocities, not velocity='filter'")
        _ = self.sensors  # the sensor model's own checks
        _oversample(self.sensor_rate_hz)

    @property
    def sensors(self) -> Sensors:
        """The sensor model these options describe."""
        return Sensors(
            encoder_counts=self.counts_per_rev if self.quantize else None,
            measurement_noise=(self.noise_std, self.velocity_noise_std),
            velocity=self.velocity,
            filter_omega0=self.filter_omega0,
            filter_xi=self.filter_xi,
        )


def _oversample(sensor_rate_hz: float) -> int:
    """How many sensor samples make one data sample; an error unless a whole number."""
    ratio = sensor_rate_hz / DATA_RATE_HZ
    if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
        raise ValueError(f"sensor_rate_hz must be an integer multiple of {DATA_RATE_HZ:g} Hz, got {sensor_rate_hz}")
    return int(round(ratio))


def _sensor_model(sensor: Sensors | _SensorOptions | None, sensor_rate_hz: float) -> tuple[Sensors, float]:
    """The sensor model and the rate it samples at (an old options object carries its own)."""
    if isinstance(sensor, _SensorOptions):
        return sensor.sensors, sensor.sensor_rate_hz
    return sensor or Sensors(), sensor_rate_hz


def sensor_record(sensors: Sensors, sensor_rate_hz: float = SENSOR_RATE_HZ) -> dict:
    """A manifest's ``"sensor"`` record: the sensor model's fields and the rate it sampled at."""
    return {**dataclasses.asdict(sensors), "sensor_rate_hz": float(sensor_rate_hz)}


def read_sensor_record(record: dict) -> tuple[Sensors, float]:
    """``(sensor model, sensor_rate_hz)`` of a manifest's ``"sensor"`` record: the one
    :func:`sensor_record` writes, or the fields of the options object older manifests hold
    (``quantize``, ``noise_std``, ...)."""
    record = dict(record)
    rate = float(record.pop("sensor_rate_hz", SENSOR_RATE_HZ))
    if "quantize" in record:
        return _SensorOptions(**record).sensors, rate
    return Sensors(**record), rate


# --------------------------------------------------------------------------------------------
# Ground truth: x0 (B, 2n), sample times t (T,) on the sensor grid, inputs u (B, T, m) on the
# same grid (linearly interpolated in between) -> states (B, T, 2n) (GroundTruth).
# --------------------------------------------------------------------------------------------


class AnalyticGroundTruth:
    """The pinned analytic model, integrated with classic RK4 at ``substeps`` steps per sensor
    sample, the input linear within each step (so the scheme stays fourth order).

    At the default 4 substeps of a 500 Hz sensor grid it agrees with a tight-tolerance adaptive
    solve (diffrax Tsit5) to round-off scale on these datasets, at a fraction of its cost.
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
            _, xs = jax.lax.scan(interval, x0, (us[:-1], us[1:], jnp.full(us.shape[0] - 1, dt)))
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
    ``substeps`` steps per sensor sample; with ``plant`` (an env :class:`~furuta_gym.envs.Plant`,
    e.g. a diagnosed rig) that plant instead, its ``input_delay`` as the input seen late.

    The input held over each MuJoCo step is the linear interpolation of the samples at the step's
    midpoint (midpoint rule), which tracks the linearly interpolated input to second order.
    """

    def __init__(self, system: str, substeps: int = 4, plant=None):
        self.system = get_spec(system).name
        self.substeps = int(substeps)
        self.plant = plant
        self._backend = MujocoBackend(self.system, substeps=1, plant=plant)
        self._delay = (
            0.0 if plant is None else sum(e.coefficient for e in plant.effects if e.kind.input_dynamics == "delay")
        )

    @property
    def name(self) -> str:
        """``"mujoco"``, or ``"mujoco plant: <the plant's source>"``."""
        return "mujoco" if self.plant is None else f"mujoco plant: {self.plant.source or 'given'}"

    def __call__(self, x0s, t, us):
        dt = float(t[1] - t[0])
        backend = self._backend
        backend.model.opt.timestep = dt / self.substeps
        out = np.empty((x0s.shape[0], len(t), x0s.shape[1]))
        fractions = (np.arange(self.substeps) + 0.5) / self.substeps
        for b in range(x0s.shape[0]):
            backend.reset(np.asarray(x0s[b], dtype=float))
            out[b, 0] = x0s[b]
            u_b = np.asarray(us[b], dtype=float)
            for k in range(len(t) - 1):
                for f in fractions:
                    x = backend.step(self._input(t, u_b, k, f))
                out[b, k + 1] = x
        return out

    def _input(self, t, u, k: int, f: float):
        """The interpolated input the plant sees at ``t[k] + f·dt``: the one commanded ``delay``
        earlier (the first sample's before the record starts)."""
        if self._delay == 0.0:
            return (1.0 - f) * u[k] + f * u[k + 1]
        when = t[k] + f * (t[1] - t[0]) - self._delay
        return np.array([np.interp(when, t, u[:, j]) for j in range(u.shape[1])])


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
# Sensor model: clean sensor-rate states -> measured 100 Hz trajectories
# --------------------------------------------------------------------------------------------


def _measure(clean: Clean, spec, sensors: Sensors, oversample: int, rng) -> Trajectory:
    """The clean sensor-rate states as ``sensors`` read them, subsampled to the data rate. Noise
    is added before the quantisation (as these data always were); the envs add theirs to the
    quantised reading."""
    n = spec.n_dof
    q_true, qd_true = clean.x[:, :n], clean.x[:, n:]
    noise = np.asarray(sensors.noise(spec))
    q = q_true.copy()
    if noise[:n].any():
        q = q + rng.normal(0.0, _std(noise[:n]), size=q.shape)
    steps = sensors.quantization(spec)
    if any(steps):
        q = np.asarray(quantize_joints(q, steps))  # NumPy in, NumPy out
    dt_fine = float(clean.t[1] - clean.t[0])
    qd = _warm_filter(q, qd_true[0], dt_fine, sensors) if sensors.velocity == "filter" else qd_true.copy()
    if noise[n:].any():
        qd = qd + rng.normal(0.0, _std(noise[n:]), size=qd.shape)
    k = oversample
    return Trajectory(t=np.round(clean.t[::k], 10), q=q[::k], u=clean.u[::k], qd=qd[::k], name=clean.name)


def _std(per_joint: np.ndarray):
    """One std for every joint as a float (the draws the data were always made with), else per joint."""
    return float(per_joint[0]) if np.all(per_joint == per_joint[0]) else per_joint


def _warm_filter(q: np.ndarray, qd0: np.ndarray, dt: float, sensors: Sensors) -> np.ndarray:
    """The paper's derivative filter, run after a 0.2 s constant-velocity history ending at x0,
    so the estimate starts on the true velocity instead of a start-up transient."""
    n_warm = int(round(0.2 / dt))
    back = (np.arange(-n_warm, 0) * dt)[:, None]
    history = q[0][None, :] + back * qd0[None, :]
    filtered = derivative_filter(np.concatenate([history, q], axis=0), dt, sensors.filter_omega0, sensors.filter_xi)
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
    sensor: Sensors | None = None,
    ground_truth: GroundTruth | str = "auto",
    sensor_rate_hz: float = SENSOR_RATE_HZ,
) -> dict[str, list[Trajectory]]:
    """Generate the paper's datasets of ``system`` (``"nmsd"``/``"furuta"``) in memory.

    Returns ``{dataset name: [Trajectory, ...]}`` with the names of :data:`DATASET_NAMES`,
    sampled at 100 Hz with velocities. Seeded: the same arguments give the same numbers.
    ``recipe`` overrides :func:`recipe_for` (``small`` picks the scaled-down one); ``sensor``
    measures the states (default: exactly) at ``sensor_rate_hz`` (a multiple of 100 Hz), before
    they are subsampled to 100 Hz;
    ``ground_truth`` is a name for :func:`default_ground_truth` or a callable
    ``(x0s (B, 2n), t (T,), us (B, T, m)) -> states (B, T, 2n)``.
    """
    return _generate(
        system, "test", seed, small, recipe, _sensor_model(sensor, sensor_rate_hz), ground_truth=ground_truth
    )


def generate_validation(
    system: str,
    *,
    seed: int = 0,
    small: bool = False,
    recipe=None,
    sensor: Sensors | None = None,
    ground_truth: GroundTruth | str = "auto",
    sensor_rate_hz: float = SENSOR_RATE_HZ,
) -> dict[str, list[Trajectory]]:
    """The validation datasets of ``system`` (:data:`VALIDATION_NAMES`), with the arguments of
    :func:`generate_datasets`. Furuta: ``val_free`` (12 × 2 s free from the *training* state
    ranges, ending before the pendulum settles where all free trajectories meet), ``val_forced`` (3 × 20 s, a 12-tone multisine over the chirp's 0.5–6 Hz band, new
    phases per trajectory) and ``val_scale_fit`` (20 s of random ±2 V steps held 0.25–1 s);
    N-MSD: ``val_multisine`` (3 × 25 s, 8 tones over 0.1–1.1 Hz) and ``val_steps`` (3 × 15 s of
    random ±5 N steps held 1–3 s), from x0 inside the training trajectory's range. Their overlap
    with the test sets is measured by ``studies/validation_overlap.py`` (docs/reproduce.md)."""
    return _generate(
        system, "validation", seed, small, recipe, _sensor_model(sensor, sensor_rate_hz), ground_truth=ground_truth
    )


_NOISE_STREAM = {"test": 7919, "validation": 7927}  # sensor-noise streams, one per kind


def _generate(system, kind, seed, small, recipe, sensor: tuple[Sensors, float], *, ground_truth):
    spec = get_spec(system)
    sensors, rate = sensor
    oversample = _oversample(rate)
    # a sensor this system cannot have fails here, before the ground truth's work
    sensors.quantization(spec)
    sensors.noise(spec)
    data = system_data(spec.name)
    recipe = recipe if recipe is not None else recipe_for(spec.name, small)
    if not isinstance(recipe, data.recipe):
        raise ValueError(f"recipe for {spec.name} must be a {data.recipe.__name__}, got {recipe!r}")
    gt = default_ground_truth(spec.name, ground_truth) if isinstance(ground_truth, str) else ground_truth
    make, names = (data.make_test, data.test_names) if kind == "test" else (data.make_validation, data.validation_names)
    clean = make(recipe, gt, seed, oversample)
    out = {}
    for name, trajs in clean.items():
        rng = np.random.default_rng([seed, _NOISE_STREAM[kind], names.index(name)])
        out[name] = [_measure(c, spec, sensors, oversample, rng) for c in trajs]
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
    distance, _ = KDTree(b).query(a, k=1, p=np.inf, distance_upper_bound=1.0)
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
                f"{existing[0]}: exists; refusing to overwrite generated data (choose another --out or pass overwrite)"
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


def data_package_versions() -> dict[str, str]:
    """Versions of the packages whose arithmetic makes generated data's bytes: MuJoCo's (its
    integrator and contact solver change between releases), numpy's, jax's and scipy's. A
    manifest records them so that data that no longer regenerate byte for byte say why."""
    return installed_versions(("mujoco", "numpy", "jax", "jaxlib", "scipy"))


def _json_default(o):
    if dataclasses.is_dataclass(o) and not isinstance(o, type):
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
    sensor: Sensors | None = None,
    ground_truth: GroundTruth | str = "auto",
    overwrite: bool = False,
    split: str = "test",
    sensor_rate_hz: float = SENSOR_RATE_HZ,
) -> dict[str, Path]:
    """:func:`generate_datasets` then :func:`write_datasets`; returns ``{name: csv path}``.
    ``split="validation"``: the training set and the validation datasets
    (:func:`generate_validation`) instead of the test sets, which are then never written."""
    sensor, sensor_rate_hz = _sensor_model(sensor, sensor_rate_hz)
    spec = get_spec(system)
    gt = default_ground_truth(spec.name, ground_truth) if isinstance(ground_truth, str) else ground_truth
    recipe = recipe_for(spec.name, small)
    t0 = time.perf_counter()
    if split not in ("test", "validation"):
        raise ValueError(f"split must be 'test' or 'validation', got {split!r}")
    measured = (seed, small, recipe, (sensor, sensor_rate_hz))
    datasets = _generate(spec.name, "test", *measured, ground_truth=gt)
    if split == "validation":
        datasets = {"train": datasets["train"], **_generate(spec.name, "validation", *measured, ground_truth=gt)}
    metadata = {
        "seed": seed,
        **({"split": split} if split != "test" else {}),
        "small": small,
        "rate_hz": DATA_RATE_HZ,
        "recipe": recipe,
        "sensor": sensor_record(sensor, sensor_rate_hz),
        "ground_truth": getattr(gt, "name", type(gt).__name__),
        "input_convention": "u samples linearly interpolated between samples",
        "furuta_gym_version": __version__,
        "packages": data_package_versions(),
        "seconds": round(time.perf_counter() - t0, 2),
    }
    return write_datasets(out_dir, datasets, spec.name, metadata=metadata, overwrite=overwrite)


__getattr__ = deprecated_names(__name__)
