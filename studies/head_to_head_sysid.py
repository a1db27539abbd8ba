"""``mujoco.sysid`` fitting the shipped Furuta MJCF (``assets/furuta.xml``) to measured windows.

Every fitted quantity is a native MJCF term, written into the spec by a ``mujoco.sysid.Parameter``
modifier: the rotor's inertia, the pendulum's centre of mass (distance from the hinge and lateral
offset, which tilts it), the pendulum's hinge armature (its own inertia), the arm length (the
pendulum body's position), joint damping and friction loss on both joints, the rotor's stiffness
with its spring reference, and the motor's gain. The pendulum's mass stays at its datasheet value:
the data fix the dynamics only up to one overall scale (input, inertia and forces together), and a
weighed mass is the usual anchor. The back-EMF stays in the actuator's bias (it and the rotor
damping are one regressor). Friction loss needs MuJoCo's constraint solver, switched on here with
its default soft-constraint settings. An input delay is one more parameter, applied to the logged
input in sysid's ``custom_rollout`` hook (each window carries the sample before it): sysid's own
delays act on sensors, and MuJoCo's actuator delay would need each window's input history.

The data are open-loop windows from the measured state (angles and zero-phase velocities), the
logged input held over each sample period, and the residual is the measured minus predicted angles
(sysid's ``modify_residual`` hook: its default divides each window's residual by that window's
signal norm, which would weight windows where the rotor sits near zero by orders of magnitude). The
fit is ``mujoco.sysid.optimize`` (box-constrained Gauss-Newton, ``mujoco.minimize``), and its
intervals are ``mujoco.sysid.calculate_intervals``'.
"""

from __future__ import annotations

import furuta_gym  # noqa: F401  first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

from furuta_gym.assets import asset_path
from furuta_gym.diagnose import InputDynamics
from furuta_gym.measured import prediction_windows


def _set_ipos(axis: int, sign: float):
    def modify(spec, value):
        body = spec.body("pendulum")
        ipos = np.array(body.ipos)
        ipos[axis] = sign * value
        body.ipos = ipos

    return modify


def _set_gain(spec, value):
    gain = np.array(spec.actuator("motor").gainprm)
    gain[0] = value
    spec.actuator("motor").gainprm = gain


def _joint(name: str, attribute: str):
    """Writes a joint attribute; damping and stiffness are polynomials in MuJoCo 4 (the linear
    coefficient first, the higher ones kept at zero)."""

    def modify(spec, value):
        joint = spec.joint(name)
        old = getattr(joint, attribute)
        setattr(joint, attribute, np.concatenate([[value], np.zeros(np.size(old) - 1)]) if np.ndim(old) else value)

    return modify


#: name -> (unit, start, lower, upper, writer into the spec); values are in the unit, so that
#: every parameter is of order one for the finite differences. Starts are the MJCF's datasheet
#: values; terms it does not have start just inside their bound.
PARAMETERS = {
    "rotor_inertia": (1e-5, 5.7197917, 0.5, 50.0, lambda s, v: setattr(s.body("rotor"), "inertia", [v, v, v])),
    "pendulum_com": (1e-2, 6.45, 3.0, 10.0, _set_ipos(2, -1.0)),
    "pendulum_com_lateral": (1e-3, 0.0, -5.0, 5.0, _set_ipos(1, 1.0)),
    "pendulum_armature": (1e-5, 3.3282, 0.1, 20.0, _joint("beta", "armature")),
    "arm_length": (1e-2, 8.5, 4.0, 13.0, lambda s, v: setattr(s.body("pendulum"), "pos", [v, 0.0, 0.0])),
    "alpha_damping": (1e-4, 3.0, 0.0, 50.0, _joint("alpha", "damping")),
    "beta_damping": (1e-5, 1.5, 0.0, 50.0, _joint("beta", "damping")),
    "alpha_frictionloss": (1e-4, 0.5, 0.0, 50.0, _joint("alpha", "frictionloss")),
    "beta_frictionloss": (1e-5, 0.5, 0.0, 50.0, _joint("beta", "frictionloss")),
    "alpha_stiffness": (1e-4, 0.5, 0.0, 100.0, _joint("alpha", "stiffness")),
    "alpha_springref": (1e-1, 0.0, -10.0, 10.0, _joint("alpha", "springref")),
    "motor_gain": (1e-3, 5.0, 1.0, 20.0, _set_gain),
    "input_delay": (1e-3, 0.5, 0.0, 6.0, None),
}


