"""The training losses of Laiche et al. 2026, §3: L_traj, L_aph, the integral inverse loss L_Iτ, L_prop.

Data enter as :class:`Windows` — equal-length slices of trajectories stacked into arrays, so that
every loss is one ``jax.vmap`` over windows and jit-friendly:

* :func:`trajectory_loss` — L_traj: from each window's first state, predict the rest with
  :func:`furuta_gym.simulate.simulate` (diffrax Tsit5, PID controller rtol 1e-3 / atol 1e-6, the
  input interpolated linearly) and average ‖x − x̂‖² over predicted samples and windows. (The
  paper writes a sum; a mean keeps the magnitude independent of the batch size.)
* :func:`integral_loss` — L_Iτ: Σ‖Z̄ − Ā‖² exactly as the paper's trapezoid formula, computed by
  :func:`furuta_gym.lagrangian.integral_residual` (``rule="trapezoid"``; ``"simpson"`` lowers the
  quadrature floor, ``"hermite"`` all but removes it by resolving the motion between samples from
  the measured q and q̇), divided by a normaliser (see below).
* :func:`augmentation_penalty` — APHYNITY's ‖F_a‖²: the mean squared data-driven force over the
  window samples, in units of the model's ``force_scale``.
* :func:`aphynity_loss` = ‖F_a‖² + λ·L_traj; :func:`proposed_loss` = L_Iτ + λ·L_traj, plus
  μ·P_a for models with a data-driven force F_a (APHYNITY, augmented DeLaN): P_a =
  Σ‖∫M̂⁻¹F_a dt‖² / Σ‖Δq̇‖², APHYNITY's minimum-norm principle integrated over L_Iτ's intervals
  (:func:`integral_loss_terms` says why L_Iτ needs it).

**Normalising L_Iτ (scale collapse).** On free data (u = 0) Z̄ = 0 and L_Iτ is minimised by L = 0,
τ_NC = 0. ``normalize="momentum"`` divides by Σ‖Δp̂‖², the model's own momentum changes over the
same intervals (with gradient): the ratio is invariant to the overall scale of (L, τ_NC), so the
collapse earns nothing and the scale is left to the forced-trajectory fit. On forced data the
input pins the scale; ``"momentum_fixed"`` divides by the same quantity with its gradient stopped,
i.e. only fixes the units (raw impulses of the Furuta are ~1e-5 N·m·s, below Adam's ε).
``"auto"`` (default) picks ``"momentum"`` when the batch has no input and ``"momentum_fixed"``
otherwise; ``"none"`` is the paper's plain sum of squares divided by the number of intervals.
``"joint_momentum"`` divides each joint's sum by that joint's own Σ‖Δp̂_j‖² and adds the joints:
scale-free like ``"momentum"``, but a model cannot lower the weight of a joint whose equation it
cannot satisfy (forces it cannot express, such as a rotor's cable spring and dry friction under a
periodic potential and viscous damping) by shrinking that joint's row of M and its damping, which
on free releases, where the rotor's momentum hardly changes, costs the other joint's equation little.
"""

from __future__ import annotations

import contextlib
import os
from typing import Any, Literal, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..data import Trajectory
from ..lagrangian import (
    QuadratureRule,
    integral_residual,
    interval_difference,
    interval_quadrature,
    momentum,
    quadrature_consistency,
    solve_mass_matrix,
)
from ..simulate import simulate

__all__ = [
    "Windows",
    "make_windows",
    "trajectory_loss",
    "integral_loss",
    "integral_loss_terms",
    "augmentation_penalty",
    "aphynity_loss",
    "proposed_loss",
    "aphynity_lambda_update",
    "resolve_normalization",
    "resolution_weights",
    "span_sum",
    "Normalization",
    "NORMALIZATIONS",
]

Normalization = Literal["auto", "momentum", "momentum_fixed", "joint_momentum", "none"]
NORMALIZATIONS = ("auto", "momentum", "momentum_fixed", "joint_momentum", "none")


