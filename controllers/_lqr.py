"""LQR about the upright x_d = (0, π, 0, 0) from the design model's autodiff linearisation.

Paper, appendix: "an LQR controller ū = K(x − x_d) ... designed using the linearized system about
the unstable equilibrium x_d", Q = diag(10, 100, 0.01, 0.01), R = 1 (Table 4). We write the
usual u = −K (x − x_d).

* **Linearisation**: ``furuta_gym.lagrangian.linearize`` (jacfwd of the model's vector field) at
  (x_d, u = 0); nothing model-specific.
* **Riccati**: *discrete* (``scipy.linalg.solve_discrete_are``) on the exact zero-order-hold
  discretisation (A_d, B_d) = expm([[A, B], [0, 0]]·dt) at the control rate (500 Hz): the
  controller really is sampled with the input held, so the discrete design is the one whose
  closed-loop eigenvalues (of A_d − B_d K, inside the unit circle) describe what runs. At 500 Hz
  it is within ~1 % of the continuous gain (``discrete=False`` gives the CARE design).
* **What the LQR acts on** (``acts_on``): ``"voltage"`` — the gain acts directly on the motor
  voltage of the linearised model (default); ``"pfl"`` — the gain acts on ū, the rotor
  acceleration of the PFL-linearised model, then PFL⁻¹ turns ū into volts (the paper's
  reading). On the exact model both stabilise; on plants the model does not know they differ.
  See docs/control.md for the measured comparison on the rotor-spring and Coulomb variants.

The angle error is wrapped (β − π to [−π, π)), so any number of full turns of the pendulum is
the same upright; the rotor error α is clipped to ±``alpha_error_limit`` so that a catch far
from α = 0 asks for a bounded rotor correction instead of saturating the motor.
"""

from __future__ import annotations

from typing import Literal, NamedTuple, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
from jaxtyping import Array, Float

from ..lagrangian import AbstractLagrangianSystem, linearize, vector_field
from ._base import AbstractController, wrap_angle
from ._energy import model_state
from ._pfl import pfl_voltage

__all__ = ["LQR", "LQRDesign", "lqr_design", "UPRIGHT_STATE", "DEFAULT_Q", "DEFAULT_R"]

UPRIGHT_STATE = (0.0, float(np.pi), 0.0, 0.0)
DEFAULT_Q = (10.0, 100.0, 0.01, 0.01)
DEFAULT_R = 1.0
ActsOn = Literal["voltage", "pfl"]


class LQRDesign(NamedTuple):
    """Everything an LQR design produced (numpy, float64)."""

    K: np.ndarray  # (1, 4): u = −K (x − x_d)
    P: np.ndarray  # Riccati solution
    A: np.ndarray  # continuous-time linearisation
    B: np.ndarray
    Ad: np.ndarray  # ZOH discretisation at dt (equal to A, B when discrete=False)
    Bd: np.ndarray
    closed_loop_eigenvalues: np.ndarray  # of Ad − Bd K (discrete) or A − B K (continuous)
    stable: bool
    acts_on: str
    discrete: bool
    dt: float


def _pfl_vector_field(model, x, ubar):
    """ẋ of the model driven through PFL: the input is ū (rotor acceleration), not volts."""
    u = pfl_voltage(model, x, ubar[0])
    return vector_field(model, x, jnp.reshape(u, (1,)))


@eqx.filter_jit
def _upright_linearization(model, acts_on: str):
    # one compilation instead of dozens of op-by-op dispatches (seconds on a busy machine)
    x_d = jnp.asarray(UPRIGHT_STATE)
    if acts_on == "voltage":
        return linearize(model, x_d, jnp.zeros(1))
    A = jax.jacfwd(lambda x_: _pfl_vector_field(model, x_, jnp.zeros(1)))(x_d)
    B = jax.jacfwd(lambda v: _pfl_vector_field(model, x_d, v))(jnp.zeros(1))
    return A, B