def furuta_spec():
    """The shipped MJCF with its angles as sensors and the constraint solver on (friction loss)."""
    import mujoco

    spec = mujoco.MjSpec.from_file(str(asset_path("furuta.xml")))
    spec.option.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    for joint in ("alpha", "beta"):
        spec.add_sensor(
            name=f"{joint}_pos", type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=joint
        )
    return spec


def parameter_dict(names=tuple(PARAMETERS)):
    from mujoco import sysid

    params = sysid.ParameterDict()
    for name in names:
        unit, start, lo, hi, write = PARAMETERS[name]
        modifier = None if write is None else (lambda s, p, w=write, k=unit: w(s, float(p.value[0]) * k))
        params.add(sysid.Parameter(name, start, lo, hi, modifier=modifier))
    return params


def from_physical(values: dict):
    """The ParameterDict of SI ``values`` (a fit's :func:`physical`)."""
    params = parameter_dict(tuple(values))
    for name, value in values.items():
        params[name].value[:] = value / PARAMETERS[name][0]
    return params


def physical(params) -> dict:
    """The fitted values in SI units."""
    return {name: float(params[name].value[0]) * PARAMETERS[name][0] for name in params.keys()}


def windows_for_sysid(trajs, window: float, every: int = 1, stride: float | None = None):
    """(x0, u with the sample before each window first, measured angles) of back-to-back windows
    (or one every ``stride`` s)."""
    x0, us, xs = prediction_windows(trajs, window, stride)
    n = us.shape[1]
    step = n if stride is None else max(1, int(round(stride / trajs[0].dt)))
    before = []
    for tr in trajs:  # the input sample before each window: as prediction_windows cuts them
        u = np.asarray(tr.u, float).reshape(len(tr), -1)
        before += [u[max(a - 1, 0)] for a in range(0, len(tr) - n, step)]
    u_ext = np.concatenate([np.asarray(before)[:, None], us], axis=1)
    keep = slice(None, None, every)
    return x0[keep], u_ext[keep], xs[keep, :, :2]


def measured_sequences(spec, x0, u_ext, q_meas, dt: float):
    from mujoco import sysid

    model = spec.compile()
    times = np.arange(q_meas.shape[1]) * dt
    states = [sysid.create_initial_state(model, x[:2], x[2:]) for x in x0]
    controls = [sysid.TimeSeries(times, u) for u in u_ext]
    sensors = [sysid.TimeSeries.from_names(times, q, model) for q in q_meas]
    seq = sysid.ModelSequences("furuta", spec, [f"w{i}" for i in range(len(x0))], states, controls, sensors)
    return seq


def _held_after(u):
    return np.concatenate([u, u[-1:]], axis=0)


def _rollout_with_delay(dt: float):
    from mujoco import sysid

    def rollout(*, models, datas, control_signal, initial_states, param_dicts, **mappings):
        delay = (
            float(param_dicts[0]["input_delay"].value[0]) * PARAMETERS["input_delay"][0]
            if ("input_delay" in param_dicts[0].keys())
            else 0.0
        )
        # sysid rolls out all but the last control (one per measured sample after the start):
        # the delayed inputs of the window's periods, then a placeholder
        shifted = [
            sysid.TimeSeries(c.times, _held_after(InputDynamics("delay", delay).apply(c.data, dt)[1:]))
            for c in control_signal
        ]
        return sysid.sysid_rollout(
            models,
            datas,
            shifted,
            initial_states,
            mappings["rollout_signal_mapping"],
            mappings["rollout_state_mapping"],
            mappings["ctrl_mapping"],
        )

    return rollout


def _angle_residual(params, pred, measured, model, return_pred_all, state=None, **_):
    """Measured minus predicted angles after each step (state columns: time, qpos...)."""
    return measured.data[1:, :2] - state[:, 1:3], pred, measured


