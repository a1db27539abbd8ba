"""Dynamics backends: what advances the state of an env by one control period.

An env never talks to MuJoCo or JAX directly; it holds an :class:`AbstractBackend`:

* :class:`MujocoBackend` — the ground truth: ``assets/<system>.xml`` stepped by MuJoCo (RK4), with
  optional extra physical effects (plant variants) and per-reset physical parameters.
* :class:`ModelBackend` — any :class:`~furuta_gym.lagrangian.AbstractLagrangianSystem` (the
  analytic model, a learned DeLaN/APHYNITY checkpoint, a user's model), integrated with the same
  fixed-step RK4 and the input held over the period (:func:`furuta_gym.simulate.rk4_zoh_step`),
  jit-compiled, float64.

Both integrate the period in ``substeps`` RK4 steps of the MJCF ``timestep``, so the analytic
backend reproduces the MuJoCo backend to round-off (~1e-12). Both render through the MuJoCo scene
(a model backend poses the MJCF bodies at its state). :func:`make_backend` turns the envs'
``dynamics=`` keyword into a backend.
"""

from __future__ import annotations

import abc
import contextlib
import dataclasses
import math
import os
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.flatten_util import ravel_pytree

from .._ckernel import CKernel, CKernelError, CKernelTranslationError, CKernelWarning
from .._x64 import ensure_x64
from ..assets import asset_path
from ..effects import CableNeutral, Effect, MujocoForm, WithEffects, actuator_lag_time
from ..lagrangian import AbstractLagrangianSystem
from ..models import LumpedSystem, analytic_model, system_definition
from ..models.checkpoint import load_model
from ..simulate import rk4_step, small_kernel_compiler_options
from ..systems import get_spec
from ._parameters import PARAMETER_CLASSES, default_parameters
from ._settings import Plant

__all__ = [
    "AbstractBackend",
    "MujocoBackend",
    "ModelBackend",
    "make_backend",
    "load_checkpoint",
    "DYNAMICS_NAMES",
    "KERNELS",
]

DYNAMICS_NAMES = ("mujoco", "analytic")
_ACCEPTED = (
    "'mujoco' (MuJoCo ground truth), 'analytic' (closed-form model in JAX), a checkpoint path "
    "written by `furuta-gym train`, or an AbstractLagrangianSystem object"
)