def lqr_design(
    model: AbstractLagrangianSystem,
    Q: Sequence[float] | np.ndarray = DEFAULT_Q,
    R: float = DEFAULT_R,
    dt: float = 1.0 / 500.0,
    acts_on: ActsOn = "voltage",
    discrete: bool = True,
) -> LQRDesign:
    """Linearise ``model`` at the upright by autodiff and solve the Riccati equation.

    ``Q`` is the diagonal (4 numbers) or a full 4×4 matrix; ``R`` a positive scalar. Raises
    ``ValueError`` when the linearisation is not stabilisable (e.g. a learned model without
    coupling at the upright).
    """
    if acts_on not in ("voltage", "pfl"):
        raise ValueError(f"acts_on must be 'voltage' or 'pfl', got {acts_on!r}")
    if not dt > 0:
        raise ValueError(f"dt must be > 0 s, got {dt}")
    Q = np.asarray(Q, dtype=float)
    Q = np.diag(Q) if Q.ndim == 1 else Q
    if Q.shape != (4, 4):
        raise ValueError(f"Q must be 4 diagonal entries or a 4x4 matrix, got shape {Q.shape}")
    if not float(R) > 0:
        raise ValueError(f"R must be > 0, got {R}")
    R_ = np.array([[float(R)]])
    A, B = _upright_linearization(model, acts_on)
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise ValueError("the model's linearisation at the upright is not finite")
    try:
        if discrete:
            blk = np.zeros((5, 5))
            blk[:4, :4], blk[:4, 4:] = A, B
            E = scipy.linalg.expm(blk * dt)
            Ad, Bd = E[:4, :4], E[:4, 4:]
            P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R_)
            K = np.linalg.solve(R_ + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
            eig = np.linalg.eigvals(Ad - Bd @ K)
            stable = bool(np.all(np.abs(eig) < 1.0))
        else:
            Ad, Bd = A, B
            P = scipy.linalg.solve_continuous_are(A, B, Q, R_)
            K = np.linalg.solve(R_, B.T @ P)
            eig = np.linalg.eigvals(A - B @ K)
            stable = bool(np.all(eig.real < 0.0))
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(
            f"LQR design failed for this model (linearisation at the upright not stabilisable?): {exc}"
        ) from exc
    return LQRDesign(K, P, A, B, Ad, Bd, eig, stable, acts_on, discrete, dt)


class LQR(AbstractController):
    """u = −K (x − x_d) about the upright, on the voltage or on ū through PFL; clipped.

    Build with :meth:`from_model`; ``design`` keeps the Riccati solution and eigenvalues.
    """

    model: AbstractLagrangianSystem
    K: Float[Array, " 4"]
    alpha_error_limit: Float[Array, ""]
    acts_on: str = eqx.field(static=True)
    voltage_limit: float = eqx.field(static=True)
    design: LQRDesign = eqx.field(repr=False)

    def __init__(
        self,
        model: AbstractLagrangianSystem,
        design: LQRDesign,
        voltage_limit: float = 5.0,
        alpha_error_limit: float = 1.0,
    ):
        if not voltage_limit > 0:
            raise ValueError(f"voltage_limit must be > 0 V, got {voltage_limit}")
        self.model = model
        self.design = design
        self.K = jnp.asarray(design.K[0], dtype=float)
        self.acts_on = design.acts_on
        self.voltage_limit = float(voltage_limit)
        self.alpha_error_limit = jnp.asarray(alpha_error_limit, dtype=float)

    @classmethod
    def from_model(
        cls,
        model: AbstractLagrangianSystem,
        Q=DEFAULT_Q,
        R: float = DEFAULT_R,
        dt: float = 1.0 / 500.0,
        acts_on: ActsOn = "voltage",
        discrete: bool = True,
        voltage_limit: float = 5.0,
        alpha_error_limit: float = 1.0,
    ) -> "LQR":
        """Design from any Lagrangian-system model (see :func:`lqr_design`)."""
        design = lqr_design(model, Q=Q, R=R, dt=dt, acts_on=acts_on, discrete=discrete)
        return cls(model, design, voltage_limit=voltage_limit, alpha_error_limit=alpha_error_limit)

    def error(self, obs: Float[Array, " 4"]) -> Float[Array, " 4"]:
        """x − x_d with β − π wrapped and α clipped to ±alpha_error_limit."""
        lim = self.alpha_error_limit
        return jnp.stack([jnp.clip(obs[0], -lim, lim), wrap_angle(obs[1] - jnp.pi), obs[2], obs[3]])

    def step(self, state, obs):
        obs = jnp.asarray(obs, dtype=float)
        v = -self.K @ self.error(obs)
        if self.acts_on == "pfl":
            v = pfl_voltage(self.model, model_state(obs), v)
        u = jnp.clip(v, -self.voltage_limit, self.voltage_limit)
        return jnp.reshape(u, (1,)), state
