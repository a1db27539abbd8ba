"""The head-to-head benchmark on real runs (studies/diagnose_head_to_head.py): the public
simulators' equations mapped onto our convention, one scoring path for every row, a tiny
mujoco.sysid fit, and the docs table generated from the committed results."""

import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym

furuta_gym.enable_x64()

from furuta_gym.lagrangian import vector_field  # noqa: E402
from furuta_gym.models import Furuta  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))
import qube_baselines as qb  # noqa: E402

sys.path.remove(str(ROOT / "studies"))

BACK_EMF = 0.042**2 / 8.4  # km²/Rm, N m s/rad
NOMINAL_DAMPING = {
    "quanser_robots": (3e-4, 1.5e-5),
    "armandpl": (3e-4, 1.5e-5),
    # gym_brt's published back-EMF term has the other sign: its Dr must hold twice it
    "gym_brt": (3e-4 + 2 * BACK_EMF, 1.5e-5),
}


def _states(n, seed=0):
    rng = np.random.default_rng(seed)
    return [(jnp.asarray(rng.normal(size=4) * [1, 3, 2, 5]), jnp.asarray(rng.normal(size=1) * 3)) for _ in range(n)]


@pytest.mark.parametrize("name", ["gym_brt", "quanser_robots"])
def test_a_qube_simulator_with_our_damping_is_our_nominal_model_in_our_frame(name):
    """Same masses, lengths and motor: with the damping set to ours, each simulator's equations,
    mapped onto (α, β = 0 hanging, positive u → positive α), give our model's accelerations."""
    b = qb.BASELINES[name]
    dr, dp = NOMINAL_DAMPING[name]
    b = b.with_params(Dr=dr, Dp=dp)
    for x, u in _states(8):
        np.testing.assert_allclose(b.vector_field(x, u), vector_field(Furuta(), x, u), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("name", list(qb.BASELINES))
def test_each_simulator_hangs_at_rest_and_swings_at_its_own_frequency(name):
    """Hanging at rest with no input is an equilibrium; linearised there, the pendulum oscillates
    (undamped: an imaginary pair at the rigid-body frequency of its own Mp, Lp, Mr, Lr with the
    rotor free), and
    upright it falls (a positive real eigenvalue); positive volts accelerate the rotor forwards."""
    b = qb.BASELINES[name]
    p = b.params
    zero = jnp.zeros(4)
    np.testing.assert_allclose(b.vector_field(zero, jnp.zeros(1)), 0.0, atol=1e-12)
    assert float(b.vector_field(zero, jnp.ones(1))[2]) > 0
    free = b.with_params(Dr=0.0, Dp=0.0, km=0.0)  # undamped: no friction, no back-EMF
    hanging = np.linalg.eigvals(np.asarray(jax.jacfwd(lambda x: free.vector_field(x, jnp.zeros(1)))(zero)))
    upright = jnp.array([0.0, np.pi, 0.0, 0.0])
    top = np.linalg.eigvals(np.asarray(jax.jacfwd(lambda x: free.vector_field(x, jnp.zeros(1)))(upright)))
    jr, jp = p["Mr"] * p["Lr"] ** 2 / 12, p["Mp"] * p["Lp"] ** 2 / 12
    j1, j2, jc = jr + p["Mp"] * p["Lr"] ** 2, jp + p["Mp"] * p["Lp"] ** 2 / 4, p["Mp"] * p["Lp"] * p["Lr"] / 2
    omega = np.sqrt(0.5 * p["Mp"] * p["g"] * p["Lp"] * j1 / (j1 * j2 - jc**2))  # rotor free, undamped
    assert abs(np.max(np.abs(hanging.imag)) - omega) < 1e-6 * omega and np.max(np.abs(hanging.real)) < 1e-6
    assert np.max(top.real) > 0.5 * omega


def test_gym_brts_back_emf_is_negative_damping_as_published():
    """In our frame gym_brt's rotor feels +km²/Rm·α̇ from its motor model: spinning the rotor with
    no input and no damping accelerates it."""
    b = qb.BASELINES["gym_brt"].with_params(Dr=0.0, Dp=0.0)
    x = jnp.array([0.0, 0.0, 1.0, 0.0])
    assert float(b.vector_field(x, jnp.zeros(1))[2]) > 0


def _experiment():
    sys.path.insert(0, str(ROOT / "studies"))
    try:
        import diagnose_head_to_head as h2h
        import head_to_head_sysid as hsysid
    finally:
        sys.path.remove(str(ROOT / "studies"))
    return h2h, hsysid


def _simulated_run(seconds=1.0, delay=0.0, seed=0):
    """A hanging-pendulum log of our nominal model under random held voltages, the plant seeing
    them ``delay`` s late."""
    from furuta_gym.data import Trajectory
    from furuta_gym.diagnose._fit import InputDynamics
    from furuta_gym.simulate import rollout_zoh

    dt, rng = 0.002, np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-3, 3, size=(int(seconds / dt) // 25, 1)), 25, axis=0)
    xs = np.asarray(rollout_zoh(Furuta(), jnp.zeros(4), jnp.asarray(InputDynamics("delay", delay).apply(u, dt)), dt, 4))
    t = dt * np.arange(len(u) + 1)
    return Trajectory(t=t, q=xs[:, :2], u=np.concatenate([u, u[-1:]]), qd=xs[:, 2:], name="sim")


def test_every_row_is_scored_like_window_errors():
    """The one scoring path (RK4, 4 substeps, dry friction that holds) gives window_errors' RMSE
    for a model without dry friction."""
    from furuta_gym.effects import Effect, WithEffects
    from furuta_gym.measured import window_errors

    h2h, _ = _experiment()
    run = [_simulated_run(seconds=0.6)]
    model = WithEffects(Furuta(), [Effect("spring", "alpha", 2e-3)])  # not the model that made the log
    ours = h2h.score_field(h2h.lagrangian_field(model), run)
    theirs = window_errors(model, run, h2h.WINDOW)
    for state in h2h.STATES:
        assert theirs["rmse"][state] > 1e-6
        assert abs(ours["rmse"][state] - theirs["rmse"][state]) <= 1e-9 * theirs["rmse"][state]
    assert ours["n_windows"] == theirs["n_windows"]


def test_every_phase_windows_start_every_stride_with_the_input_before_each():
    """``--every-phase`` scores windows starting every 10 ms (5 samples), each carrying the input
    sample before it for the MuJoCo rollout's delay, as the back-to-back windows do."""
    h2h, hsysid = _experiment()
    run = [_simulated_run(seconds=0.6)]
    u = np.asarray(run[0].u, float)
    x0, u_ext, q = hsysid.windows_for_sysid(run, h2h.WINDOW, stride=h2h.EVERY_PHASE)
    x0_b, u_ext_b, _ = hsysid.windows_for_sysid(run, h2h.WINDOW)
    assert len(x0) == len(range(0, len(run[0]) - 50, 5)) == 51 and len(x0_b) == 6
    assert np.allclose(x0[10], x0_b[1]) and np.allclose(u_ext[10], u_ext_b[1])  # sample 50 in both
    assert np.allclose(u_ext[3, 0], u[14]) and np.allclose(u_ext[3, 1:], u[15:65])
    assert np.allclose(q[3], run[0].q[15:66])
    every = h2h.score_field(h2h.lagrangian_field(Furuta()), run, stride=h2h.EVERY_PHASE)
    assert every["n_windows"] == 51 and every["position_rmse"] < 1e-9  # the log's own model


def test_sysid_recovers_a_motor_gain_and_an_input_delay_on_simulated_windows():
    """mujoco.sysid on the MJCF (a tiny fit: two parameters, one second of windows) finds the
    gain and delay of a log our nominal model made; its MuJoCo rollout matches ours."""
    sysid = pytest.importorskip("mujoco.sysid")
    if not hasattr(sysid, "create_initial_state"):  # the module ships with MuJoCo, its API with the extra
        pytest.skip("mujoco.sysid without its extra: pip install 'furuta-gym[sysid]'")
    _, hsysid = _experiment()
    run = [_simulated_run(seconds=1.0, delay=0.001)]
    fitted, values, half, record = hsysid.fit(run, 0.1, names=("motor_gain", "input_delay"), max_iters=20)
    assert abs(values["motor_gain"] - 0.005) < 1e-4 and abs(values["input_delay"] - 0.001) < 5e-5
    assert record["rms_angle_residual"] < 1e-5 and all(np.isfinite(list(half.values())))


def test_head_to_head_docs_table_matches_its_results():
    if not (ROOT / "results" / "head_to_head" / "summary.json").is_file():
        pytest.skip("results/head_to_head not generated")
    proc = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "head_to_head_table.py"), "--check"], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
