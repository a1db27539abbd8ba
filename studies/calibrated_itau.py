"""Why DeLaN L_prop does not train on the calibrated rig's experimental data: its L_Iτ stage alone.

The calibrated-rig protocol (``studies/calibrated_protocol.py``) left DeLaN L_prop with a mass
matrix ~3000x too small and free dynamics ~3000x stiffer than the plant's after its L_Iτ stage.
This script separates the candidate causes on the same plant, the same 64 free releases and the
same seed, training the L_Iτ stage of the frozen recipe alone:

* the sensor: exact states (the paper's simulated data) or the QUBE's (2048-count encoders and
  the paper's derivative filter for velocities, its experiments);
* the velocities: the sensor's (the derivative filter lags by 2ξ/ω0 = 16 ms) or re-estimated
  offline from the angles without lag;
* the residual's span: the paper's intervals (1) or sums over 10 of them (``integral_span``: 10
  Simpson intervals of two samples, 0.2 s at 100 Hz; the fix that gave the real closed-loop runs
  a physical potential, there over 0.1 s, docs/learning.md).

Per cell: the mass matrix at rest, the free dynamics' stiffness (largest |eigenvalue| of the state
Jacobian at 20 random states, 1/s) beside the plant's, the potential's shape, and the loss of the
learned model beside the plant's own on the training data (learned / plant < 1: the loss prefers
the learned model, so more training cannot help). The recipe's own run (experiment sensor, span 1)
is read from the calibrated protocol's training state. Writes
``results/calibrated_protocol/itau_causes.json``.

    python studies/calibrated_itau.py [--epochs 12000] [--cell experiment:10:zero_phase ...]
    python studies/calibrated_itau.py --scale-fit-only
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibrated_protocol import OUT, PLANT, shape  # noqa: E402

RESULT = OUT / "itau_causes.json"
#: Simpson intervals (two samples each) summed into one residual: 0.2 s at the experiments' 100 Hz
SPAN_SAMPLES = 10
CELLS = (
    "exact:1:recorded",
    "experiment:1:recorded",
    f"experiment:{SPAN_SAMPLES}:recorded",
    "experiment:1:zero_phase",
    f"experiment:{SPAN_SAMPLES}:zero_phase",
)


def _config(sensor: str):
    from furuta_gym.training.reproduce import ReproduceSettings

    return ReproduceSettings(plant=str(PLANT), sensor=sensor, systems=("furuta",))


def _data(sensor: str):
    """The protocol's training releases with ``sensor``, generated afresh on the plant (the
    protocol's committed manifest records data this code does not regenerate bit for bit)."""
    from furuta_gym.envs import Plant
    from furuta_gym.training.datagen import MujocoGroundTruth, generate_datasets
    from furuta_gym.training.reproduce import SENSORS

    config = _config(sensor)
    return generate_datasets(
        "furuta",
        seed=config.data_seed,
        small=config.small,
        sensor=SENSORS[sensor],
        ground_truth=MujocoGroundTruth("furuta", plant=Plant.load(PLANT)),
    )


def _train_config(sensor: str, span: int, epochs: int):
    from furuta_gym.training.reproduce import training_settings

    recipe = training_settings("furuta", _config(sensor), 0, "prop", "dln")
    rate = recipe.learning_rate[0] if isinstance(recipe.learning_rate, tuple) else recipe.learning_rate
    return dataclasses.replace(
        recipe, epochs=(epochs,), horizons=(None,), learning_rate=rate, integral_span=span, progress=False
    )


def _stiffness(model, states) -> list[float]:
    import jax
    import jax.numpy as jnp

    from furuta_gym.lagrangian import forward_dynamics

    field = lambda x: jnp.concatenate([x[2:], forward_dynamics(model, x[:2], x[2:], jnp.zeros(1))])  # noqa: E731
    return [float(np.max(np.abs(np.linalg.eigvals(np.asarray(jax.jacfwd(field)(jnp.asarray(x))))))) for x in states]


