"""The MJCF ground truth equals the analytic models (issue 2: "Must show").

* mass matrix (mj_fullM), bias force (Coriolis − ∂L/∂q), passive force (τ_NC, plus the N-MSD's
  springs) and actuator force (τ_u) at 1 000 random states, to ≤ 1e-9 relative;
* MuJoCo trajectories (RK4, the shipped timesteps) against a 1e-10/1e-12-tolerance diffrax solution
  of the analytic model with the same held inputs: ≤ 2e-6 rad / m RMS.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from furuta_gym import lagrangian as lag
from furuta_gym.assets import asset_path
from furuta_gym.envs import MujocoBackend
from furuta_gym.models import NMSD, Furuta
from furuta_gym.signals import chirp
from furuta_gym.simulate import simulate

N_STATES = 1000


def _random_states(system, rng):
    n = 2 if system == "furuta" else 1
    if system == "furuta":
        q = rng.uniform(-2 * np.pi, 2 * np.pi, (N_STATES, n))
        qd = rng.uniform(-30.0, 30.0, (N_STATES, n))
        u = rng.uniform(-10.0, 10.0, (N_STATES, 1))
    else:
        q = rng.uniform(-2.0, 2.0, (N_STATES, n))
        qd = rng.uniform(-5.0, 5.0, (N_STATES, n))
        u = rng.uniform(-20.0, 20.0, (N_STATES, 1))
    return q, qd, u


def _max_rel(a, b):
    """max over samples of ‖a − b‖∞ / ‖b‖∞ (per-sample relative error)."""
    num = np.max(np.abs(a - b), axis=-1)
    den = np.maximum(np.max(np.abs(b), axis=-1), 1e-300)
    return float(np.max(num / den))


@pytest.mark.parametrize("system,model", [("furuta", Furuta()), ("nmsd", NMSD())])
def test_mass_matrix_and_forces_equal_analytic_model(system, model):
    backend = MujocoBackend(system)
    q, qd, u = _random_states(system, np.random.default_rng(0))
    n = q.shape[1]
    jq, jqd, ju = jnp.asarray(q), jnp.asarray(qd), jnp.asarray(u)
    M_ref = np.asarray(jax.vmap(model.mass_matrix)(jq))
    bias_ref = np.asarray(
        jax.vmap(lambda q_, qd_: lag.coriolis_force(model, q_, qd_) - lag.potential_derived_force(model, q_, qd_))(
            jq, jqd
        )
    )
    nc_ref = np.asarray(jax.vmap(model.nonconservative_force)(jq, jqd))
    u_ref = np.asarray(jax.vmap(model.input_force)(jq, jqd, ju))

    M = np.zeros((N_STATES, n, n))
    bias, passive, actuator = (np.zeros((N_STATES, n)) for _ in range(3))
    d = backend.data
    for i in range(N_STATES):
        d.qpos[:], d.qvel[:], d.ctrl[:] = q[i], qd[i], u[i]
        with backend.passive_forces():
            mujoco.mj_forward(backend.model, d)
        mujoco.mj_fullM(backend.model, d, M[i])
        bias[i], passive[i], actuator[i] = d.qfrc_bias, d.qfrc_passive, d.qfrc_actuator

    assert _max_rel(M.reshape(N_STATES, -1), M_ref.reshape(N_STATES, -1)) <= 1e-9
    assert _max_rel(actuator, u_ref) <= 1e-9
    if system == "furuta":
        # gravity + Coriolis/centrifugal in qfrc_bias, friction in qfrc_passive
        assert _max_rel(bias, bias_ref) <= 1e-9
        assert _max_rel(passive, nc_ref) <= 1e-9
    else:
        # MuJoCo puts the springs (linear native, cubic by callback) in qfrc_passive, the model in V
        assert np.max(np.abs(bias)) == 0.0
        assert _max_rel(bias - passive, bias_ref - nc_ref) <= 1e-9
    # and the whole right-hand side at once
    assert _max_rel(bias - passive - actuator, bias_ref - nc_ref - u_ref) <= 1e-9


def test_passive_callback_is_scoped_to_the_backend():
    """The N-MSD's cubic terms use MuJoCo's global passive callback: it must be restored."""
    calls = []

    def sentinel(m, d):
        calls.append(1)

    backend = MujocoBackend("nmsd")
    mujoco.set_mjcb_passive(sentinel)
    try:
        backend.reset(np.array([0.5, 0.0]))
        backend.step(np.array([1.0]))
        assert mujoco.get_mjcb_passive() is sentinel
        assert calls == []  # our steps did not call someone else's callback
    finally:
        mujoco.set_mjcb_passive(None)
    # without the callback MuJoCo sees the linear system only: the cubic spring matters
    linear = mujoco.MjModel.from_xml_path(str(asset_path("nmsd.xml")))
    data = mujoco.MjData(linear)
    data.qpos[0] = 1.0
    mujoco.mj_forward(linear, data)
    assert data.qfrc_passive[0] == pytest.approx(-10.0)  # −k1 p only
    d = backend.data
    d.qpos[0], d.qvel[0] = 1.0, 0.0
    with backend.passive_forces():
        mujoco.mj_forward(backend.model, d)
    assert d.qfrc_passive[0] == pytest.approx(-15.0)  # −k1 p − k2 p³


def _mujoco_rollout(system, x0, us, substeps=1):
    backend = MujocoBackend(system, substeps=substeps)
    backend.reset(x0)
    xs = [np.asarray(x0, dtype=float)]
    for u in us[:-1]:
        xs.append(backend.step(np.array([u])))
    return np.array(xs), backend.control_dt


def _reference(model, x0, ts, us):
    return np.asarray(
        simulate(
            model,
            jnp.asarray(x0),
            jnp.asarray(ts),
            jnp.asarray(us)[:, None],
            input_interpolation="zoh",
            rtol=1e-10,
            atol=1e-12,
            max_steps=2_000_000,
        )
    )


@pytest.mark.parametrize("forced", [False, True], ids=["free_swing", "chirp"])
def test_furuta_trajectory_matches_tight_diffrax(forced):
    dt = 0.002
    ts = np.arange(2501) * dt  # 5 s at 500 Hz
    x0 = np.array([0.0, 2.0, 0.0, 0.0]) if not forced else np.array([0.0, 0.1, 0.0, 0.0])
    us = chirp(ts, 0.2, 3.0, 5.0, amplitude=3.0) if forced else np.zeros_like(ts)
    xs, control_dt = _mujoco_rollout("furuta", x0, us)
    assert control_dt == dt
    ref = _reference(Furuta(), x0, ts, us)
    rms = np.sqrt(np.mean((xs[:, :2] - ref[:, :2]) ** 2, axis=0))
    assert np.all(rms <= 2e-6), rms  # RK4 at the 2 ms control period against rtol 1e-10
    # the run is not trivial: the pendulum actually swings
    assert np.ptp(xs[:, 1]) > 0.5


def test_nmsd_chirp_trajectory_matches_tight_diffrax():
    dt = 0.01
    ts = np.arange(1001) * dt  # 10 s at 100 Hz
    x0 = np.array([0.0, 0.0])
    us = chirp(ts, 0.1, 2.0, 10.0, amplitude=10.0)
    xs, control_dt = _mujoco_rollout("nmsd", x0, us)
    assert control_dt == dt
    ref = _reference(NMSD(), x0, ts, us)
    rms = np.sqrt(np.mean((xs[:, 0] - ref[:, 0]) ** 2))
    assert rms <= 2e-6, rms
    assert np.max(np.abs(xs[:, 0])) > 0.5  # deep into the cubic spring
