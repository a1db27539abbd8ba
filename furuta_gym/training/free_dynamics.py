"""Is a learned model's free motion physical? Checked against the training logs, needing no scale.

A model can fit an equation-error loss and still move wrongly when let go: on one real free
release, L_Iτ recipes learned a pendulum about twice too fast (docs/learning.md, "Free releases").
Three checks read what the logs say without a model or an overall scale, and compare:

* **frequency**: the small oscillation about each stable equilibrium of the system's definition,
  measured in the logs' free (u = 0) stretches near it by zero crossings, against the model's
  linearised oscillation there (damped by its own τ_NC). A real rig's other joints may stick while the joint oscillates
  (a rotor held by friction), which lowers the frequency towards the one with those joints held,
  √(K_jj / M_jj); the measurement must lie between the model's held and free frequencies, within
  ``tolerance``. Neither depends on the overall scale of L.
* **energy**: along the free stretches the model's own energy T + V must not rise (there is no
  input to supply it); the check reports the share of free trajectories over which a
  least-squares line through E(t) rises by more than ``tolerance`` of E's spread.
* **prediction**: open-loop from the measured state over back-to-back windows of the free
  stretches (``window`` s, u = 0), the model's angle error against that of holding the angles
  where they start. A model that has learned the free dynamics predicts them better than standing
  still; one whose coupling between the joints is wrong (a rotor that should follow the pendulum
  and runs away) does not, even with the right frequency. Scale-free too (u = 0).
* the potential's shape at each equilibrium (:func:`~furuta_gym.training.check_potential_shape`).

:func:`check_free_dynamics` returns all three with a verdict; :func:`warn_free_dynamics` warns
once with :class:`FreeDynamicsWarning` saying in words what is not physical. Training calls it
at the end of every run on data with free stretches and writes the result beside the checkpoint.
"""

from __future__ import annotations

import warnings
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..data import DataError, Trajectory
from ..lagrangian import energy
from ..measured import prediction_windows, window_predictions
from ..models import system_definition
from .consistency import COVERAGE_RADIUS, check_potential_shape

__all__ = [
    "FreeDynamicsWarning",
    "has_free_motion",
    "model_frequencies",
    "measured_frequency",
    "energy_trend",
    "prediction_against_hold",
    "check_free_dynamics",
    "free_dynamics_message",
    "free_dynamics_summary",
    "warn_free_dynamics",
]

#: relative room around the model's [held, free] frequency range, and for the energy's rise
TOLERANCE = 0.15
#: fewest zero crossings (half periods) a frequency is measured from
MIN_CROSSINGS = 6
#: the prediction check's window, s (about one pendulum period)
WINDOW = 0.5


class FreeDynamicsWarning(UserWarning):
    """A learned model's free motion contradicts what its training logs show."""


def has_free_motion(trajs: Sequence[Trajectory]) -> bool:
    """Whether any trajectory has no input and velocities (what the checks read)."""
    return any(tr.qd is not None and not np.any(np.asarray(tr.u) != 0) for tr in trajs)


def model_frequencies(model, q, joint: int, damped: bool = True) -> tuple[float, float]:
    """(free, held) frequency in Hz of the model's small oscillation about the rest ``q`` along
    ``joint``, damped by its own τ_NC (a real rotor's back-EMF and friction slow the pendulum
    measurably): every joint free (the largest |Im λ| of the linearisation), and the other joints
    held (one joint: ω² = K/M − (D/2M)²). Both are unchanged by scaling L and τ_NC together.
    ``damped=False``: without τ_NC, the undamped ω² = eig(M⁻¹K)."""
    q = jnp.asarray(q, dtype=float)
    zero = jnp.zeros_like(q)
    k = np.asarray(jax.hessian(model.potential)(q))
    m = np.asarray(model.mass_matrix(q))
    d = -np.asarray(jax.jacfwd(lambda v: model.nonconservative_force(q, v))(zero)) if damped else 0.0 * k
    n = len(q)
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(m, k), -np.linalg.solve(m, d)]])
    free = float(np.abs(np.imag(np.linalg.eigvals(a))).max())
    held2 = k[joint, joint] / m[joint, joint] - (d[joint, joint] / (2 * m[joint, joint])) ** 2
    return free / (2 * np.pi), float(np.sqrt(max(held2, 0.0)) / (2 * np.pi))