class AbstractBackend(abc.ABC):
    """Advance a system's state (q, q̇) one control period at a time, input held (zero-order hold).

    The period is ``substeps`` RK4 steps of ``timestep`` seconds. Concrete backends implement
    :meth:`reset`, :meth:`step`, :meth:`step_split` and :meth:`_scene_data`.
    """

    system: str  # "furuta" or "nmsd"
    _parameters: dict[str, float]
    timestep: float  # seconds per RK4 step
    substeps: int  # RK4 steps per control period
    #: whether the backend applies an ``actuator_lag`` effect itself (else the env does)
    native_actuator_lag: bool = False

    @property
    def spec(self):
        return get_spec(self.system)

    @property
    def control_dt(self) -> float:
        """Control period in seconds."""
        return self.timestep * self.substeps

    @property
    def parameters(self) -> dict[str, float]:
        """Physical parameters in use (the pinned ones unless :meth:`set_parameters` changed them)."""
        return dict(self._parameters)

    @abc.abstractmethod
    def reset(self, x: np.ndarray) -> None:
        """Put the system at state ``x`` = (q, q̇), time 0."""

    @abc.abstractmethod
    def step(self, u: np.ndarray) -> np.ndarray:
        """Advance one control period with ``u`` held; return the new state (a fresh float64 array)."""

    @abc.abstractmethod
    def step_split(self, u_first: np.ndarray, n_first: int, u: np.ndarray) -> np.ndarray:
        """Advance one period applying ``u_first`` for the first ``n_first`` substeps, then ``u``
        (an actuation delay that is not a whole number of periods)."""

    @property
    @abc.abstractmethod
    def state(self) -> np.ndarray:
        """Current state (a copy)."""

    def set_parameters(self, values: Mapping[str, float]) -> None:
        """Use these physical parameters from now on (domain randomisation)."""
        raise ValueError(
            f"{type(self).__name__} has no physical parameters to change; domain randomisation "
            "needs dynamics='mujoco' or 'analytic'"
        )

    # -- rendering through the MuJoCo scene --------------------------------------------------
    @abc.abstractmethod
    def _scene_data(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """(model, data) whose qpos is the current configuration."""

    def scene(self) -> tuple[mujoco.MjModel, mujoco.MjData]:
        """The MuJoCo (model, data) posed at the current configuration, kinematics computed."""
        model, data = self._scene_data()
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_tendon(model, data)  # the N-MSD spring is drawn as a tendon
        return model, data


# ---------------------------------------------------------------------------------------------
# MuJoCo ground truth
# ---------------------------------------------------------------------------------------------


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

    def step(self, u) -> np.ndarray:
        self._ctrl[:] = u
        self._mj_step(self.substeps)
        return np.concatenate((self._qpos, self._qvel))

    def step_split(self, u_first, n_first: int, u) -> np.ndarray:
        if n_first > 0:
            self.data.ctrl[:] = u_first
            self._mj_step(n_first)
        self.data.ctrl[:] = u
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
        for k in ("_ctrl", "_qpos", "_qvel", "_neutrals"):
            state.pop(k, None)
        return state

    def __setstate__(self, state):
        vars(self).update(state)
        self._bind_views()
        self._apply_parameters()


# ---------------------------------------------------------------------------------------------
# Any Lagrangian model, in JAX
# ---------------------------------------------------------------------------------------------

_STEP_CACHE: dict = {}
_C_KERNEL_CACHE: dict = {}

#: ``kernel=`` values of the model backends (see :class:`ModelBackend`)
KERNELS = ("auto", "c", "xla")


def _step_functions(static, rebuild, timestep: float, substeps: int):
    """The (full period, split period) steps of one model structure as plain JAX functions of
    ``(model arrays, x, u...)``: what both kernels compile."""

    def period(flat, x, u):
        system = eqx.combine(rebuild(flat), static)
        return jax.lax.fori_loop(0, substeps, lambda _, x_: rk4_step(system, x_, u, timestep), x)

    def split(flat, x, u_first, n_first, u):
        system = eqx.combine(rebuild(flat), static)

        def body(i, x_):
            return rk4_step(system, x_, jnp.where(i < n_first, u_first, u), timestep)

        return jax.lax.fori_loop(0, substeps, body, x)

    return period, split


def _compiled_steps(static, rebuild, treedef_key, timestep: float, substeps: int):
    """Jitted (full period, split period) steps for one model structure; cached across envs so
    a second env of the same model (or new parameters / weights) does not recompile.

    The model's arrays travel as ``(vector, matrices)``: every scalar and vector leaf raveled into
    ONE float64 vector (one argument to flatten per call instead of many, and XLA fuses the
    unravelling slices into their elementwise consumers), the matrices (network weights) as a
    list of their own: a slice feeding a matrix product is a separate XLA kernel per leaf and call,
    a large share of a single-copy step.
    """
    key = (treedef_key, timestep, substeps)
    try:
        return _STEP_CACHE[key]
    except (KeyError, TypeError):
        pass
    period, split = _step_functions(static, rebuild, timestep, substeps)
    options = small_kernel_compiler_options()
    fns = (jax.jit(period, compiler_options=options), jax.jit(split, compiler_options=options))
    try:
        _STEP_CACHE[key] = fns
    except TypeError:  # unhashable static structure: no sharing, still correct
        pass
    return fns


class _XlaStepper:
    """The period step as one jitted XLA call (the state stays a JAX array between steps)."""

    name = "xla"

    def __init__(self, static, rebuild, treedef_key, dynamic, timestep, substeps, n_state, n_inputs):
        self._period, self._split = _compiled_steps(static, rebuild, treedef_key, timestep, substeps)
        self._dynamic = dynamic
        self._x = None

    def reset(self, x) -> None:
        self._x = jnp.asarray(np.asarray(x, dtype=np.float64))

    def step(self, u) -> np.ndarray:
        self._x = self._period(self._dynamic, self._x, u)
        return np.array(self._x)

    def step_split(self, u_first, n_first: int, u) -> np.ndarray:
        self._x = self._split(self._dynamic, self._x, u_first, n_first, u)
        return np.array(self._x)

    @property
    def state(self) -> np.ndarray | None:
        return None if self._x is None else np.array(self._x)


class _CStepper:
    """The same period step lowered to one C function (:mod:`furuta_gym._ckernel`), called
    on fixed numpy buffers: the model's arrays are copied in once per model, the state is
    updated in place: no XLA dispatch or per-kernel overhead, which dominate one small step."""

    name = "c"

    def __init__(self, static, rebuild, treedef_key, dynamic, timestep, substeps, n_state, n_inputs):
        self._n_state = n_state
        self._functions = _step_functions(static, rebuild, timestep, substeps)
        self._model_name = type(static).__name__  # named when its C kernel is refused
        self._key = (treedef_key, timestep, substeps, n_inputs)
        self._leaves = [np.asarray(a) for a in jax.tree_util.tree_leaves(dynamic)]
        self._dynamic = dynamic
        self._n_inputs = n_inputs
        self._x_buf = None
        self._has_state = False
        self._period = self._bind("period")  # built now: a model C cannot take fails here
        self._split = None
        self._xla_split = None
        self._xla_arguments = (static, rebuild, treedef_key, timestep, substeps)

    def _kernel(self, which: str):
        """The compiled kernel of this model structure, or the CKernelError it gave: a failure is
        cached too, so ``kernel="auto"`` does not trace and translate the step again at every
        reset that draws new parameters (domain randomisation)."""
        key = (which, *self._key)
        try:
            kernel = _C_KERNEL_CACHE[key]
        except (KeyError, TypeError):
            period, split = self._functions
            x, u = np.zeros(self._n_state), np.zeros(self._n_inputs)
            try:
                if which == "period":
                    kernel = CKernel(period, self._dynamic, x, u, name=f"period step of {self._model_name}")
                else:
                    kernel = CKernel(
                        split, self._dynamic, x, u, np.int64(0), u, name=f"split step of {self._model_name}"
                    )
            except CKernelError as exc:
                kernel = exc
                if isinstance(exc, CKernelTranslationError):  # once per model structure: cached below
                    warnings.warn(
                        f"the {which} step of {self._model_name} has no C translation, XLA steps it: {exc}",
                        CKernelWarning,
                        stacklevel=2,
                    )
            try:
                _C_KERNEL_CACHE[key] = kernel
            except TypeError:  # unhashable static structure: no sharing, still correct
                pass
        if isinstance(kernel, CKernelError):
            raise kernel
        return kernel

    def _bind(self, which: str):
        """(call, the step's input buffers after x); x's buffer is shared by both kernels."""
        kernel = self._kernel(which)
        inputs, _ = kernel.new_buffers()
        k = len(self._leaves)  # the model's leaves come first, then x and the step's inputs
        for buf, leaf in zip(inputs[:k], self._leaves, strict=True):
            buf[...] = leaf
        if self._x_buf is None:
            self._x_buf = inputs[k]
        inputs[k] = self._x_buf
        return kernel.bind(inputs, [self._x_buf]), inputs[k + 1 :]

    def reset(self, x) -> None:
        self._x_buf[:] = np.asarray(x, dtype=np.float64)
        self._has_state = True

    def step(self, u) -> np.ndarray:
        call, (u_buf,) = self._period
        u_buf[:] = u
        call()
        return self._x_buf.copy()

    def step_split(self, u_first, n_first: int, u) -> np.ndarray:
        if self._split is None and self._xla_split is None:
            try:
                self._split = self._bind("split")
            except CKernelError:  # the period step stays C; this one XLA (warned if untranslatable)
                self._xla_split = _compiled_steps(*self._xla_arguments)[1]
        if self._xla_split is not None:
            self._x_buf[:] = np.asarray(self._xla_split(self._dynamic, jnp.asarray(self._x_buf), u_first, n_first, u))
            return self._x_buf.copy()
        assert self._split is not None
        call, (u_first_buf, n_buf, u_buf) = self._split
        u_first_buf[:] = u_first
        n_buf[...] = n_first
        u_buf[:] = u
        call()
        return self._x_buf.copy()

    @property
    def state(self) -> np.ndarray | None:
        return self._x_buf.copy() if self._has_state else None


class ModelBackend(AbstractBackend):
    """Any Lagrangian system in JAX: ``substeps`` RK4 steps of ``timestep`` per period, input held.

    ``effects`` (joint effects and ``input_gain``) are added with
    :class:`furuta_gym.effects.WithEffects` (Coulomb and stiction as the exact sgn law, like the
    MuJoCo backend); ``input_delay`` and ``actuator_lag`` are left to the env's actuation path.
    :meth:`set_parameters` works for the analytic models (their ``params`` pytree).
    Rendering poses the system's MJCF scene at the model's state.

    ``kernel`` chooses what runs the period step (the same JAX function either way):

    * ``"c"``: the step's jaxpr lowered to one C function and compiled with the system's C
      compiler (:mod:`furuta_gym._ckernel`; cached on disk, built once per model structure).
      A single env steps several times faster than through XLA, whose fixed cost per call
      dominates one small step (BENCHMARKS.md).
    * ``"xla"``: one jitted XLA call per step.
    * ``"auto"`` (default): ``"c"`` when a C compiler is on PATH and every primitive of the model's
      step has a C translation, else ``"xla"``; :attr:`kernel` says which, and
      :attr:`kernel_fallback` why not C.
    """

    def __init__(
        self,
        model: AbstractLagrangianSystem,
        timestep: float,
        substeps: int = 1,
        effects: Sequence[Effect] = (),
        parameters: Mapping[str, float] | None = None,
        kernel: str = "auto",
    ):
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {list(KERNELS)}, got {kernel!r}")
        ensure_x64()
        self.kernel_request = kernel
        self.kernel_fallback: str | None = None
        self._stepper = None
        self.system = model.spec.name
        self.base_model = model
        self.timestep = float(timestep)
        self.substeps = int(substeps)
        with_state = [e.name for e in effects if e.kind.has_memory and not e.kind.on_input]
        if with_state:
            raise ValueError(
                f"effects {with_state} have memory that a model backend does not keep; "
                "use the MuJoCo plant (dynamics='mujoco')"
            )
        self.effects = tuple(e for e in effects if not e.kind.has_memory)
        self._n = self.spec.n_dof
        self._scene = None
        # the model's own parameter values (an analytic model may carry non-pinned ones)
        own = self._model_parameters()
        self._parameters = _params_as_floats(own) if own is not None else {}
        if parameters:
            self.set_parameters(parameters)
        else:
            self._set_model(model)

    def _model_parameters(self):
        """The model's physical parameters when it carries the system's (an analytic model), else None."""
        params = getattr(self.base_model, "params", None)  # a learned model has none
        return params if isinstance(params, PARAMETER_CLASSES[self.system]) else None

    def _has_parameters(self) -> bool:
        return self._model_parameters() is not None

    def _set_model(self, model: AbstractLagrangianSystem) -> None:
        self.model = WithEffects(model, self.effects) if self.effects else model
        dynamic, static = eqx.partition(self.model, eqx.is_array)
        leaves, treedef = jax.tree_util.tree_flatten(dynamic)
        is_matrix = tuple(a.ndim >= 2 for a in leaves)
        vector, unravel = ravel_pytree([a for a, m in zip(leaves, is_matrix, strict=True) if not m])
        self._dynamic = (vector, [a for a, m in zip(leaves, is_matrix, strict=True) if m])

        def rebuild(arrays):  # (vector, matrices) -> the model's dynamic pytree
            small, matrices = iter(unravel(arrays[0])), iter(arrays[1])
            return jax.tree_util.tree_unflatten(treedef, [next(matrices) if m else next(small) for m in is_matrix])

        shapes = tuple((a.shape, str(a.dtype)) for a in leaves)
        treedef_key = (treedef, shapes, static)
        self._stepper = self._make_stepper(static, rebuild, treedef_key)

    def _make_stepper(self, static, rebuild, treedef_key):
        state = None if self._stepper is None else self._stepper.state
        n_inputs = len(self.spec.input_names)
        args = (static, rebuild, treedef_key, self._dynamic, self.timestep, self.substeps, 2 * self._n, n_inputs)
        stepper = None
        if self.kernel_request in ("auto", "c"):
            try:
                stepper = _CStepper(*args)
            except CKernelError as exc:
                if self.kernel_request == "c":
                    raise ValueError(f"kernel='c': {exc}") from exc
                self.kernel_fallback = str(exc)
        if stepper is None:
            stepper = _XlaStepper(*args)
        if state is not None:
            stepper.reset(state)
        return stepper

    @property
    def kernel(self) -> str:
        """What runs the period step: ``"c"`` or ``"xla"`` (see the class docstring)."""
        return self._stepper.name

    def set_parameters(self, values: Mapping[str, float]) -> None:
        own = self._model_parameters()
        if own is None:
            super().set_parameters(values)  # raises: nothing to change

        nominal = default_parameters(self.system)
        unknown = sorted(set(values) - set(nominal))
        if unknown:
            raise ValueError(f"unknown {self.system} parameter(s) {unknown}; expected {list(nominal)}")
        merged = {**{k: float(v) for k, v in _params_as_floats(own).items()}}
        merged.update({k: float(v) for k, v in values.items()})
        self._parameters = merged
        params = PARAMETER_CLASSES[self.system](**merged)
        self._set_model(eqx.tree_at(lambda m: m.params, self.base_model, params))

    def reset(self, x) -> None:
        self._stepper.reset(x)

    def step(self, u) -> np.ndarray:
        return self._stepper.step(u)

    def step_split(self, u_first, n_first: int, u) -> np.ndarray:
        return self._stepper.step_split(u_first, n_first, u)

    @property
    def state(self) -> np.ndarray | None:  # None before the first reset
        return self._stepper.state

    def _scene_data(self):
        if self._scene is None:
            model = load_mjcf(self.system)
            self._scene = (model, mujoco.MjData(model))
        model, data = self._scene
        data.qpos[:] = self.state[: self._n]
        return model, data

    def __getstate__(self):
        # compiled steps do not pickle; the model (an Equinox pytree) and the state do
        state = self.__dict__.copy()
        for k in ("_stepper", "_dynamic", "model"):
            state.pop(k, None)
        state["_pickled_state"] = None if self._stepper is None else self._stepper.state
        state["_scene"] = None
        return state

    def __setstate__(self, state):
        x = state.pop("_pickled_state", None)
        vars(self).update(state)
        self._stepper = None
        if self._parameters and self._has_parameters():
            self.set_parameters(self._parameters)
        else:
            self._set_model(self.base_model)
        if x is not None:
            self.reset(x)


def _params_as_floats(params) -> dict[str, float]:
    return {f.name: float(getattr(params, f.name)) for f in dataclasses.fields(params)}


# ---------------------------------------------------------------------------------------------
# dynamics= keyword
# ---------------------------------------------------------------------------------------------


def load_checkpoint(path: str | os.PathLike, system: str | None = None) -> AbstractLagrangianSystem:
    """Load a model written by ``furuta-gym train`` (:func:`furuta_gym.models.checkpoint.load_model`);
    with ``system``, a checkpoint of the other system is a clear error."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"dynamics: checkpoint file {str(path)!r} not found; accepted: {_ACCEPTED}")
    return load_model(path, expected_system=system)


def _lumped_backend(system, dynamics, substeps, effects, lumped, kernel) -> AbstractBackend:
    """A diagnosed plant's backend: MuJoCo with its bodies, or its lumped model (``"analytic"``)."""
    if isinstance(dynamics, str) and dynamics == "mujoco":
        return MujocoBackend(system, substeps, plant=Plant(effects=effects, lumped=lumped, system=system))
    if isinstance(dynamics, str) and dynamics == "analytic":
        timestep = float(load_mjcf(system).opt.timestep)
        return ModelBackend(LumpedSystem.of(system, lumped), timestep, substeps, effects, kernel=kernel)
    raise ValueError(
        f"dynamics={dynamics!r}: a diagnosed plant (its lumped parameters) runs on "
        "dynamics='mujoco' or 'analytic' (its lumped model); a learned model has its own"
    )


def _named_model(name: str, system: str) -> AbstractLagrangianSystem:
    """The model ``dynamics=name`` names: ``"analytic"`` or a checkpoint's path."""
    if name == "analytic":
        return analytic_model(system)
    if Path(name).exists() or os.sep in name or Path(name).suffix:
        model = load_checkpoint(name, system)
        if not isinstance(model, AbstractLagrangianSystem):
            raise ValueError(
                f"dynamics: checkpoint {name!r} did not load as an AbstractLagrangianSystem "
                f"(got {type(model).__name__})"
            )
        return model
    raise ValueError(f"dynamics: unknown backend {name!r}; accepted: {_ACCEPTED}")


def make_backend(
    system: str,
    dynamics="mujoco",
    *,
    substeps: int = 1,
    effects: Sequence[Effect] = (),
    parameters: Mapping[str, float] | None = None,
    kernel: str = "auto",
    lumped: Mapping[str, float] | None = None,
) -> AbstractBackend:
    """The backend the envs' ``dynamics=`` keyword names, for ``system`` ("furuta"/"nmsd").

    Model backends use the MJCF model's ``timestep`` so they integrate exactly as MuJoCo does;
    ``kernel`` is the model backends' step kernel (:class:`ModelBackend`). ``lumped``: a
    diagnosed plant's lumped parameters instead of the pinned physical ones.
    """
    system = get_spec(system).name
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {list(KERNELS)}, got {kernel!r}")
    if lumped is not None:
        return _lumped_backend(system, dynamics, substeps, effects, lumped, kernel)
    if isinstance(dynamics, AbstractLagrangianSystem):
        model = dynamics
    elif isinstance(dynamics, (str, os.PathLike)):
        name = os.fspath(dynamics)
        if name == "mujoco":
            if kernel != "auto":
                raise ValueError(
                    f"kernel={kernel!r} chooses how a model backend's step runs; dynamics='mujoco' "
                    "is stepped by MuJoCo itself (leave kernel at 'auto')"
                )
            return MujocoBackend(system, substeps, effects, parameters)
        model = _named_model(name, system)
    else:
        raise ValueError(f"dynamics: expected {_ACCEPTED}; got an object of type {type(dynamics).__name__}")
    model_system = getattr(getattr(model, "spec", None), "name", None)
    if model_system != system:
        raise ValueError(
            f"dynamics: the model is a {model_system!r} model but this env simulates {system!r}; "
            f"load a {system} checkpoint"
        )
    timestep = float(load_mjcf(system).opt.timestep)
    return ModelBackend(model, timestep, substeps, effects, parameters, kernel=kernel)
