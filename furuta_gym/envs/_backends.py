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

Each backend has its own module (:mod:`._backend_base`, :mod:`._mujoco_backend`,
:mod:`._model_backend`); this one turns the ``dynamics=`` keyword into one of them and keeps
their names importable from here.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Sequence

from ..effects import Effect
from ..lagrangian import AbstractLagrangianSystem
from ..models import LumpedSystem, analytic_model
from ..models.checkpoint import load_model
from ..systems import get_spec
from ._backend_base import AbstractBackend
from ._model_backend import KERNELS, ModelBackend
from ._mujoco_backend import MujocoBackend, load_mjcf
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
