"""The MuJoCo ground truth (:class:`MujocoBackend`): the shipped MJCF stepped by MuJoCo, with a
plant's extra physical effects as passive forces and per-reset physical parameters; see
:mod:`._backends`."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import xml.etree.ElementTree as ET
from typing import Mapping, Sequence

import mujoco
import numpy as np

from ..assets import asset_path
from ..effects import CableNeutral, Effect, MujocoForm, actuator_lag_time, shaped_input
from ..models import system_definition
from ..systems import get_spec
from ._backend_base import AbstractBackend
from ._parameters import default_parameters
from ._settings import Plant


def load_mjcf(system: str, actuator_lag: bool = False) -> mujoco.MjModel:
    """The shipped MJCF model of ``"furuta"`` or ``"nmsd"``.

    With ``actuator_lag`` its actuator gets first-order dynamics τ·u̇_m = u − u_m: one activation
    (``data.act`` = u_m, 0 after ``mj_resetData``) that the force uses instead of ``ctrl``; τ is
    written into ``actuator_dynprm[0, 0]`` by :func:`apply_parameters`.
    """
    if not actuator_lag:
        return mujoco.MjModel.from_xml_path(str(asset_path(f"{get_spec(system).name}.xml")))
    return mujoco.MjModel.from_xml_string(mjcf_text(system, actuator_lag))


def mjcf_text(system: str, actuator_lag: bool = False) -> str:
    """The MJCF text :func:`load_mjcf` compiles."""
    path = asset_path(f"{get_spec(system).name}.xml")
    if not actuator_lag:
        return path.read_text()
    # the activation changes the model's sizes (na), so it is added before compiling
    root = ET.parse(path).getroot()
    actuators = root.find("actuator")
    assert actuators is not None, path
    (actuator,) = list(actuators)
    if actuator.tag == "motor":  # <motor> is <general> with gain 1 and no bias, minus dyntype
        actuator.tag = "general"
    # 'filter', not 'filterexact': MuJoCo's RK4 integrates the activation with the state at every
    # stage (exact to ~6e-6 at h = τ/5), whereas filterexact's update applied to RK4's combined
    # derivative counts the decay twice (u_m 4 % short of 1 − 1/e at t = τ, h = τ/5)
    actuator.set("dyntype", "filter")
    actuator.set("dynprm", "1")
    return ET.tostring(root, encoding="unicode")


@dataclasses.dataclass
class PassiveForces:
    """The forces MuJoCo cannot express, for the passive callback: per dof the system's cubic
    stiffness and damping, the joint effects (their force laws, :meth:`Effect.law`), and the
    ``com_offset`` shift of MuJoCo's gravity potential, and the moving neutrals of hysteretic
    springs (their state: the plant advances them after each step)."""

    cubic: dict[int, tuple[float, float]]
    effects: dict[int, list[Effect]]
    shift: np.ndarray
    neutrals: dict[int, list[CableNeutral]] = dataclasses.field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.cubic or self.effects or self.shift.any() or self.neutrals)


def _gravity_force(model: mujoco.MjModel, scratch: mujoco.MjData, qpos, out: np.ndarray) -> np.ndarray:
    """g(q) = ∂V_gravity/∂q as MuJoCo computes it, into ``out``: the bias force at zero velocity.

    ``scratch`` is an MjData of ``model`` whose qvel (and so cvel, cdof_dot) is never set, i.e.
    zero: then recursive Newton-Euler without acceleration is gravity alone. Kinematics and
    com-frame quantities are all it needs (no mass matrix, no velocity stage).
    """
    scratch.qpos[:] = qpos
    mujoco.mj_kinematics(model, scratch)
    mujoco.mj_comPos(model, scratch)
    mujoco.mj_rne(model, scratch, 0, out)
    return out


def _check_gravitational(model: mujoco.MjModel, system: str, joint: str, dof: int) -> None:
    """``com_offset`` shifts MuJoCo's gravity potential only: refuse a joint gravity never acts on
    (probed at random configurations), whose potential in the model is something else."""
    scratch, out = mujoco.MjData(model), np.zeros(model.nv)
    scale = float(np.sum(model.body_mass) * np.linalg.norm(model.opt.gravity))
    for q in np.random.default_rng(0).uniform(-math.pi, math.pi, (8, model.nq)):
        if abs(_gravity_force(model, scratch, q, out)[dof]) > 1e-12 * max(scale, 1e-300):
            return
    raise ValueError(
        f"effect 'com_offset' on joint {joint!r}: gravity exerts no force on this joint of the "
        f"{system} MuJoCo model, so its potential there is not gravitational and shifting "
        f"MuJoCo's gravity cannot shift it; for a spring's neutral use "
        f"Effect('spring', {joint!r}, k, reference=...)"
    )


def apply_parameters(
    model: mujoco.MjModel,
    system: str,
    p: Mapping[str, float],
    effects: Sequence[Effect] = (),
    data: mujoco.MjData | None = None,
    lumped: bool = False,
) -> PassiveForces:
    """Write physical parameters (and the natively expressible effects) into ``model``.

    Returns the forces MuJoCo cannot express, which the passive callback applies (see
    :class:`PassiveForces`). Springs, viscous friction, the input
    gain and the actuator lag are native (joint stiffness with a combined rest position, joint
    damping, actuator gain and bias, actuator dynamics: ``model`` must then come from
    ``load_mjcf(system, actuator_lag=True)``). With ``lumped``, ``p`` holds the lumped form's
    values (a :class:`~furuta_gym.envs.Plant`'s) instead of the physical parameters.
    """
    spec = get_spec(system)
    n = spec.n_dof
    definition = system_definition(system)
    if lumped and definition.write_lumped_mujoco is None:
        raise ValueError(f"{system} has no MuJoCo form of its lumped parameters (write_lumped_mujoco)")
    terms = (definition.write_lumped_mujoco if lumped else definition.write_mujoco)(model, p)
    form = MujocoForm(np.array(terms.stiffness, float), np.zeros(n), np.array(terms.damping, float), shift=np.zeros(n))
    for e in effects:  # each kind writes itself: native terms, or laws for the callback
        e.kind.to_mujoco(e, -1 if e.kind.on_input else e.joint_index(spec), form)
    assert form.shift is not None
    extra = PassiveForces(
        {
            dof: cubic
            for dof, cubic in enumerate(zip(terms.cubic_stiffness, terms.cubic_damping, strict=True))
            if any(cubic)
        },
        form.laws,
        form.shift,
        form.neutrals,
    )
    # masses changed: refresh MuJoCo's derived constants (e.g. the constant mass of a body that
    # only slides, dof_M0, which the N-MSD uses instead of body_mass)
    mujoco.mj_setConst(model, mujoco.MjData(model) if data is None else data)
    model.jnt_stiffness[:] = form.stiffness
    model.qpos_spring[:] = np.divide(form.stiff_ref, form.stiffness, out=np.zeros(n), where=form.stiffness != 0)
    model.dof_damping[:] = form.damping
    model.actuator_gainprm[0, 0] = form.gain * terms.motor_gain
    model.actuator_biasprm[0, :3] = (0.0, 0.0, form.gain * terms.motor_bias)
    tau = actuator_lag_time(effects)
    if tau > 0:
        if model.na != 1:
            raise ValueError(
                "an actuator_lag needs the actuator's activation: load the model with "
                f"load_mjcf({system!r}, actuator_lag=True)"
            )
        model.actuator_dynprm[0, 0] = tau
    for e in effects:
        if e.kind.shifts_potential:
            _check_gravitational(model, system, e.joint, e.joint_index(spec))
    return extra


class _FloatMath:
    """The namespace :meth:`Effect.law` needs, on plain floats (the callback
    runs at every RK4 stage: numpy's scalar functions would cost more than the step itself)."""

    tanh, exp, abs = staticmethod(math.tanh), staticmethod(math.exp), staticmethod(abs)

    @staticmethod
    def sign(x: float) -> int:
        return (x > 0.0) - (x < 0.0)


def _passive_callback(extra: PassiveForces, model: mujoco.MjModel):
    """MuJoCo passive-force callback adding the non-native forces (evaluated at every RK4 stage).

    Per dof: the system's −k3·q³ − b3·q̇³, plus each effect's
    :meth:`furuta_gym.effects.Effect.law` (dry friction as the honest discontinuous
    sgn law, sgn(0) = 0, as :class:`~furuta_gym.effects.WithEffects` with no smoothing, so the
    model backend with the same effects matches it). A ``com_offset`` Δ shifts MuJoCo's own
    gravity potential, V(q) → V(q − Δ), generically: + g(q) − g(q − Δ), with g = ∂V_gravity/∂q
    computed by MuJoCo on a scratch MjData of ``model``.
    """
    dofs = sorted(set(extra.cubic) | set(extra.effects) | set(extra.neutrals))
    terms = tuple(
        (
            dof,
            *extra.cubic.get(dof, (0.0, 0.0)),
            tuple(e.law(xp=_FloatMath) for e in extra.effects.get(dof, ()))
            + tuple(lambda q, v, n=n: n.force(q) for n in extra.neutrals.get(dof, ())),
        )
        for dof in dofs
    )
    shift = extra.shift
    if shift.any() and model.nq != model.nv:
        raise ValueError("com_offset needs hinge/slide joints only (qpos and qvel of equal size)")
    scratch = mujoco.MjData(model) if shift.any() else None
    g_here, g_shifted = np.zeros(model.nv), np.zeros(model.nv)

    def callback(model, data):
        qpos, qvel, qfrc = data.qpos, data.qvel, data.qfrc_passive
        for dof, k3, b3, laws in terms:
            q, v = float(qpos[dof]), float(qvel[dof])
            f = -k3 * q * q * q - b3 * v * v * v
            for law in laws:
                f += law(q, v)
            qfrc[dof] += f
        if scratch is not None:
            _gravity_force(model, scratch, qpos, g_here)
            _gravity_force(model, scratch, qpos - shift, g_shifted)
            qfrc += g_here - g_shifted

    return callback


class MujocoBackend(AbstractBackend):
    """Ground truth: the shipped MJCF model stepped by MuJoCo's RK4, ``substeps`` per period
    (each of the MJCF's ``timestep``, unless ``timestep`` overrides it).

    ``effects`` (:class:`~furuta_gym.effects.Effect`) make a plant variant: springs, viscous
    friction and an input gain are written into the model; Coulomb friction (sgn law), quadratic
    drag and constant torques — and the N-MSD's cubic spring and damper, which MJCF lacks — are
    added by a MuJoCo passive-force callback that is installed only around this backend's own
    ``mj_step`` calls and restored afterwards, so other MuJoCo models in the process are untouched.
    ``input_delay`` effects are ignored here (the env's input buffer applies them).

    Stiction (the Stribeck term) joins Coulomb friction in the callback; ``com_offset`` adds
    g(q) − g(q − Δ) there, g being MuJoCo's own gravity force (a joint gravity does not act on is
    refused: its potential is not gravitational). ``actuator_lag`` is native actuator dynamics
    (``dyntype="filter"``, ``dynprm[0]`` = τ): the activation ``data.act`` holds u_m and MuJoCo
    integrates it with the state in every RK4 stage; :meth:`reset` sets it to 0 (the plant at rest
    with no input), :attr:`state` stays (q, q̇) and :attr:`lagged_input` reads or sets u_m.
    An ``input_dead_band`` (no MJCF form) dead-bands the control before it reaches the actuator,
    as the analytic model's τ_u takes the dead-banded input; with an ``actuator_lag`` too the two
    would disagree on their order (MuJoCo's lag acts after the control), so that is refused.
    """

    native_actuator_lag = True

    def __init__(
        self,
        system: str,
        substeps: int = 1,
        effects: Sequence[Effect] = (),
        parameters: Mapping[str, float] | None = None,
        timestep: float | None = None,
        plant: Plant | None = None,
    ):
        self.system = get_spec(system).name
        self.plant = plant
        if plant is not None:
            if plant.lumped is None or plant.presets or plant.system != self.system or effects or parameters:
                raise ValueError(
                    f"plant= is a whole {self.system} plant with its lumped parameters (presets "
                    "resolved into effects): give it alone, no effects= or parameters="
                )
            effects = plant.effects
        self.effects = tuple(effects)
        self._shaped = shaped_input(self.effects, np)
        if self._shaped is not None and actuator_lag_time(self.effects) > 0:
            raise ValueError(
                "an input_dead_band with an actuator_lag: MuJoCo's lag acts on the dead-banded control, "
                "the analytic model's dead band on the lagged input; give one of them"
            )
        self.model = load_mjcf(self.system, actuator_lag=actuator_lag_time(self.effects) > 0)
        if timestep is not None:  # default: the MJCF's (what every env uses)
            self.model.opt.timestep = float(timestep)
        self.data = mujoco.MjData(self.model)
        self.timestep = float(self.model.opt.timestep)
        self.substeps = int(substeps)
        self._n = self.spec.n_dof
        self._callback = None
        self._bind_views()
        self.set_parameters(parameters or self._nominal())

    def _nominal(self) -> dict[str, float]:
        """The parameters set_parameters starts from: the plant's lumped ones, or the pinned ones."""
        if self.plant is not None and self.plant.lumped is not None:  # (a plant always has them)
            return dict(self.plant.lumped)
        return default_parameters(self.system)

    def _bind_views(self) -> None:
        # MjData's array attributes build a new NumPy view on every access; the step path reuses
        # these (they stay valid as long as self.data does)
        self._ctrl, self._qpos, self._qvel = self.data.ctrl, self.data.qpos, self.data.qvel

    def set_parameters(self, values: Mapping[str, float]) -> None:
        """Physical parameters (any subset), or for a ``plant=`` backend its lumped ones."""
        nominal = self._nominal()
        unknown = sorted(set(values) - set(nominal))
        if unknown:
            what = "lumped parameter(s) of its plant" if self.plant is not None else "parameter(s)"
            raise ValueError(f"unknown {self.system} {what} {unknown}; expected {list(nominal)}")
        self._parameters = {**nominal, **{k: float(v) for k, v in values.items()}}
        self._apply_parameters()

    def _apply_parameters(self) -> None:
        """Write parameters and effects into the model and rebuild the passive callback. The
        state survives: mj_setConst works in ``self.data`` and leaves qpos at qpos0."""
        d = self.data
        saved = (d.qpos.copy(), d.qvel.copy(), d.act.copy(), d.time)
        extra = apply_parameters(
            self.model, self.system, self._parameters, self.effects, d, lumped=self.plant is not None
        )
        d.qpos[:], d.qvel[:], d.act[:], d.time = saved
        self._callback = _passive_callback(extra, self.model) if extra else None
        self._neutrals = [(dof, n) for dof, ns in extra.neutrals.items() for n in ns]

    def reset(self, x) -> None:
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = x[: self._n]
        self.data.qvel[:] = x[self._n :]
        for _, neutral in self._neutrals:
            neutral.reset()

    def move(self, x) -> None:
        """Put the system at state ``x`` as a hand would carry it there from where it is: unlike
        :meth:`reset`, effects with memory are kept, and a hysteretic spring's neutral is dragged
        along the joint's straight path (releases of a rig whose cable remembers the last one)."""
        self.data.qpos[:] = x[: self._n]
        self.data.qvel[:] = x[self._n :]
        for dof, neutral in self._neutrals:
            neutral.advance(float(self._qpos[dof]))

    @contextlib.contextmanager
    def passive_forces(self):
        """Context in which MuJoCo computes this plant's full passive force (callback installed);
        the previous global callback is restored on exit. Use around your own ``mj_forward``."""
        if self._callback is None:
            yield
            return
        previous = mujoco.get_mjcb_passive()
        mujoco.set_mjcb_passive(self._callback)
        try:
            yield
        finally:
            mujoco.set_mjcb_passive(previous)

    def _mj_step(self, nstep: int) -> None:
        if self._callback is None:
            mujoco.mj_step(self.model, self.data, nstep)
            return
        previous = mujoco.get_mjcb_passive()
        mujoco.set_mjcb_passive(self._callback)
        try:
            mujoco.mj_step(self.model, self.data, nstep)
        finally:
            mujoco.set_mjcb_passive(previous)
        for dof, neutral in self._neutrals:
            neutral.advance(float(self._qpos[dof]))

    def _control(self, u):
        """What the actuator gets of the input ``u``: ``u``, or ``u`` through its dead band."""
        return u if self._shaped is None else self._shaped(np.asarray(u, dtype=np.float64))

    def step(self, u) -> np.ndarray:
        self._ctrl[:] = self._control(u)
        self._mj_step(self.substeps)
        return np.concatenate((self._qpos, self._qvel))

    def step_split(self, u_first, n_first: int, u) -> np.ndarray:
        if n_first > 0:
            self.data.ctrl[:] = self._control(u_first)
            self._mj_step(n_first)
        self.data.ctrl[:] = self._control(u)
        if self.substeps - n_first > 0:
            self._mj_step(self.substeps - n_first)
        return np.concatenate((self.data.qpos, self.data.qvel))

    @property
    def state(self) -> np.ndarray:
        return np.concatenate((self.data.qpos, self.data.qvel))

    @property
    def lagged_input(self) -> np.ndarray | None:
        """u_m of an ``actuator_lag`` plant (the actuator's activation); None without a lag."""
        return self.data.act.copy() if self.model.na else None

    @lagged_input.setter
    def lagged_input(self, u_m) -> None:
        if self.model.na:
            self.data.act[:] = u_m

    def _scene_data(self):
        return self.model, self.data

    def __getstate__(self):
        # MjModel/MjData pickle, but the callback closure does not: rebuild it on unpickling
        state = self.__dict__.copy()
        state["_callback"] = None
        for k in ("_ctrl", "_qpos", "_qvel", "_neutrals", "_shaped"):
            state.pop(k, None)
        return state

    def __setstate__(self, state):
        vars(self).update(state)
        self._shaped = shaped_input(self.effects, np)
        self._bind_views()
        self._apply_parameters()