def _free_runs(tr: Trajectory, j: int, centre: float, radius: float) -> list[slice]:
    """Contiguous stretches with no input and joint ``j`` within ``radius`` of ``centre``."""
    u = np.asarray(tr.u, float).reshape(len(tr.t), -1)
    d = np.angle(np.exp(1j * (np.asarray(tr.q, float)[:, j] - centre)))
    ok = np.all(u == 0, axis=1) & (np.abs(d) <= radius)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def measured_frequency(trajs: Sequence[Trajectory], q, joint: int, radius: float = COVERAGE_RADIUS) -> dict:
    """The frequency of the logs' free oscillation about ``q`` along ``joint`` (zero crossings of
    the angle about each stretch's median), and the share of its samples over which every other
    joint stayed on one logged value (held). ``hz`` is None with fewer than :data:`MIN_CROSSINGS`."""
    half_periods, seconds, held, samples = 0, 0.0, 0, 0
    for tr in trajs:
        qs = np.asarray(tr.q, float)
        for run in _free_runs(tr, joint, q[joint], radius):
            x = qs[run, joint] - np.median(qs[run, joint])
            cross = np.flatnonzero(np.signbit(x[1:]) != np.signbit(x[:-1]))
            if len(cross) < 3:
                continue
            half_periods += len(cross) - 1
            seconds += (cross[-1] - cross[0]) * tr.dt
            others = np.delete(qs[run], joint, axis=1)
            held += int(np.sum(np.all(np.diff(others, axis=0) == 0, axis=1)))
            samples += len(x) - 1
    hz = half_periods / (2 * seconds) if half_periods + 1 >= MIN_CROSSINGS and seconds > 0 else None
    return {"hz": hz, "half_periods": half_periods, "held_share": held / samples if samples else None}


def energy_trend(model, trajs: Sequence[Trajectory], tolerance: float = TOLERANCE) -> dict:
    """On trajectories with no input, the model's energy E(q, q̇) along the data: per trajectory,
    the rise of a least-squares line through E over its duration relative to E's spread. Returns
    ``{"n_free", "median_rise", "share_rising"}`` (rising: above ``tolerance``)."""
    e_of = jax.jit(jax.vmap(lambda q, qd: energy(model, q, qd)))
    rises = []
    for tr in trajs:
        if tr.qd is None or np.any(np.asarray(tr.u) != 0) or len(tr.t) < 3:
            continue
        e = np.asarray(e_of(jnp.asarray(tr.q, float), jnp.asarray(tr.qd, float)))
        t = np.asarray(tr.t, float) - tr.t[0]
        spread = float(np.ptp(e))
        if not np.isfinite(spread) or spread == 0:
            continue
        rises.append(float(np.polyfit(t, e, 1)[0] * t[-1] / spread))
    if not rises:
        return {"n_free": 0, "median_rise": None, "share_rising": None}
    return {
        "n_free": len(rises),
        "median_rise": float(np.median(rises)),
        "share_rising": float(np.mean(np.asarray(rises) > tolerance)),
    }


def prediction_against_hold(model, trajs: Sequence[Trajectory], seconds: float = WINDOW) -> dict:
    """Open-loop angle RMSE of ``model`` over free windows (see the module docstring) and of
    holding the start angles; ``ratio`` model / hold (None without free windows). The windows and
    rollouts are :mod:`furuta_gym.measured`'s, as ``evaluate`` scores a model."""
    free = [tr for tr in trajs if tr.qd is not None and not np.any(np.asarray(tr.u) != 0)]
    try:
        x0, us, xs = prediction_windows(free, seconds) if free else (None, None, None)
    except DataError:  # every free trajectory shorter than one window
        x0 = None
    if x0 is None:
        return {"n_windows": 0, "model_rmse": None, "hold_rmse": None, "ratio": None}
    dt = float(np.median([tr.dt for tr in free]))
    n = model.spec.n_dof
    pred = window_predictions(model, x0, us, dt)[:, 1:, :n]
    qs = xs[:, :, :n]
    err = np.where(np.isfinite(pred), pred - qs[:, 1:], 1e6)
    hold = qs[:, 1:] - qs[:, :1]
    model_rmse, hold_rmse = float(np.sqrt(np.mean(err**2))), float(np.sqrt(np.mean(hold**2)))
    ratio = model_rmse / hold_rmse if hold_rmse > 0 else None
    return {"n_windows": int(len(x0)), "model_rmse": model_rmse, "hold_rmse": hold_rmse, "ratio": ratio}


