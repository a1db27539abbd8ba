"""The spine: autodiff-derived dynamics against hand-derived Euler–Lagrange, residual properties."""

import functools
import re
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from furuta_gym import lagrangian as lg
from furuta_gym.models import NMSD, Furuta, FurutaParameters, FurutaSharedTrig
from furuta_gym.simulate import rk4_zoh_step, simulate


def hand_derived_furuta(params, q, qd, u):
    """Euler–Lagrange for the Furuta worked out on paper (not by autodiff)."""
    p = params
    a = 0.25 * p.mp * p.Lp**2
    b = 0.5 * p.mp * p.Lr * p.Lp
    s, c = np.sin(q[1]), np.cos(q[1])
    ad, bd = qd
    M = np.array([[p.J1 + a * s**2, b * c], [b * c, p.J2]])
    coriolis = np.array([2 * a * s * c * ad * bd - b * s * bd**2, -b * s * ad * bd])
    dL_dq = np.array([0.0, a * s * c * ad**2 - b * s * ad * bd - 0.5 * p.mp * p.g * p.Lp * s])
    tau = np.array([p.kt / p.Rm * (u[0] - p.km * ad) - p.c_r * ad, -p.c_p * bd])
    qdd = np.linalg.solve(M, tau + dL_dq - coriolis)
    return M, coriolis, dL_dq, qdd


def test_furuta_autodiff_matches_hand_derived_euler_lagrange():
    model = Furuta()
    pf = jax.tree_util.tree_map(float, model.params)
    rng = np.random.default_rng(0)

    @jax.jit  # one compiled evaluation: 200 eager ones spend minutes dispatching
    def derived(q, qd, u, qdd):
        terms = lg.inverse_dynamics_terms(model, q, qd, qdd)
        got_qdd = lg.forward_dynamics(model, q, qd, u)
        tau_u = lg.inverse_dynamics(model, q, qd, got_qdd)
        return model.mass_matrix(q), terms, got_qdd, tau_u, model.input_force(q, qd, u)

    worst = 0.0
    for _ in range(200):
        q = rng.uniform(-np.pi, np.pi, 2)
        qd = rng.uniform(-20, 20, 2)
        u = rng.uniform(-10, 10, 1)
        M, cor, dLdq, qdd = hand_derived_furuta(pf, q, qd, u)
        got_M, terms, got_qdd, tau_u, applied = derived(q, qd, u, qdd)
        for ref, got in [
            (M, got_M),
            (cor, terms.coriolis),
            (dLdq, terms.potential),
            (qdd, got_qdd),
            (M @ qdd, terms.inertial),
        ]:
            scale = np.max(np.abs(ref)) + 1e-300
            worst = max(worst, float(np.max(np.abs(np.asarray(got) - ref)) / scale))
        # inverse dynamics closes the loop: τ_u needed for q̈ equals the applied τ_u
        np.testing.assert_allclose(tau_u, applied, rtol=1e-10, atol=1e-14)
    assert worst <= 1e-12, worst


def test_energy_balance_is_the_work_of_external_forces():
    """dE/dt = q̇ᵀ(τ_u + τ_NC): the derived dynamics conserve what they should."""
    model = Furuta()
    q, qd, u = jnp.array([0.4, 2.0]), jnp.array([3.0, -7.0]), jnp.array([2.0])
    qdd = lg.forward_dynamics(model, q, qd, u)
    dE = jax.jvp(lambda q_, qd_: lg.energy(model, q_, qd_), (q, qd), (qd, qdd))[1]
    power = qd @ (model.input_force(q, qd, u) + model.nonconservative_force(q, qd))
    np.testing.assert_allclose(dE, power, rtol=1e-12)


def test_linearisation_of_upright_furuta_is_unstable_and_controllable():
    model = Furuta()
    A, B = lg.linearize(model, jnp.array([0.0, np.pi, 0.0, 0.0]), jnp.array([0.0]))
    eig = np.linalg.eigvals(np.asarray(A))
    assert eig.real.max() > 1.0  # the upright pendulum falls
    ctrb = np.hstack([np.linalg.matrix_power(np.asarray(A), k) @ np.asarray(B) for k in range(4)])
    assert np.linalg.matrix_rank(ctrb) == 4