def _itau(model, trajs, tcfg) -> float:
    from furuta_gym.training.losses import integral_loss, make_windows

    w = min(tcfg.integral_window, min(len(t) for t in trajs))
    w -= tcfg.quadrature == "simpson" and w % 2 == 0
    windows = make_windows(trajs, w, stride=w - 1, cover_end=True)
    return float(integral_loss(model, windows, rule=tcfg.quadrature, normalize=tcfg.normalize, span=tcfg.integral_span))


def measure(model, plant, trajs, tcfg) -> dict:
    """What the L_Iτ stage left, beside the plant."""
    import jax.numpy as jnp

    states = np.random.default_rng(0).uniform([-3, -3, -5, -5], [3, 3, 5, 5], (20, 4))
    mass = np.asarray(model.mass_matrix(jnp.zeros(2)))
    learned, truth = _itau(model, trajs, tcfg), _itau(plant, trajs, tcfg)
    return {
        "mass_matrix_at_rest": mass.tolist(),
        "plant_mass_matrix_at_rest": np.asarray(plant.mass_matrix(jnp.zeros(2))).tolist(),
        "stiffness_median": float(np.median(_stiffness(model, states))),
        "plant_stiffness_median": float(np.median(_stiffness(plant, states))),
        "shape": shape(model),
        "itau_learned": learned,
        "itau_plant": truth,
        "itau_learned_over_plant": learned / truth,
    }


def _velocities(trajs, velocity: str):
    """``trajs`` with the sensor's velocities (``"recorded"``) or re-estimated offline from the
    angles without lag (``"zero_phase"``: :func:`~furuta_gym.signals.zero_phase_velocity` at its
    default cutoff, 20 Hz at 100 Hz)."""
    from furuta_gym.signals import zero_phase_velocity

    if velocity == "recorded":
        return trajs
    if velocity != "zero_phase":
        raise ValueError(f"velocity: expected 'recorded' or 'zero_phase', got {velocity!r}")
    return [dataclasses.replace(t, qd=zero_phase_velocity(np.asarray(t.q), t.dt)) for t in trajs]


def plant_losses() -> dict:
    """The plant's own L_Iτ on its training releases, per sensor, velocity estimate and span: how
    far from zero the loss of the right answer is (exact states: quadrature error only)."""
    from furuta_gym.training.reproduce import truth_model

    plant = truth_model("furuta", _config("exact"))
    exact, measured = _data("exact")["train"], _data("experiment")["train"]
    variants = {
        "exact states": exact,
        "encoder angles, exact velocities": [
            dataclasses.replace(m, qd=e.qd) for m, e in zip(measured, exact, strict=True)
        ],
        "encoder angles, derivative filter": measured,
        "encoder angles, zero-phase": _velocities(measured, "zero_phase"),
    }
    return {
        f"{name}, span {span}": _itau(plant, trajs, _train_config("exact", span, 1))
        for span in (1, SPAN_SAMPLES)
        for name, trajs in variants.items()
    }