def _frequency_rows(model, trajs, tolerance: float) -> list[dict]:
    definition = system_definition(model.spec)
    names = definition.spec.joint_names
    rows = []
    for e in definition.equilibria:
        if e.shape != "minimum":
            continue
        j = names.index(e.joint)
        free, held = model_frequencies(model, e.q, j)
        meas = measured_frequency(trajs, e.q, j)
        lo, hi = min(free, held) * (1 - tolerance), max(free, held) * (1 + tolerance)
        ok = None if meas["hz"] is None else bool(lo <= meas["hz"] <= hi)
        rows.append(
            {"name": e.name, "joint": e.joint, "model_free_hz": free, "model_held_hz": held, "measured": meas, "ok": ok}
        )
    return rows


def check_free_dynamics(model, trajs: Sequence[Trajectory], tolerance: float = TOLERANCE) -> dict:
    """The three checks of the module docstring on ``trajs`` (velocities needed for the energy).
    ``physical`` is False when any check that could be made fails; checks the data cannot make
    (no free stretch, too few crossings) are reported as None and do not fail it."""
    frequency = _frequency_rows(model, trajs, tolerance)
    trend = energy_trend(model, trajs, tolerance)
    prediction = prediction_against_hold(model, trajs)
    shape = check_potential_shape(model)
    energy_ok = None if trend["share_rising"] is None else bool(trend["share_rising"] <= 0.5)
    prediction_ok = None if prediction["ratio"] is None else bool(prediction["ratio"] < 1.0)
    verdicts = [r["ok"] for r in frequency] + [energy_ok, prediction_ok, shape["physical"]]
    return {
        "physical": all(v is not False for v in verdicts),
        "tolerance": tolerance,
        "frequency": frequency,
        "energy": {**trend, "ok": energy_ok},
        "prediction": {**prediction, "window_seconds": WINDOW, "ok": prediction_ok},
        "potential_shape": shape,
    }


def free_dynamics_message(result: dict) -> str | None:
    """What is not physical, in words, or None."""
    parts = []
    for r in result["frequency"]:
        if r["ok"] is False:
            f = r["measured"]["hz"]
            parts.append(
                f"about {r['name']} the logs' free oscillation is {f:.3g} Hz (zero crossings, no scale "
                f"needed) but the model's is {r['model_free_hz']:.3g} Hz with every joint free and "
                f"{r['model_held_hz']:.3g} Hz with the others held ({f / r['model_free_hz'] - 1:+.0%} "
                "against the free one)"
            )
    if result["energy"]["ok"] is False:
        parts.append(
            f"its energy rises along {result['energy']['share_rising']:.0%} of the free (u = 0) trajectories, "
            "with nothing to supply it"
        )
    p = result["prediction"]
    if p["ok"] is False:
        parts.append(
            f"predicted open loop over {p['window_seconds']:g} s of its own free training data it is "
            f"{p['ratio']:.2g}x further off ({1e3 * p['model_rmse']:.0f} mrad) than holding the angles still "
            f"({1e3 * p['hold_rmse']:.0f} mrad)"
        )
    if not parts:  # a wrong potential shape has its own warning (PotentialShapeWarning)
        return None
    return (
        "the trained model's free motion is not physical: " + "; ".join(parts) + ". Open-loop predictions "
        "and controllers designed on it will be wrong; more or more varied data, or a recipe with a "
        "trajectory stage, may fix it (docs/learning.md, 'Free releases')."
    )


def free_dynamics_summary(result: dict) -> str:
    """One line for a terminal: each check's numbers and the verdict."""
    parts = []
    for r in result["frequency"]:
        f = r["measured"]["hz"]
        seen = "not measurable (too few free oscillations)" if f is None else f"{f:.3g} Hz in the logs"
        parts.append(
            f"oscillation about {r['name']} {seen}, model {r['model_free_hz']:.3g} Hz free / "
            f"{r['model_held_hz']:.3g} Hz others held"
        )
    e = result["energy"]
    if e["share_rising"] is not None:
        parts.append(f"energy rises on {e['share_rising']:.0%} of {e['n_free']} free trajectories")
    p = result["prediction"]
    if p["ratio"] is not None:
        parts.append(f"open loop over {p['window_seconds']:g} s {p['ratio']:.2g}x the error of holding still")
    verdict = "physical" if result["physical"] else "NOT physical"
    return f"free-motion check: {'; '.join(parts)}: {verdict}"


def warn_free_dynamics(model, trajs: Sequence[Trajectory], *, stacklevel: int = 2) -> dict:
    """:func:`check_free_dynamics`, and one :class:`FreeDynamicsWarning` if it is not physical."""
    result = check_free_dynamics(model, trajs)
    message = free_dynamics_message(result)
    if message is not None:
        warnings.warn(message, FreeDynamicsWarning, stacklevel=stacklevel + 1)
    return result