def residual_function(spec, seq, dt: float):
    """``(x, params) -> ([residual], None, None)`` for ``mujoco.sysid.optimize``: all windows
    rolled out in one call per parameter vector (one column per finite-difference point)."""
    from mujoco import sysid

    rollout = _rollout_with_delay(dt)

    def one(x, params):
        r, _, _ = sysid.model_residual(
            x,
            params,
            lambda p: sysid.apply_param_modifiers(p, spec),
            seq.measured_rollout,
            modify_residual=_angle_residual,
            custom_rollout=rollout,
            n_threads=1,
            resample_true=False,
        )
        return r

    def residual(x, params):
        if x.ndim == 1:
            return [one(x, params)], None, None
        return [np.stack([one(x[:, i], params) for i in range(x.shape[1])], axis=1)], None, None

    return residual


def fit(trajs, window: float, every: int = 1, max_iters: int = 30, names=tuple(PARAMETERS)):
    """Fit :data:`PARAMETERS` (``names``) on the back-to-back windows of ``trajs``; returns the
    fitted ParameterDict, its SI values, 95 % half-widths (SI) and the fit's record."""
    from mujoco import sysid

    dt = float(np.median([tr.dt for tr in trajs]))
    spec = furuta_spec()
    seq = measured_sequences(spec, *windows_for_sysid(trajs, window, every), dt)
    residual = residual_function(spec, seq, dt)
    start = parameter_dict(names)
    fitted, result = sysid.optimize(start, residual, optimizer="mujoco", verbose=False, max_iters=max_iters)
    r_star = residual(fitted.as_vector(), fitted)[0]
    _, half = sysid.calculate_intervals(r_star, np.asarray(result.jac))
    units = np.array([PARAMETERS[n][0] for n in fitted.keys()])
    objective = [float(v) for v in result.extras.get("objective", [])]
    record = {
        "windows": len(seq.measured_rollout),
        "iterations_cap": max_iters,
        "objective": objective,
        "rms_angle_residual": float(np.sqrt(np.mean(np.concatenate(r_star) ** 2))),
    }
    return fitted, physical(fitted), dict(zip(fitted.keys(), (np.asarray(half) * units).tolist(), strict=True)), record


def predictor(params):
    """``(x0, u_ext, dt) -> states (W, L + 1, 4)`` of the identified MJCF (the fitted spec, MuJoCo's own
    rollout), the logged inputs delayed by the fitted delay."""
    import mujoco
    from mujoco import rollout as mj_rollout, sysid

    model = sysid.apply_param_modifiers(params, furuta_spec())
    delay = (
        float(params["input_delay"].value[0]) * PARAMETERS["input_delay"][0] if "input_delay" in params.keys() else 0.0
    )

    def predict(x0, u_ext, dt):
        data = mujoco.MjData(model)
        starts = np.stack([sysid.create_initial_state(model, x[:2], x[2:]) for x in x0])
        ctrl = np.stack([InputDynamics("delay", delay).apply(u, dt)[1:] for u in u_ext])
        state, _ = mj_rollout.rollout(model, data, starts, ctrl)
        return np.concatenate([x0[:, None, :], np.asarray(state)[:, :, 1:5]], axis=1)

    return predict


def predictor_from_values(values: dict):
    """:func:`predictor` of a fit's SI ``values`` (its :func:`physical`), the terms written by
    their own writers without ``mujoco.sysid`` (whose API comes with the ``[sysid]`` extra)."""
    import mujoco
    from mujoco import rollout as mj_rollout

    spec = furuta_spec()
    for name, value in values.items():
        write = PARAMETERS[name][4]
        if write is not None:
            write(spec, value)
    model = spec.compile()
    delay = values.get("input_delay", 0.0)

    def predict(x0, u_ext, dt):
        data = mujoco.MjData(model)
        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        starts = np.empty((len(x0), mujoco.mj_stateSize(model, full)))
        for k, x in enumerate(x0):
            mujoco.mj_resetData(model, data)
            data.qpos[:], data.qvel[:] = x[:2], x[2:]
            mujoco.mj_getState(model, data, starts[k], full)
        ctrl = np.stack([InputDynamics("delay", delay).apply(u, dt)[1:] for u in u_ext])
        state, _ = mj_rollout.rollout(model, data, starts, ctrl)
        return np.concatenate([x0[:, None, :], np.asarray(state)[:, :, 1:5]], axis=1)

    return predict