def scale_fit_check() -> dict:
    """The recipe's scale fit (one 20 s forced run, the 2 V chirp) on this rig: how far its rotor
    travels beside the training releases, the scale the plant's own model gets there (1 is right)
    per velocity estimate and span, and the fits the retrained L_prop checkpoints record."""
    import jax.numpy as jnp

    from furuta_gym.lagrangian import integral_terms
    from furuta_gym.training import fit_scale
    from furuta_gym.training.checkpoint import load_model, read_header
    from furuta_gym.training.losses import span_sum
    from furuta_gym.training.reproduce import truth_model

    data = _data("experiment")
    forced, plant = data["scale_fit"][0], truth_model("furuta", _config("experiment"))
    fits = {}
    for velocity in ("recorded", "zero_phase"):
        run = _velocities([forced], velocity)[0]
        terms = integral_terms(
            plant, jnp.asarray(run.q), jnp.asarray(run.qd), jnp.asarray(run.u).reshape(-1, 1), run.dt, "simpson"
        )
        for span in (1, SPAN_SAMPLES):
            a, z = (np.asarray(span_sum(x, span)).ravel() for x in (terms.A, terms.Z))
            scale = float(z @ a / (a @ a))
            fits[f"{velocity}, span {span}"] = {
                "factor": scale,
                "relative_residual": float(np.linalg.norm(z - scale * a) / np.linalg.norm(z)),
            }
    recorded, in_range = {}, {}
    reach = float(max(np.max(np.abs(t.q[:, 0])) for t in data["train"]))
    offline = _velocities([forced], "zero_phase")[0]
    outside = np.flatnonzero(np.abs(np.asarray(forced.q)[:, 0]) > reach)
    stay = int(outside[0]) if len(outside) else len(forced.t)
    prefix = dataclasses.replace(
        offline,
        t=offline.t[:stay],
        q=np.asarray(offline.q)[:stay],
        u=np.asarray(offline.u)[:stay],
        qd=np.asarray(offline.qd)[:stay],
    )
    for folder in ("reproduce", "reproduce_span", "reproduce_offline", "reproduce_spring"):
        for path in sorted((OUT / folder / "runs" / "furuta").glob("*_prop/seed0/model.eqx")):
            recorded[f"{folder}/{path.parts[-3]}"] = read_header(path)["meta"].get("scale_fit")
            if folder in ("reproduce_offline", "reproduce_spring"):  # the same fit inside the training range
                model = load_model(path, expected_system="furuta")
                in_range[f"{folder}/{path.parts[-3]}"] = fit_scale(model, [prefix], "simpson", SPAN_SAMPLES)[
                    1
                ].to_json()
    return {
        "rotor_travel_rad": float(np.ptp(forced.q[:, 0])),
        "training_max_abs_alpha_rad": reach,
        "scale_fit_max_abs_alpha_rad": float(np.max(np.abs(forced.q[:, 0]))),
        "seconds_inside_training_range": stay * forced.dt,
        "plant_fits": fits,
        "recorded_fits": recorded,
        "in_range_fits": in_range,
    }


def run_cell(sensor: str, span: int, velocity: str, epochs: int) -> dict:
    from furuta_gym.training import train
    from furuta_gym.training.reproduce import truth_model

    data = {"train": _velocities(_data(sensor)["train"], velocity)}
    tcfg = _train_config(sensor, span, epochs)
    plant = truth_model("furuta", _config(sensor))
    t0 = time.perf_counter()
    model, _ = train("dln", "furuta", "prop", data["train"], tcfg, hparams=_config(sensor).model_overrides)
    return {
        "sensor": sensor,
        "span": span,
        "velocity": velocity,
        "epochs": epochs,
        "seconds": round(time.perf_counter() - t0, 1),
        **measure(model, plant, data["train"], tcfg),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=12000)
    ap.add_argument(
        "--cell", nargs="+", default=list(CELLS), help="sensor:span:velocity cells to run (merged into the result file)"
    )
    ap.add_argument("--out", type=Path, default=RESULT, help="the result file (merged into if it exists)")
    ap.add_argument("--scale-fit-only", action="store_true", help="only the scale fit's check (no training)")
    args = ap.parse_args(argv)
    doc = json.loads(args.out.read_text()) if args.out.exists() else {"cells": {}}
    doc["scale_fit"] = scale_fit_check()
    print(json.dumps(doc["scale_fit"], indent=1), flush=True)
    if args.scale_fit_only:
        args.out.write_text(json.dumps(doc, indent=1) + "\n")
        return 0
    doc["plant_itau"] = plant_losses()
    print(json.dumps(doc["plant_itau"], indent=1), flush=True)
    for cell in args.cell:
        sensor, span, velocity = cell.split(":")
        doc["cells"][cell] = run_cell(sensor, int(span), velocity, args.epochs)
        print(cell, json.dumps({k: v for k, v in doc["cells"][cell].items() if "matrix" not in k}), flush=True)
        args.out.write_text(json.dumps(doc, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
