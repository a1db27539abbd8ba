"""Is a learned potential physical? Its shape at the system's equilibria.

Data that only visit part of the configuration space, or that a feedback loop makes the input a
function of the state, can leave an equation-error loss free to learn a potential of the wrong
shape (on the shipped closed-loop QUBE runs, L_prop learned the upright pendulum as a *minimum*,
docs/learning.md). Prediction scores near the data do not show it; a controller designed on such
a model fails much later. The physics fixes the sign of ∂²V/∂q² at each equilibrium the system's
definition lists (:attr:`furuta_gym.models.SystemDefinition.equilibria`); :func:`check_potential_shape`
measures it (autodiff, ``jax.grad`` of ``jax.grad``) and :func:`warn_potential_shape` warns with
:class:`PotentialShapeWarning` when one is wrong. Training calls both (``train``: every snapshot's
history line and the final record).
"""

from __future__ import annotations

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..lagrangian import SystemSpec
from ..models import system_definition

__all__ = [
    "DataCoverageWarning",
    "PotentialShapeWarning",
    "check_data_coverage",
    "check_potential_shape",
    "warn_data_coverage",
    "warn_potential_shape",
]

#: how near an equilibrium (rad or m, along its joint) a sample must come to count as visiting it
COVERAGE_RADIUS = 0.5


class PotentialShapeWarning(UserWarning):
    """A learned potential has the wrong shape (minimum / maximum) at an equilibrium."""


class DataCoverageWarning(UserWarning):
    """The training data never come near one of the system's equilibria: what a model learns
    there is extrapolation, and designs that rely on it are not supported by the data."""


@eqx.filter_jit
def _curvatures(model, points, joints):
    """∂²V/∂q_j² at each point (rows of ``points``) along its joint index."""

    def one(q, j):
        along = lambda s: model.potential(q.at[j].set(s))  # noqa: E731
        return jax.grad(jax.grad(along))(q[j])

    return jnp.stack([one(points[k], j) for k, j in enumerate(joints)])


def check_potential_shape(model, system: str | SystemSpec | None = None) -> dict:
    """The learned potential's curvature at each equilibrium of the system's definition.

    ``system`` defaults to ``model.spec``. Returns ``{"physical": bool, "equilibria": [{"name",
    "q", "joint", "expected", "curvature", "ok"}, ...]}``; ``curvature`` is ∂²V/∂q² along the
    equilibrium's joint in the model's units (N·m/rad, N/m), ``ok`` whether its sign is the one
    ``expected`` (a flat potential, curvature 0, is neither a minimum nor a maximum).
    """
    spec = system if system is not None else getattr(model, "spec", None)
    if spec is None:
        raise ValueError("check_potential_shape: the model has no .spec; pass system='furuta' or 'nmsd'")
    definition = system_definition(spec)
    eqs = definition.equilibria
    if not eqs:
        return {"physical": True, "equilibria": []}
    names = definition.spec.joint_names
    joints = tuple(names.index(e.joint) for e in eqs)
    points = jnp.asarray([e.q for e in eqs], dtype=float)
    curv = [float(c) for c in _curvatures(model, points, joints)]
    rows = [
        {
            "name": e.name,
            "q": list(e.q),
            "joint": e.joint,
            "expected": e.shape,
            "curvature": c,
            "ok": bool(c > 0 if e.shape == "minimum" else c < 0),
        }
        for e, c in zip(eqs, curv, strict=True)
    ]
    return {"physical": all(r["ok"] for r in rows), "equilibria": rows}


def shape_message(result: dict) -> str | None:
    """One sentence naming every equilibrium with the wrong shape, or ``None`` if all are right."""
    wrong = [r for r in result["equilibria"] if not r["ok"]]
    if not wrong:
        return None
    parts = [
        f"{r['name']} must be a {r['expected']} (∂²V/∂{r['joint']}² {'>' if r['expected'] == 'minimum' else '<'} 0) "
        f"but the learned curvature is {r['curvature']:.3g}"
        for r in wrong
    ]
    return (
        "learned potential is not physical: "
        + "; ".join(parts)
        + ". The data may not determine the potential there (e.g. closed-loop data near one "
        "equilibrium); a swing-up or LQR designed on this model rests on the wrong shape."
    )


def warn_potential_shape(model, system: str | SystemSpec | None = None, *, stacklevel: int = 2) -> dict:
    """:func:`check_potential_shape`, and one :class:`PotentialShapeWarning` if any shape is wrong."""
    result = check_potential_shape(model, system)
    message = shape_message(result)
    if message is not None:
        warnings.warn(message, PotentialShapeWarning, stacklevel=stacklevel + 1)
    return result


def check_data_coverage(trajs, system: str | SystemSpec, radius: float = COVERAGE_RADIUS) -> dict:
    """Per equilibrium of the system's definition, the share of the samples of ``trajs`` whose
    equilibrium joint lies within ``radius`` of it (angles compared modulo 2π). Returns
    ``{"radius", "n_samples", "equilibria": [{"name", "joint", "share"}, ...]}``."""
    definition = system_definition(system)
    spec = definition.spec
    q = np.concatenate([np.asarray(tr.q, dtype=float).reshape(len(tr.q), -1) for tr in trajs])
    rows = []
    for e in definition.equilibria:
        j = spec.joint_names.index(e.joint)
        d = q[:, j] - e.q[j]
        if spec.angular[j]:
            d = np.angle(np.exp(1j * d))
        rows.append({"name": e.name, "joint": e.joint, "share": float(np.mean(np.abs(d) <= radius))})
    return {"radius": radius, "n_samples": int(q.shape[0]), "equilibria": rows}


def coverage_message(result: dict) -> str | None:
    """One sentence naming the equilibria the data never visit and those they do, or ``None``."""
    missed = [r["name"] for r in result["equilibria"] if r["share"] == 0.0]
    if not missed:
        return None
    seen = [f"{r['name']} ({r['share']:.0%} of the samples)" for r in result["equilibria"] if r["share"] > 0]
    return (
        f"the training data never come within {result['radius']:g} of {' or '.join(missed)} "
        f"({result['n_samples']} samples): what the model learns there is extrapolation, and a design that "
        "relies on it (an energy swing-up through it) is not supported by these data"
        + (f"; one about {', '.join(seen)} is (e.g. an LQR catch)." if seen else ".")
    )


def warn_data_coverage(trajs, system: str | SystemSpec, *, stacklevel: int = 2) -> dict:
    """:func:`check_data_coverage`, and one :class:`DataCoverageWarning` if an equilibrium is never visited."""
    result = check_data_coverage(trajs, system)
    message = coverage_message(result)
    if message is not None:
        warnings.warn(message, DataCoverageWarning, stacklevel=stacklevel + 1)
    return result