class Windows(NamedTuple):
    """Equal-length trajectory slices: ``t`` (B, W), ``x`` = (q, q̇) (B, W, 2n), ``u`` (B, W, m)."""

    t: Float[Array, "B W"]
    x: Float[Array, "B W s"]
    u: Float[Array, "B W m"]

    @property
    def n_windows(self) -> int:
        return int(self.t.shape[0])

    @property
    def length(self) -> int:
        return int(self.t.shape[1])

    def take(self, index) -> "Windows":
        """The windows at ``index`` (an integer array), as a new batch."""
        return Windows(self.t[index], self.x[index], self.u[index])


def _window_starts(T: int, length: int, stride: int, cover_end: bool) -> list[int]:
    starts = list(range(0, T - length + 1, stride))
    if cover_end and starts and starts[-1] != T - length:
        starts.append(T - length)  # last window aligned to the end: every interval is covered
    return starts


def make_windows(trajs: Sequence[Trajectory], length: int, stride: int = 1, *, cover_end: bool = False) -> Windows:
    """Cut trajectories into windows of ``length`` samples every ``stride`` samples.

    Trajectories shorter than ``length`` are skipped; with ``cover_end`` a last window aligned to
    each trajectory's end is added so every sampling interval lies in some window (used for
    L_Iτ: stride ``length − 1`` then tiles the trajectory). Velocities are required.
    """
    if length < 2:
        raise ValueError(f"window length must be at least 2 samples, got {length}")
    if stride < 1:
        raise ValueError(f"window stride must be at least 1, got {stride}")
    ts, xs, us = [], [], []
    for tr in trajs:
        if tr.qd is None:
            raise ValueError(
                f"trajectory {tr.name!r} has no velocities; training needs q̇ (estimate it with "
                "furuta_gym.signals.derivative_filter or zero_phase_velocity)"
            )
        x = np.concatenate([np.asarray(tr.q, float), np.asarray(tr.qd, float)], axis=1)
        t = np.asarray(tr.t, float)
        u = np.asarray(tr.u, float).reshape(len(t), -1)
        for s in _window_starts(len(t), length, stride, cover_end):
            ts.append(t[s : s + length])
            xs.append(x[s : s + length])
            us.append(u[s : s + length])
    if not ts:
        raise ValueError(
            f"no trajectory has {length} samples; shortest has {min(len(tr) for tr in trajs) if trajs else 0}"
        )
    return Windows(jnp.asarray(np.stack(ts)), jnp.asarray(np.stack(xs)), jnp.asarray(np.stack(us)))


@contextlib.contextmanager
def _runtime_checks_as_nan():
    """While tracing, Equinox runtime checks (``eqx.error_if``) inside diffrax become NaNs.

    diffrax checks its traced inputs (``ts`` increasing, save times inside [t0, t1], the sign of
    dt0) with ``eqx.error_if``, which by default lowers to a host callback; JAX never stores an
    executable with host callbacks in its persistent compilation cache, so every process would
    recompile the L_traj step from scratch. Equinox's ``"nan"`` mode instead returns NaN from a
    failed check: the loss turns non-finite and the training loop's NaN guard skips the step, as
    it does for a solve that fails (``throw=False``). The windows come from validated
    trajectories (:func:`make_windows`), so these checks cannot fire on real data anyway.

    Equinox exposes the mode only globally (the ``EQX_ON_ERROR`` environment variable, read at
    import). Here the checks traced inside the block ask for ``on_error="nan"`` explicitly —
    a separate entry of Equinox's jit cache, so neither earlier nor later traces of the same
    check elsewhere (e.g. :func:`~furuta_gym.simulate.simulate` with ``throw=True``) change
    behaviour. A user's explicit ``EQX_ON_ERROR`` wins; if Equinox's internals differ from what
    this expects it does nothing (the step is then just not cacheable). Not thread-safe against
    another thread tracing Equinox checks at the same moment.
    """
    try:
        from equinox import _errors  # noqa: PLC0415  Equinox internals that may move: inside the try

        checked = _errors.branched_error_if_impl_jit
    except (ImportError, AttributeError):  # pragma: no cover - another Equinox layout
        yield
        return
    if "EQX_ON_ERROR" in os.environ:
        yield
        return

    def as_nan(x, pred, index, msgs, *, on_error: Any = "default"):
        return checked(x, pred, index, msgs, on_error="nan" if on_error == "default" else on_error)

    _errors.branched_error_if_impl_jit = as_nan
    try:
        yield
    finally:
        _errors.branched_error_if_impl_jit = checked