def test_vmap_batches_every_derived_quantity():
    model = Furuta()
    q = jnp.array(np.random.default_rng(1).normal(size=(7, 2)))
    qd = jnp.array(np.random.default_rng(2).normal(size=(7, 2)))
    u = jnp.zeros((7, 1))
    batched = jax.vmap(lambda a, b, c: lg.forward_dynamics(model, a, b, c))(q, qd, u)
    single = np.stack([lg.forward_dynamics(model, q[i], qd[i], u[i]) for i in range(7)])
    np.testing.assert_allclose(batched, single, rtol=1e-13)


def test_shared_trig_furuta_is_furutas_physics_with_one_sin_and_cos_per_rk4_stage():
    """FurutaSharedTrig (what the functional env steps) agrees with Furuta to round-off — the
    vector field, an RK4 control period, the linearisation and a parameter gradient through an RK4
    step, at other parameters too — and under jit + vmap XLA:CPU evaluates sin β and cos β once
    per RK4 stage (Furuta's own graph: in several fused kernels each)."""
    rng = np.random.default_rng(5)
    xs = jnp.asarray(rng.uniform([-4, -7, -30, -60], [4, 7, 30, 60], (300, 4)))
    us = jnp.asarray(rng.uniform(-6, 6, (300, 1)))
    heavier = FurutaParameters(mp=0.03, Lp=0.14, c_r=5e-4)

    def batched(fn):
        """fn(model, x, u) over the states, compiled once per model class (the parameters traced)."""
        return lambda cls: jax.jit(jax.vmap(lambda p, x, u: fn(cls(params=p), x, u), in_axes=(None, 0, 0)))

    field = batched(lg.vector_field)
    period = batched(lambda m, x, u: rk4_zoh_step(m, x, u, 0.02, 10))
    jacobian = batched(lambda m, x, u: lg.linearize(m, x, u)[0])
    gradient = batched(
        lambda m, x, u: jnp.stack(
            jax.tree_util.tree_leaves(jax.grad(lambda mm: jnp.sum(rk4_zoh_step(mm, x, u, 0.002) ** 2))(m).params)
        )
    )
    for quantity in (field, period, jacobian, gradient):
        ours, theirs = quantity(FurutaSharedTrig), quantity(Furuta)
        for p in (FurutaParameters(), heavier):
            np.testing.assert_allclose(ours(p, xs, us), theirs(p, xs, us), rtol=1e-12, atol=1e-12)

    def sines(cls):
        step = jax.jit(jax.vmap(lambda x, u: rk4_zoh_step(cls(), x, u, 0.002)))
        text = step.lower(xs, us).compile().as_text()
        return len(re.findall(r" sine\(", text)), len(re.findall(r" cosine\(", text))

    if jax.default_backend() == "cpu":
        assert sines(FurutaSharedTrig) == (4, 4)  # one of each per stage
        assert min(sines(Furuta)) > 4  # what the shared values save (if XLA stops duplicating, drop this)


def _true_trajectory(model, x0, dt, T, u_fn):
    ts = jnp.arange(T) * dt
    us = jnp.asarray(u_fn(ts))[:, None]
    xs = simulate(model, x0, ts, lambda t: u_fn(t)[None], rtol=1e-11, atol=1e-13, dt0=dt / 10)
    return ts, xs, us


@functools.cache
def _sine_driven_nmsd(dt: float, T: int):
    """The N-MSD under a 0.7 Hz sine from one state, solved tightly: shared by the rules' cases
    (each tight solve costs seconds)."""
    return _true_trajectory(NMSD(), jnp.array([0.8, -2.0]), dt, T, lambda t: 3 * jnp.sin(2 * jnp.pi * 0.7 * t))


