"""Integrating any Lagrangian system: adaptive diffrax solves and fixed-step zero-order-hold steps.

Two ways to turn the protocol's vector field into trajectories, used everywhere else:

* :func:`simulate` — diffrax Tsit5 with a PID step-size controller, the input linearly interpolated
  between samples (the paper's appendix) or held (zero-order hold). Differentiable; used by the
  trajectory loss, by evaluation and as the tight-tolerance reference in tests.
* :func:`rk4_zoh_step` / :func:`rollout_zoh` — classic fixed-step RK4 with the input held over the
  control period, as a digital controller drives hardware. This is the same scheme MuJoCo's
  ``RK4`` integrator uses, so a model backend and the MuJoCo backend agree to integration
  round-off when they share the substep. Used by the model-backed envs and batched rollouts.
"""

from __future__ import annotations

from typing import Callable, Literal

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .lagrangian import AbstractLagrangianSystem, vector_field

__all__ = ["simulate", "rk4_step", "rk4_zoh_step", "rollout_zoh", "small_kernel_compiler_options", "DIVERGED"]

#: Table value of a prediction that diverged for at least one test trajectory (paper's "X")
DIVERGED = "X"

# XLA:CPU by default hands matrix products *together with the elementwise work around them* to
# YNNPACK "custom fusions"; for the few-neuron layers of these models those fused calls cost more
# than XLA's own loops, and YNNPACK for the bare products alone is fastest (docs/batched.md,
# "Speed"). Same quantities; summation order inside a product may differ at round-off level.
_SMALL_KERNEL_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": "LIBRARY_FUSION_TYPE_INDIVIDUAL_DOT"}
_small_kernel_options_checked: dict | None = None


def small_kernel_compiler_options() -> dict:
    """``compiler_options`` for ``jax.jit`` of fixed-step model integration on CPU: YNNPACK for
    individual matrix products only (no fused elementwise work). Empty when this jaxlib does not
    know the option (checked once)."""
    global _small_kernel_options_checked
    if _small_kernel_options_checked is None:
        try:
            jax.jit(lambda a: a + 1.0, compiler_options=_SMALL_KERNEL_OPTIONS).lower(1.0).compile()
            _small_kernel_options_checked = dict(_SMALL_KERNEL_OPTIONS)
        except Exception:  # an unknown option name is an error at compile time
            _small_kernel_options_checked = {}
    return dict(_small_kernel_options_checked)


def simulate(
    system: AbstractLagrangianSystem,
    x0: Float[Array, " 2n"],
    ts: Float[Array, " T"],
    us: Float[Array, "T m"] | Callable | None = None,
    *,
    input_interpolation: Literal["linear", "zoh"] = "linear",
    rtol: float = 1e-3,
    atol: float = 1e-6,
    max_steps: int | None = 100_000,
    dt0: float | None = None,
    adjoint: diffrax.AbstractAdjoint | None = None,
    throw: bool = True,
) -> Float[Array, "T 2n"]:
    """Solve ẋ = f(x, u(t)) from ``x0`` and return the state at every time in ``ts``.

    ``us`` are input samples at ``ts`` (zeros when omitted); between samples the input is
    interpolated linearly (default, as in the paper) or held (``"zoh"``). ``us`` may also be a
    JAX-traceable function ``u(t) -> (m,)`` for a continuous-time input (then
    ``input_interpolation`` is ignored). Defaults are the paper's
    training tolerances (rtol 1e-3, atol 1e-6); tests use 1e-10/1e-12 for a reference solution.
    With ``throw=False`` a failed solve returns ``inf`` past the failure instead of raising, so
    a diverging learned model shows up as a non-finite prediction.
    """
    ts = jnp.asarray(ts)
    u_at, jump_ts = _input_of_time(us, ts, system.spec.n_inputs, input_interpolation)

    def f(t, x, args):
        return _vector_field_once(system, x, u_at(t))

    # diffrax >= 0.7 moved jump_ts to ClipStepSizeController (and builds one from this call); the
    # lowest supported diffrax, 0.6.1, has only this form
    controller = diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=jump_ts)  # pyright: ignore[reportCallIssue]
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(f),
        diffrax.Tsit5(),
        t0=ts[0],
        t1=ts[-1],
        dt0=(ts[1] - ts[0]) if dt0 is None else dt0,
        y0=jnp.asarray(x0),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller,
        max_steps=max_steps,
        adjoint=adjoint if adjoint is not None else diffrax.RecursiveCheckpointAdjoint(),
        throw=throw,
    )
    ys = sol.ys
    assert ys is not None  # saved at ts
    if not throw:
        # diffrax leaves unreached save points as inf; NaNs from a blown-up model become inf too
        ys = jnp.where(jnp.isfinite(ys), ys, jnp.inf)
    return ys


