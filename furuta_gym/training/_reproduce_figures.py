"""Figures of a reproduction run, like the paper's (private helper of :mod:`.reproduce`).

* ``predictions_<system>.png`` — open-loop predictions on the first 10 s of the first forced test
  trajectory (N-MSD: square pulse; Furuta: chirp), every model beside the ground truth.
* ``energy_state_<system>.png`` — energy as a function of the state (V(q_rest) = 0): N-MSD over p
  (ṗ = 0) and ṗ (p = 0); Furuta over β (α = α̇ = β̇ = 0) and β̇ (α = β = α̇ = 0).
* ``energy_time_<system>.png`` — E(t)/E(0) along the first test trajectory.
* ``forces_<system>.png`` — inertial, Coriolis and potential-derived forces along the first 10 s of
  a forced test trajectory, per joint, with the ground-truth accelerations.

Models are those of the first seed; APHYNITY's physics is its prior (N/A in the tables), so it is
drawn in the prediction figure only.
"""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..models import model_kind, system_definition
from ._labels import LOSS_LABELS, MODEL_LABELS, TEST_SETS
from .checkpoint import load_model
from .datagen import system_data
from .metrics import _terms_along, _true_accelerations, energy_along, predict


def _load_models(out: Path, system: str, config) -> list[tuple[str, str, object]]:
    seed = config.seeds[0]
    models = []
    for kind, loss in config.pairs:
        path = out / "runs" / system / f"{kind}_{loss}" / f"seed{seed}" / "model.eqx"
        if path.exists():
            models.append((kind, loss, load_model(path, expected_system=system)))
    return models


def _label(kind, loss) -> str:
    return f"{MODEL_LABELS[kind]} ({LOSS_LABELS[loss]})"


def make_figures(out: Path, config, per_system: dict) -> dict[str, Path]:
    """The four figures of each system (module docstring) into ``out/figures``; returns their paths."""
    import matplotlib  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    matplotlib.use("Agg")
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    for system in config.systems:
        data, truth = per_system[system]["data"], per_system[system]["truth"]
        models = _load_models(out, system, config)
        physics = [(kind, loss, m) for kind, loss, m in models if not model_kind(kind).analytic_prior]
        tr = data[system_data(system).forced_set][0]
        k = min(len(tr), int(round(10.0 / tr.dt)) + 1)  # the first 10 s
        figures = {
            "predictions": _predictions(system, data, truth, models, tr, k),
            "energy_state": _energy_over_state(system, truth, physics),
            "energy_time": _energy_over_time(system, data, truth, physics),
            "forces": _forces(system, truth, physics, tr, k),
        }
        for name, fig in figures.items():
            paths[f"{name}_{system}"] = _save(fig, fig_dir / f"{name}_{system}.png")
    return paths


def _predictions(system, data, truth, models, tr, k):
    """Open-loop predictions on the first ``k`` samples of the first forced trajectory."""
    import matplotlib.pyplot as plt  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    n = truth.spec.n_dof
    fig, axes = plt.subplots(2 * n, 1, figsize=(8, 2.0 * 2 * n), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for j in range(2 * n):
        axes[j].plot(tr.t[:k], tr.x[:k, j], "k", lw=2, label="ground truth")
        axes[j].set_ylabel(system_data(system).state_labels[j])
    for kind, loss, model in models:
        # the whole set, as in the evaluation: same shapes, so the compiled solve is reused
        pred = predict(model, data[system_data(system).forced_set])[0]
        for j in range(2 * n):
            y = np.where(np.abs(pred[:k, j]) < 1e6, pred[:k, j], np.nan)
            axes[j].plot(tr.t[:k], y, lw=1, label=_label(kind, loss))
    axes[0].legend(fontsize=7, ncol=2)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"{system}: open-loop predictions, first 10 s of a forced test trajectory")
    fig.tight_layout()
    return fig


def _energy_cases(system):
    """(x axis, q, q̇, label) of the two energy-over-state panels: one state variable on a grid,
    the others zero."""
    definition = system_definition(system)
    n = definition.spec.n_dof
    cases = []
    for index, low, high, factor, label in definition.energy_panels:
        grid = np.linspace(low, high, 201) * factor
        state = np.zeros((len(grid), 2 * n))
        state[:, index] = grid
        cases.append((grid, state[:, :n], state[:, n:], label))
    return cases


def _energy_over_state(system, truth, physics):
    import matplotlib.pyplot as plt  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, (x, q, qd, xlabel) in zip(axes, _energy_cases(system), strict=True):
        ax.plot(x, energy_along(truth, q, qd, normalize=False), "k", lw=2, label="ground truth")
        for kind, loss, model in physics:
            ax.plot(x, energy_along(model, q, qd, normalize=False), lw=1, label=_label(kind, loss))
        ax.set_xlabel(xlabel)
        ax.set_ylabel("E [J] (V(q_rest) = 0)")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{system}: energy as a function of the state")
    fig.tight_layout()
    return fig


def _energy_over_time(system, data, truth, physics):
    import matplotlib.pyplot as plt  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    tr_e = data[system_data(system).energy_set][0]
    fig, ax = plt.subplots(figsize=(7, 3.4))
    ax.plot(tr_e.t, energy_along(truth, tr_e.q, tr_e.qd), "k", lw=2, label="ground truth")
    for kind, loss, model in physics:
        ax.plot(tr_e.t, energy_along(model, tr_e.q, tr_e.qd), lw=1, label=_label(kind, loss))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("E(t) / E(0)")
    ax.legend(fontsize=7)
    label = next(l for l, name in TEST_SETS[system].items() if name == system_data(system).energy_set)
    ax.set_title(f"{system}: energy along the first {label} test trajectory")
    fig.tight_layout()
    return fig


def _forces(system, truth, physics, tr, k):
    """Inertial, Coriolis and potential forces per joint along the first ``k`` samples of ``tr``."""
    import matplotlib.pyplot as plt  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    n = truth.spec.n_dof
    q, qd = jnp.asarray(tr.q[:k]), jnp.asarray(tr.qd[:k])
    u = jnp.asarray(np.asarray(tr.u[:k], dtype=float).reshape(k, -1))
    qdd = _true_accelerations(truth, q, qd, u)
    names = ("inertial", "coriolis", "potential")
    fig, axes = plt.subplots(n, 3, figsize=(12, 2.6 * n), sharex=True, squeeze=False)
    true_terms = _terms_along(truth, q, qd, qdd)
    model_terms = [(kind, loss, _terms_along(m, q, qd, qdd)) for kind, loss, m in physics]
    for j in range(n):
        for c, name in enumerate(names):
            ax = axes[j, c]
            ax.plot(tr.t[:k], np.asarray(getattr(true_terms, name))[:, j], "k", lw=2, label="ground truth")
            for kind, loss, tt in model_terms:
                ax.plot(tr.t[:k], np.asarray(getattr(tt, name))[:, j], lw=1, label=_label(kind, loss))
            ax.set_title(f"{name} · {truth.spec.joint_names[j]}", fontsize=9)
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(f"{system}: force decomposition on a forced test trajectory (first 10 s)")
    fig.tight_layout()
    return fig


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt  # noqa: PLC0415  matplotlib loads only when a figure is drawn

    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