@pytest.mark.parametrize("rule", ["trapezoid", "simpson", "hermite"])
def test_integral_residual_is_at_the_quadrature_floor_and_scales_with_dt(rule):
    model = NMSD()
    x0 = jnp.array([0.8, -2.0])
    rms = []
    for dt in (0.02, 0.01):
        ts, xs, us = _sine_driven_nmsd(dt, int(round(4.0 / dt)) + 1)
        if rule == "hermite":  # its Z̄ takes u linear between samples: give the plant that input
            xs = _linear_input_trajectory(model, x0, us, dt)
        r = lg.integral_residual(model, xs[:, :1], xs[:, 1:], us, dt, rule)
        p = jax.vmap(lambda a, b: lg.momentum(model, a, b))(xs[:, :1], xs[:, 1:])
        dp = jnp.sqrt(jnp.mean(lg.interval_difference(p, rule) ** 2))
        rms.append(float(jnp.sqrt(jnp.mean(r**2)) / dp))
    order = np.log2(rms[0] / rms[1])
    expected = 2 if rule == "trapezoid" else 4
    assert order == pytest.approx(expected, abs=0.35), (rms, order)
    if rule == "hermite":
        # same order as Simpson's, a far smaller constant (the states between samples are resolved)
        assert rms[1] < 1e-2 * _relative_floor(model, xs, us, dt, "simpson")
        # an input smooth between the samples is integrated as if linear: second order there
        _, smooth, _ = _sine_driven_nmsd(dt, xs.shape[0])
        assert _relative_floor(model, smooth, us, dt, "hermite") > 10 * rms[1]
    # a wrong model is far above the floor: V × 1.1 and a sign-flipped input
    wrong_v = NMSD(params=type(model.params)(k1=11.0, k2=5.5))
    r_wrong = lg.integral_residual(wrong_v, xs[:, :1], xs[:, 1:], us, dt, rule)
    assert float(jnp.sqrt(jnp.mean(r_wrong**2))) > 20 * rms[1] * float(dp)
    r_flip = lg.integral_residual(model, xs[:, :1], xs[:, 1:], -us, dt, rule)
    assert float(jnp.sqrt(jnp.mean(r_flip**2))) > 20 * rms[1] * float(dp)


def _linear_input_trajectory(model, x0, us, dt, substeps=40):
    """The plant under u linear between samples, to ~1e-15: fixed-step RK4 inside each sampling
    interval (an adaptive solve steps across the input's kinks at the samples and loses order)."""
    h = dt / substeps

    def interval(x, u01):
        u0, u1 = u01

        def substep(x, k):
            u_at = lambda s: u0 + (u1 - u0) * s / dt  # noqa: E731
            s = k * h
            f = lambda x_, s_: lg.vector_field(model, x_, u_at(s_))  # noqa: E731
            k1 = f(x, s)
            k2 = f(x + 0.5 * h * k1, s + 0.5 * h)
            k3 = f(x + 0.5 * h * k2, s + 0.5 * h)
            k4 = f(x + h * k3, s + h)
            return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), None

        x, _ = jax.lax.scan(substep, x, jnp.arange(substeps))
        return x, x

    _, rest = jax.lax.scan(interval, jnp.asarray(x0), (us[:-1], us[1:]))
    return jnp.concatenate([jnp.asarray(x0)[None], rest])


def _relative_floor(model, xs, us, dt, rule):
    n = model.spec.n_dof
    r = lg.integral_residual(model, xs[:, :n], xs[:, n:], us, dt, rule)
    p = jax.vmap(lambda a, b: lg.momentum(model, a, b))(xs[:, :n], xs[:, n:])
    return float(jnp.sqrt(jnp.mean(r**2) / jnp.mean(lg.interval_difference(p, rule) ** 2)))


def test_hermite_quadrature_is_exact_for_cubic_motion_and_linear_input():
    # a cubic q(t) is its own Hermite interpolant, and two Gauss nodes integrate cubics exactly
    t = jnp.linspace(0.0, 1.0, 11)
    dt = 0.1
    q = (1 + 2 * t - t**2 + 0.5 * t**3)[:, None]
    qd = (2 - 2 * t + 1.5 * t**2)[:, None]
    u = (3 * t - 1)[:, None]
    got = lg.interval_quadrature(lambda a, b, c: jnp.concatenate([a, b * c]), q, qd, u, dt, "hermite")
    Q = lambda x: x + x**2 - x**3 / 3 + x**4 / 8  # noqa: E731  ∫q
    QU = lambda x: -2 * x + 4 * x**2 - 2.5 * x**3 + 1.125 * x**4  # noqa: E731  ∫q̇·u
    np.testing.assert_allclose(got[:, 0], Q(t[1:]) - Q(t[:-1]), atol=1e-14)
    np.testing.assert_allclose(got[:, 1], QU(t[1:]) - QU(t[:-1]), atol=1e-14)
    # the sample rules on the same intervals: the trapezoid is not exact here
    trap = lg.interval_quadrature(lambda a, b, c: a, q, qd, u, dt, "trapezoid")
    assert float(jnp.max(jnp.abs(trap[:, 0] - (Q(t[1:]) - Q(t[:-1]))))) > 1e-5
    # its states at the interval ends are the samples, its velocity integrates to Δq exactly
    q_end, qd_end, u_end = lg.hermite_states(q, qd, u, dt, 1.0)
    np.testing.assert_allclose(q_end, q[1:], atol=1e-15)
    np.testing.assert_allclose(qd_end, qd[1:], atol=1e-14)
    np.testing.assert_allclose(u_end, u[1:], atol=1e-15)
    assert float(jnp.max(jnp.abs(lg.quadrature_consistency(q, qd, dt, "hermite")))) == 0.0