def _predict(model, t, x, u, rtol, atol, max_steps):
    return simulate(
        model,
        x[0],
        t - t[0],
        u,
        input_interpolation="linear",
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        throw=False,
    )


def trajectory_loss(
    model,
    windows: Windows,
    *,
    rtol: float = 1e-3,
    atol: float = 1e-6,
    max_steps: int = 4096,
) -> Float[Array, ""]:
    """L_traj: mean over windows and predicted samples of ‖x − x̂‖² (open loop from x[0]).

    A solve that fails (e.g. hits ``max_steps``) returns ``inf`` (not an exception), which the
    training loop's NaN guard skips; so does a failed diffrax input check (NaN, see
    :func:`_runtime_checks_as_nan`). Without host callbacks the compiled step can be stored in
    JAX's persistent compilation cache.
    """
    with _runtime_checks_as_nan():
        pred = jax.vmap(lambda t, x, u: _predict(model, t, x, u, rtol, atol, max_steps))(
            windows.t, windows.x, windows.u
        )
    err = pred[:, 1:] - windows.x[:, 1:]
    return jnp.mean(jnp.sum(err**2, axis=-1))


#: what P_a measures: all of F_a, or F_a beyond its linear viscous term
AUGMENTATION_PARTS = ("full", "beyond_linear")


def resolution_weights(
    windows: Windows, n_dof: int, rule: QuadratureRule, tolerance: float | None
) -> Float[Array, "B K"]:
    """Per window and quadrature interval, 1 / (1 + (e / tolerance)²) with e the norm over joints
    of :func:`~furuta_gym.lagrangian.quadrature_consistency` (∫q̇ dt − Δq, from the data alone);
    all ones when ``tolerance`` is None.

    Weighted least squares with the quadrature error as the noise: an interval whose motion the
    sampling under-resolves carries a residual of the order of e however good the model, so its
    weight falls as 1/e² and each such interval counts about as much as one at e = tolerance
    instead of dominating the sum (see :class:`~furuta_gym.training.train.TrainSettings`).
    """

    def one(t, x):
        e = quadrature_consistency(x[:, :n_dof], x[:, n_dof:], t[1] - t[0], rule)
        if tolerance is None:
            return jnp.ones(e.shape[0])
        return 1.0 / (1.0 + jnp.sum(e**2, axis=-1) / tolerance**2)

    return jax.vmap(one)(windows.t, windows.x)