# diffrax evaluates the vector field in several places (first stage, the stage loop, and again
# in the adjoint's backward pass); as one jitted function its jaxpr is traced once and JAX reuses
# the transformed (vmapped, differentiated) copies, which cuts the trace time of a differentiated
# solve by about a quarter (bench/loss_cost.py). XLA inlines the call, so the numbers are the same.
_vector_field_once = eqx.filter_jit(vector_field)


def _input_of_time(us, ts, m: int, input_interpolation: str):
    """The input as a function of time, and the times where it jumps (held samples), or None."""
    if callable(us):
        return us, None
    if input_interpolation == "linear":
        u_of_t = diffrax.LinearInterpolation(ts=ts, ys=_samples(us, ts, m))
        return u_of_t.evaluate, None
    if input_interpolation == "zoh":
        samples = _samples(us, ts, m)

        def u_zoh(t):
            i = jnp.clip(jnp.searchsorted(ts, t, side="right") - 1, 0, ts.shape[0] - 1)
            return samples[i]

        return u_zoh, ts
    raise ValueError(f"input_interpolation must be 'linear' or 'zoh', got {input_interpolation!r}")


def _samples(us, ts, m):
    if us is None:
        return jnp.zeros((ts.shape[0], m), dtype=ts.dtype)
    return jnp.asarray(us).reshape(ts.shape[0], m)


def rk4_step(system: AbstractLagrangianSystem, x, u, h, field: Callable | None = None):
    """One classic RK4 step of size ``h`` with the input held at ``u``; ``field(x, u)`` replaces
    the system's own vector field (e.g. one with dry friction that holds)."""
    f = field or (lambda x_, u_: vector_field(system, x_, u_))
    k1 = f(x, u)
    k2 = f(x + 0.5 * h * k1, u)
    k3 = f(x + 0.5 * h * k2, u)
    k4 = f(x + h * k3, u)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_zoh_step(system: AbstractLagrangianSystem, x, u, dt: float, substeps: int = 1, field: Callable | None = None):
    """Advance one control period ``dt`` with ``u`` held, in ``substeps`` RK4 steps."""
    h = dt / substeps
    return jax.lax.fori_loop(0, substeps, lambda _, x_: rk4_step(system, x_, u, h, field), x)


def rollout_zoh(
    system: AbstractLagrangianSystem,
    x0: Float[Array, " 2n"],
    us: Float[Array, "T m"],
    dt: float,
    substeps: int = 1,
    field: Callable | None = None,
) -> Float[Array, "T+1 2n"]:
    """States at every control instant under a held input sequence; ``xs[0] = x0``
    (``field``: see :func:`rk4_step`)."""

    def step(x, u):
        x_next = rk4_zoh_step(system, x, u, dt, substeps, field)
        return x_next, x_next

    _, xs = jax.lax.scan(step, jnp.asarray(x0), jnp.asarray(us))
    return jnp.concatenate([jnp.asarray(x0)[None], xs], axis=0)