def test_hermite_removes_the_floor_where_the_pendulum_whirls():
    """A Furuta pendulum whirling through the bottom at ~25 rad/s turns 0.25 rad per 100 Hz
    sample: Simpson's integrand is under-resolved there, the Hermite states are not."""
    model = Furuta()
    dt = 0.01
    ts = jnp.arange(101) * dt
    xs = simulate(model, jnp.array([0.3, 0.5, 2.0, 22.0]), ts, jnp.zeros((101, 1)), rtol=1e-12, atol=1e-13)
    us = jnp.zeros((101, 1))
    simpson = _relative_floor(model, xs, us, dt, "simpson")
    hermite = _relative_floor(model, xs, us, dt, "hermite")
    assert simpson > 1e-4, simpson  # the floor of the trapezoid and Simpson rules (relative rms)
    assert hermite < simpson / 100, (simpson, hermite)
    # still a test of the model: a pendulum damping 10 % off stands far above the new floor
    wrong = Furuta(params=FurutaParameters(c_p=1.1 * float(model.params.c_p)))
    assert _relative_floor(wrong, xs, us, dt, "hermite") > 10 * hermite
    assert _relative_floor(wrong, xs, us, dt, "simpson") < 1.5 * simpson  # lost in Simpson's floor


def test_hermite_needs_the_states_not_samples_of_the_integrand():
    with pytest.raises(ValueError, match="interval_quadrature"):
        lg.interval_integral(jnp.ones((5, 2)), 0.01, "hermite")
    with pytest.raises(ValueError, match="rule must be one of"):
        lg.interval_difference(jnp.ones((5, 2)), "boole")


def test_rk4_zoh_matches_tight_diffrax_with_held_input():
    model = Furuta()
    x0 = jnp.array([0.1, 2.5, 1.0, -3.0])
    u = jnp.array([1.5])
    x_rk4 = rk4_zoh_step(model, x0, u, 0.02, substeps=20)
    x_ref = simulate(model, x0, jnp.array([0.0, 0.02]), jnp.stack([u, u]), rtol=1e-12, atol=1e-14)[-1]
    np.testing.assert_allclose(x_rk4, x_ref, atol=1e-10)


def test_import_does_not_touch_jax_x64_flag():
    code = "import jax, furuta_gym, furuta_gym.models, furuta_gym.lagrangian;print(jax.config.read('jax_enable_x64'))"
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={"PATH": "/usr/bin:/bin", "HOME": "/tmp"} | _pyenv(),
    )
    assert out.stdout.strip() == "False", out.stderr


def test_first_model_construction_switches_x64_on_with_one_warning():
    code = (
        "import warnings, jax, furuta_gym\n"
        "from furuta_gym.models import Furuta\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    m = Furuta(); m2 = Furuta()\n"
        "print(jax.config.read('jax_enable_x64'), sum(issubclass(x.category, furuta_gym.Float64Warning) for x in w), m.params.mr.dtype)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={"PATH": "/usr/bin:/bin", "HOME": "/tmp"} | _pyenv(),
    )
    assert out.stdout.split() == ["True", "1", "float64"], out.stderr


def _pyenv():
    import os

    return {k: v for k, v in os.environ.items() if k.startswith(("PYTHON", "VIRTUAL_ENV", "PYENV"))}
