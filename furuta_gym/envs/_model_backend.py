"""Any Lagrangian model stepped in JAX (:class:`ModelBackend`): fixed-step RK4 with the input
held, run by one jitted XLA call or by the same step lowered to C (:mod:`furuta_gym._ckernel`);
see :mod:`._backends`."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.flatten_util import ravel_pytree

from .._ckernel import CKernel, CKernelError, CKernelTranslationError, CKernelWarning
from .._x64 import ensure_x64
from ..effects import Effect, WithEffects
from ..lagrangian import AbstractLagrangianSystem
from ..simulate import rk4_step, small_kernel_compiler_options
from ._backend_base import AbstractBackend
from ._mujoco_backend import load_mjcf
from ._parameters import PARAMETER_CLASSES, default_parameters

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
