"""Input signals and sensor models shared by data generation, the envs and diagnosis.

Inputs: :func:`chirp` (linear frequency sweep, the paper's training and test inputs) and
:func:`square_pulse`. Sensors: :func:`quantize_encoder` (2048 counts/rev on the QUBE-Servo 2),
:func:`derivative_filter` (the paper's causal velocity estimate F(s) = ω0²s/(s²+2ξω0s+ω0²),
ω0 = 100 rad/s, ξ = 0.8) and :func:`zero_phase_velocity` (offline, no lag).
"""

from __future__ import annotations

from typing import cast

import jax
import jax.numpy as jnp
import numpy as np
import scipy  # scipy.signal loads on first use: a slow import that an env without filtered sensors never needs

__all__ = [
    "ENCODER_COUNTS_PER_REV",
    "chirp",
    "square_pulse",
    "multisine",
    "random_steps",
    "quantize_encoder",
    "quantize_joints",
    "derivative_filter",
    "derivative_filter_coefficients",
    "DerivativeFilter",
    "zero_phase_velocity",
]

ENCODER_COUNTS_PER_REV = 2048


def chirp(t, f0: float, f1: float, t1: float, amplitude: float = 1.0, phase: float = 0.0):
    """Linear chirp amplitude·sin(2π(f0 t + (f1 − f0) t²/(2 t1)) + phase); f0 Hz at 0, f1 Hz at t1."""
    t = np.asarray(t, dtype=float)
    return amplitude * np.sin(2.0 * np.pi * (f0 * t + 0.5 * (f1 - f0) / t1 * t**2) + phase)


def square_pulse(t, start: float, width: float, amplitude: float = 1.0):
    """amplitude on [start, start + width), 0 elsewhere (the paper's N-MSD "square" test input)."""
    t = np.asarray(t, dtype=float)
    return np.where((t >= start) & (t < start + width), amplitude, 0.0)


def multisine(t, f0: float, f1: float, n_tones: int, amplitude: float, rng: np.random.Generator):
    """Sum of ``n_tones`` sines at log-spaced frequencies from f0 to f1 Hz with random phases
    (drawn from ``rng``), scaled so that its peak over ``t`` is ``amplitude``."""
    t = np.asarray(t, dtype=float)
    freqs = np.geomspace(f0, f1, n_tones)
    phases = rng.uniform(0.0, 2.0 * np.pi, n_tones)
    y = np.sin(2.0 * np.pi * freqs[:, None] * t[None, :] + phases[:, None]).sum(axis=0)
    return amplitude * y / max(np.abs(y).max(), 1e-12)


def random_steps(t, hold_range: tuple[float, float], amplitude: float, rng: np.random.Generator):
    """Piecewise-constant levels ~ U(−amplitude, amplitude), each held for a time
    ~ U(*hold_range) s (drawn from ``rng``)."""
    t = np.asarray(t, dtype=float)
    edges = [float(t[0]) if t.size else 0.0]
    while edges[-1] <= (t[-1] if t.size else 0.0):
        edges.append(edges[-1] + rng.uniform(*hold_range))
    levels = rng.uniform(-amplitude, amplitude, len(edges))
    return levels[np.searchsorted(edges, t, side="right") - 1]


def quantize_encoder(angle, counts_per_rev: int = ENCODER_COUNTS_PER_REV):
    """Round an angle to the encoder's resolution 2π/counts_per_rev (see :func:`quantize_joints`)."""
    return quantize_joints(angle, 2.0 * np.pi / counts_per_rev)


def quantize_joints(q, steps):
    """Round each joint's coordinate to its own quantisation step (a step of 0: exact).

    NumPy in, NumPy out; a JAX array (or a traced value inside ``jax.jit``) in, JAX out — the
    one encoder model the envs (single and batched), the data generation and the controllers'
    JAX sensor model share.
    """
    xp = jnp if isinstance(q, jax.Array) else np
    q = q if xp is jnp else np.asarray(q, dtype=float)
    steps = xp.asarray(steps, dtype=q.dtype)
    safe = xp.where(steps > 0, steps, 1.0)
    return xp.where(steps > 0, xp.round(q / safe) * steps, q)


def derivative_filter_coefficients(dt: float, omega0: float = 100.0, xi: float = 0.8):
    """(b, a) of the paper's derivative filter discretised with the bilinear transform, a[0] = 1.

    The one definition used by :func:`derivative_filter`, :class:`DerivativeFilter` and the
    controllers' JAX sensor model.
    """
    num = [omega0**2, 0.0]
    den = [1.0, 2.0 * xi * omega0, omega0**2]
    b, a, _ = cast(tuple, scipy.signal.cont2discrete((num, den), dt, method="bilinear"))  # (num, den, dt)
    b, a = np.ravel(b), np.ravel(a)
    return b / a[0], a / a[0]


class DerivativeFilter:
    """Streaming form of :func:`derivative_filter`, one sample at a time (for envs/controllers).

    The first sample initialises the filter at rest at that position (velocity estimate 0).
    """

    def __init__(self, dt: float, n_channels: int, omega0: float = 100.0, xi: float = 0.8):
        self.b, self.a = derivative_filter_coefficients(dt, omega0, xi)
        self._zi_unit = scipy.signal.lfilter_zi(self.b, self.a)
        self.n_channels = n_channels
        self._z = None

    def reset(self, y0) -> None:
        """Restart the filter at rest at position ``y0`` (velocity estimate 0)."""
        y0 = np.asarray(y0, dtype=float).reshape(self.n_channels)
        # steady state for a constant input y0: derivative 0
        self._z = np.outer(self._zi_unit, y0)

    def __call__(self, y):
        y = np.asarray(y, dtype=float).reshape(self.n_channels)
        if self._z is None:
            self.reset(y)
        out = np.empty(self.n_channels)
        for c in range(self.n_channels):
            o, self._z[:, c] = scipy.signal.lfilter(self.b, self.a, [y[c]], zi=self._z[:, c])
            out[c] = o[0]
        return out


def derivative_filter(y, dt: float, omega0: float = 100.0, xi: float = 0.8):
    """Causal velocity estimate of ``y`` (samples along axis 0), the paper's derivative filter.

    Discretised with the bilinear transform; starts at rest at ``y[0]``. Lags by ≈ 2ξ/ω0 = 16 ms.
    """
    y = np.asarray(y, dtype=float)
    b, a = derivative_filter_coefficients(dt, omega0, xi)
    zi = scipy.signal.lfilter_zi(b, a)
    zi = zi.reshape((-1,) + (1,) * (y.ndim - 1)) * y[:1]
    out, _ = scipy.signal.lfilter(b, a, y, axis=0, zi=zi)
    return out


def zero_phase_velocity(y, dt: float, cutoff_hz: float | None = None, order: int = 4):
    """Offline velocity estimate without lag: Butterworth low-pass run forwards and backwards
    (filtfilt), then central differences. ``cutoff_hz`` defaults to min(25 Hz, 0.4·Nyquist)."""
    y = np.asarray(y, dtype=float)
    fs = 1.0 / dt
    if cutoff_hz is None:
        cutoff_hz = min(25.0, 0.2 * fs)
    b, a = cast(tuple, scipy.signal.butter(order, cutoff_hz, fs=fs))  # (b, a) in its default output
    padlen = min(3 * max(len(a), len(b)), y.shape[0] - 1)
    smooth = scipy.signal.filtfilt(b, a, y, axis=0, padlen=padlen)
    return np.gradient(smooth, dt, axis=0)
