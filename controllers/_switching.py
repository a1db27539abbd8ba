"""Swing-up → LQR switching with hysteresis (paper appendix: "the switch to this controller is
done when the system is close to the upright position").

Mode 0 runs :class:`EnergySwingUp`, mode 1 runs :class:`LQR`. The region is a band on the
wrapped pendulum angle e_β = β − π ∈ [−π, π):

* swing-up → LQR when |e_β| < ``catch_angle`` (default 0.35 rad ≈ 20°);
* LQR → swing-up only when |e_β| > ``release_angle`` (default 0.8 rad ≈ 46°).

The gap between the two is the hysteresis: noise or a quantised β sitting on one threshold can't
flip the mode at every step (no chatter), and a catch that overshoots a little stays with the
LQR instead of being handed back to the pump. If the LQR loses the pendulum (|e_β| beyond the
release angle) the swing-up takes over again, so a failed catch is retried, not abandoned.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from ..lagrangian import AbstractLagrangianSystem
from ._base import AbstractController, wrap_angle
from ._energy import EnergySwingUp
from ._lqr import DEFAULT_Q, DEFAULT_R, LQR, ActsOn
from ._tuning import pick_k_e

__all__ = ["SwingUpLQR", "SWING_UP", "BALANCE"]

SWING_UP, BALANCE = 0, 1


class SwingUpLQR(AbstractController):
    """Energy swing-up, then LQR balance near the upright, with a hysteresis band.

    Internal state: the mode (0 swing-up, 1 LQR) as an int32 array. ``step`` returns it, so
    a ``lax.scan`` rollout records when the switch happened.
    """

    swing_up: EnergySwingUp
    lqr: LQR
    catch_angle: float = eqx.field(static=True)
    release_angle: float = eqx.field(static=True)

    def __init__(
        self,
        swing_up: EnergySwingUp,
        lqr: LQR,
        catch_angle: float = 0.35,
        release_angle: float = 0.8,
    ):
        if not 0 < catch_angle < release_angle <= jnp.pi:
            raise ValueError(
                "need 0 < catch_angle < release_angle <= pi (rad) for a hysteresis band, got "
                f"catch_angle={catch_angle}, release_angle={release_angle}"
            )
        self.swing_up = swing_up
        self.lqr = lqr
        self.catch_angle = float(catch_angle)
        self.release_angle = float(release_angle)

    @classmethod
    def from_model(
        cls,
        model: AbstractLagrangianSystem,
        k_e: float | None = None,
        *,
        auto_gain: bool = False,
        k_alpha: float = 10.0,
        d_alpha: float = 2.0,
        Q=DEFAULT_Q,
        R: float = DEFAULT_R,
        acts_on: ActsOn = "voltage",
        dt: float = 1.0 / 500.0,
        voltage_limit: float = 5.0,
        catch_angle: float = 0.35,
        release_angle: float = 0.8,
        alpha_error_limit: float = 1.0,
        seed: int = 0,
    ) -> "SwingUpLQR":
        """Design both parts from any Lagrangian-system model.

        ``k_e=None`` uses :func:`~furuta_gym.controllers.default_k_e` (a fixed commanded pump of
        150 rad/s² at the bottom, whatever the model's potential scale); ``auto_gain=True``
        picks k_e by a short seeded closed-loop sweep on the design model itself
        (:func:`furuta_gym.controllers.pick_k_e`).
        """
        lqr = LQR.from_model(
            model,
            Q=Q,
            R=R,
            dt=dt,
            acts_on=acts_on,
            voltage_limit=voltage_limit,
            alpha_error_limit=alpha_error_limit,
        )

        def build(k):
            swing = EnergySwingUp(model, k_e=k, k_alpha=k_alpha, d_alpha=d_alpha, voltage_limit=voltage_limit)
            return cls(swing, lqr, catch_angle=catch_angle, release_angle=release_angle)

        if auto_gain:
            if k_e is not None:
                raise ValueError("give either k_e or auto_gain=True, not both")

            return pick_k_e(build, model, dt=dt, seed=seed).controller
        return build(k_e)

    def init_state(self):
        return jnp.asarray(SWING_UP, dtype=jnp.int32)

    def next_mode(self, mode, obs):
        """Hysteresis: enter the LQR inside the catch band, leave it outside the release band."""
        err = jnp.abs(wrap_angle(obs[1] - jnp.pi))
        enter = (mode == SWING_UP) & (err < self.catch_angle)
        leave = (mode == BALANCE) & (err > self.release_angle)
        return jnp.where(enter, BALANCE, jnp.where(leave, SWING_UP, mode)).astype(jnp.int32)

    def step(self, state, obs):
        obs = jnp.asarray(obs, dtype=float)
        mode = self.next_mode(state, obs)
        u_swing, _ = self.swing_up.step((), obs)
        u_lqr, _ = self.lqr.step((), obs)
        return jnp.where(mode == BALANCE, u_lqr, u_swing), mode