def span_sum(x: Float[Array, " K *rest"], span: int) -> Float[Array, " G *rest"]:
    """Sums of ``span`` consecutive quadrature intervals (the last group may be shorter).

    The integral residual is additive over intervals (the momentum difference telescopes), so a
    group's sum is exactly the residual over the group's longer interval: the paper's equation
    on [t_k, t_{k+span}] with the integrands still resolved at every sample.
    """
    if span == 1:
        return x
    groups = -(-x.shape[0] // span)
    pad = jnp.zeros((groups * span - x.shape[0], *x.shape[1:]), x.dtype)
    return jnp.concatenate([x, pad]).reshape(groups, span, *x.shape[1:]).sum(axis=1)


def _integral_parts(
    model,
    windows: Windows,
    rule: QuadratureRule,
    with_augmentation: bool = False,
    augmentation_part: str = "full",
    span: int = 1,
):
    """Per window: the residual Z̄ − Ā and the model's momentum changes Δp̂ over the quadrature
    intervals (summed ``span`` at a time) and, if asked, the velocity changes the data-driven
    force accounts for, ∫M̂⁻¹F_a dt, with the data's own velocity changes Δq̇ over the same
    intervals."""
    n = model.spec.n_dof

    def one(t, x, u):
        q, qd = x[:, :n], x[:, n:]
        dt = t[1] - t[0]
        r = span_sum(integral_residual(model, q, qd, u, dt, rule), span)
        p = jax.vmap(lambda q_, qd_: momentum(model, q_, qd_))(q, qd)
        dp = span_sum(interval_difference(p, rule), span)
        if not with_augmentation:
            return r, dp, None, None
        force = model.augmentation if augmentation_part == "full" else model.augmentation_beyond_linear
        acc = interval_quadrature(
            lambda q_, qd_, u_: solve_mass_matrix(model.mass_matrix(q_), force(q_, qd_)), q, qd, u, dt, rule
        )
        return r, dp, span_sum(acc, span), span_sum(interval_difference(qd, rule), span)

    return jax.vmap(one)(windows.t, windows.x, windows.u)


def _normalised(r2, dp, normalize: str, size):
    """L_Iτ from the (…, n) squared residuals ``r2`` and momentum changes ``dp``."""
    if normalize == "joint_momentum":
        per_joint = tuple(range(r2.ndim - 1))
        return jnp.sum(jnp.sum(r2, axis=per_joint) / jnp.sum(dp**2, axis=per_joint))
    sq = jnp.sum(r2)
    if normalize == "momentum":
        return sq / jnp.sum(dp**2)
    if normalize == "momentum_fixed":
        return sq / jax.lax.stop_gradient(jnp.sum(dp**2))
    if normalize == "none":
        return sq / size
    raise ValueError(f"normalize must be one of {NORMALIZATIONS[1:]} or 'auto', got {normalize!r}")


def integral_loss(
    model,
    windows: Windows,
    *,
    rule: QuadratureRule = "trapezoid",
    normalize: Normalization = "auto",
    resolution_tolerance: float | None = None,
    span: int = 1,
) -> Float[Array, ""]:
    """L_Iτ = Σ‖Z̄ − Ā‖² over windows, intervals and joints, divided by the normaliser.

    See the module docstring for ``normalize``; with ``"momentum"`` the value is the squared
    residual relative to the model's own momentum changes (dimensionless).
    ``resolution_tolerance`` and ``span``: see :func:`integral_loss_terms`.
    """
    return integral_loss_terms(
        model, windows, rule=rule, normalize=normalize, resolution_tolerance=resolution_tolerance, span=span
    )[0]


def integral_loss_terms(
    model,
    windows: Windows,
    *,
    rule: QuadratureRule = "trapezoid",
    normalize: Normalization = "auto",
    with_augmentation: bool = False,
    augmentation_part: str = "full",
    resolution_tolerance: float | None = None,
    span: int = 1,
) -> tuple[Float[Array, ""], Float[Array, ""] | None]:
    """``(L_Iτ, P_a)``: L_Iτ as :func:`integral_loss` and, with ``with_augmentation``, the share
    of the data's velocity changes that the data-driven force accounts for,
    P_a = Σ‖∫M̂⁻¹F_a dt‖² / Σ‖Δq̇‖² over the same intervals (``None`` otherwise).

    P_a is APHYNITY's minimum-norm principle (Yin et al. 2021: the smallest F_a in the state
    derivative, i.e. in accelerations), integrated like L_Iτ so no accelerations are measured.
    L_Iτ alone cannot say what F_a should hold: with a general F_a(q, q̇) any position-dependent
    force (gravity) or any change of M can be moved into F_a at no cost. In accelerations the
    choice is clean: the conservative part M̂⁻¹(−C q̇ − ∇V) is even in q̇ and viscous friction is
    odd, so on data symmetric in q̇ the smallest M̂⁻¹F_a leaves exactly the friction to F_a.
    Measured in forces and divided by the model's own Δp̂ instead, a learned M can inflate the
    denominator and the minimum is not physical (augmented DeLaN found one). P_a is invariant to
    the overall scale (M̂ and F_a scale together) and its denominator is data, so it cannot be
    gamed by the model; a small weight μ breaks the ties L_Iτ leaves while costing the fit little.

    ``augmentation_part="beyond_linear"`` measures only what F_a adds to its linear viscous term
    W·q̇ (:meth:`ForceNetwork.beyond_linear`): the minimum-norm principle then asks for the
    least force beyond textbook viscous friction instead of the least force, so it no longer
    pulls the damping itself towards zero.

    ``resolution_tolerance`` (position units, rad or m; None: off) weights each interval's
    squared residual, and its Δp̂² in the normaliser, by :func:`resolution_weights`.

    ``span`` (1: the paper's intervals) sums the residual over ``span`` consecutive quadrature
    intervals before squaring (:func:`span_sum`). Velocities estimated from encoder counts carry
    an error that enters each interval's residual through the momentum at its two ends; over a
    longer interval that error stays the same size while the physics' impulse grows with the
    interval, so on such data a span of a few estimator time constants lets the potential, not
    the estimator's noise, decide the fit.
    """
    if not (isinstance(span, (int, np.integer)) and span >= 1):
        raise ValueError(f"span must be a positive integer (quadrature intervals per residual), got {span!r}")
    if span > 1 and resolution_tolerance is not None:
        raise ValueError("span > 1 and resolution_tolerance cannot be combined: the weights are per interval")
    if augmentation_part not in AUGMENTATION_PARTS:
        raise ValueError(f"augmentation_part must be one of {AUGMENTATION_PARTS}, got {augmentation_part!r}")
    if normalize == "auto":
        normalize = resolve_normalization(windows)
    if resolution_tolerance is not None and not resolution_tolerance > 0:
        raise ValueError(f"resolution_tolerance must be positive or None, got {resolution_tolerance!r}")
    r, dp, acc, dqd = _integral_parts(model, windows, rule, with_augmentation, augmentation_part, int(span))
    if resolution_tolerance is None:
        itau = _normalised(r**2, dp, normalize, r.size)
    else:
        w = resolution_weights(windows, model.spec.n_dof, rule, resolution_tolerance)[..., None]
        itau = _normalised(w * r**2, jnp.sqrt(w) * dp, normalize, jnp.sum(w) * r.shape[-1])
    share = None if acc is None else jnp.sum(acc**2) / jnp.sum(dqd**2)
    return itau, share


def resolve_normalization(windows: Windows) -> Normalization:
    """What ``normalize="auto"`` means for this data: "momentum" if free (u ≡ 0), else "momentum_fixed".

    Needs concrete data; inside ``jax.jit`` resolve it beforehand and pass the result.
    """
    try:
        u = np.asarray(windows.u)
    except jax.errors.TracerArrayConversionError:
        raise ValueError(
            "normalize='auto' needs concrete data; inside jit pass resolve_normalization(windows)"
        ) from None
    return "momentum" if not np.any(u != 0) else "momentum_fixed"


def augmentation_penalty(model, windows: Windows) -> Float[Array, ""]:
    """APHYNITY's ‖F_a‖²: mean over all window samples of ‖F_a(q, q̇) / force_scale‖²."""
    if not getattr(model, "has_augmentation", False):
        raise ValueError(
            f"the APHYNITY penalty needs a model with a data-driven force F_a (aph or adln), got {type(model).__name__}"
        )
    n = model.spec.n_dof
    x = windows.x.reshape(-1, windows.x.shape[-1])
    fa = jax.vmap(lambda s: model.augmentation(s[:n], s[n:]))(x)
    return jnp.mean(jnp.sum((fa / model.force_net.force_scale) ** 2, axis=-1))


def aphynity_loss(model, windows: Windows, lam, **traj_kwargs) -> Float[Array, ""]:
    """L_aph = ‖F_a‖² + λ·L_traj (paper eq. 5; λ updated by :func:`aphynity_lambda_update`)."""
    return augmentation_penalty(model, windows) + lam * trajectory_loss(model, windows, **traj_kwargs)


def proposed_loss(
    model,
    integral_windows: Windows,
    trajectory_windows: Windows,
    lam,
    *,
    rule: QuadratureRule = "trapezoid",
    normalize: Normalization = "auto",
    augmentation_weight: float = 0.0,
    resolution_tolerance: float | None = None,
    **traj_kwargs,
) -> Float[Array, ""]:
    """L_prop = L_Iτ + λ·L_traj (paper eq. 11) + μ·P_a with μ = ``augmentation_weight`` (models
    with F_a only; see :func:`integral_loss_terms`, also for ``resolution_tolerance``)."""
    itau, share = integral_loss_terms(
        model,
        integral_windows,
        rule=rule,
        normalize=normalize,
        with_augmentation=augmentation_weight != 0.0,
        resolution_tolerance=resolution_tolerance,
    )
    total = itau + lam * trajectory_loss(model, trajectory_windows, **traj_kwargs)
    return total if share is None else total + augmentation_weight * share


def aphynity_lambda_update(lam: float, trajectory_loss_value: float, step: float) -> float:
    """APHYNITY's dual ascent on the trajectory constraint: λ ← λ + τ₂·L_traj (Yin et al. 2021)."""
    return float(lam) + float(step) * float(trajectory_loss_value)
