"""Which model predicts the real QUBE-Servo best? Fit or train on runs 1–5, score on runs 6–15.

The 15 MIT-licensed closed-loop runs shipped in ``furuta_gym.datasets`` (upright balancing,
500 Hz, no velocities logged). Everything that is fitted or chosen sees runs 1–5 only:

* **nominal**: the analytic model with the datasheet parameters (``furuta_gym.models.Furuta``).
* **fitted analytic** / **diagnosed**: ``diagnose`` on runs 1–5 (its documented recipe for these
  logs: 0.1 s windows, 64 output-error windows) — the declared model's fitted parameters, and
  that model plus the effects it found (``model_after``; input dynamics, which have no
  memoryless Lagrangian form, are left out and said so).
* **DeLaN / augmented DeLaN** with L_prop and with their baselines (L_traj / L_aph): the
  reproduction's recipe for each model (``furuta_gym.training.reproduce.training_settings``: stage
  structure, learning rates, λ, μ, quadrature), its epochs cut to a training budget of about
  ten minutes per model on this machine (:data:`SCHEDULES`), and the long horizon 0.1 s instead
  of 1 s (an open-loop second of an upright pendulum diverges whatever the model). Trained on
  1 s elementary trajectories of runs 1–5 (the paper's split), every 5th held out; the snapshot
  kept is the one with the lowest mean validation error on that held-out fifth.

Scored on runs 6–15 in back-to-back 0.1 s open-loop windows started from the measured state
(measured angles, zero-phase velocities), the logged voltage held over each 2 ms period: per
state log10 RMSE (the paper's metric) and RMSE in rad, rad/s. The energy figure shows E(t) along
a test run as each model sees it, and the potential each model believes in (the paper shows only
the energy's shape for its experimental system). Writes ``results/real_models/*.json`` and
``energy.png``; ``studies/real_models_table.py`` puts the table into docs/learning.md.

One more L_prop row continues DeLaN's "L_Iτ over 0.1 s" run with L_prop's trajectory stages at
its baseline's budget and learning rate (:data:`FINETUNE`), λ chosen on the same validation fifth.
``--fit-runs``/``--test-runs`` take another split (runs 1–10 / 11–15: results/real_models_1to10).

    python studies/real_models.py [--out results/real_models] [--budget 1.0] [--fit-runs 1-5 --test-runs 6-15]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import shlex
import shutil
import sys
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.datasets import load_qube_closed_loop  # noqa: E402
from furuta_gym.measured import prepare_log, window_errors  # noqa: E402

FIT_RUNS, TEST_RUNS = list(range(1, 6)), list(range(6, 16))
SKIP, SPLIT, WINDOW, VALIDATION_EVERY = 0.5, 1.0, 0.1, 5
#: Epochs per stage, cut from the reproduction's recipe (L_prop: L_Iτ alone, 2-step, long horizon
#: — recipe 12 000 / 24 000, 20, 60; baselines: 2-step, long horizon — recipe 60, 200) to about
#: ten minutes of training each, from per-epoch costs measured here on runs 1–5's 76 training
#: trajectories (500 Hz) with other jobs on both cores: an L_Iτ epoch 0.13 s (Simpson) / 0.37 s
#: (augmented DeLaN's Hermite rule); a 2-step epoch (147 minibatches) ~16 s, ~40 s (DeLaN
#: L_prop) and ~80 s (augmented DeLaN L_prop: the full L_Iτ goes into every step); a 0.1 s epoch
#: (133 minibatches) ~50 s, ~60 s and ~110 s. L_prop's trajectory stages keep one epoch each.
SCHEDULES = {
    ("dln", "prop"): (4000, 1, 1),
    ("dln", "traj"): (10, 8),
    ("adln", "prop"): (1000, 1, 1),
    ("adln", "aph"): (10, 8),
}
#: L_Iτ over 0.1 s (25 Simpson intervals at 500 Hz) instead of the paper's one interval, chosen on
#: the simulated ablation (studies/lprop_closed_loop_ablation.py, cells g/h): per interval the
#: encoder's counts, through the estimated velocities, all but hide gravity from the loss
SPAN = 25
#: learned models: name -> (kind, loss, TrainSettings changes to the recipe)
LEARNED = {
    "dln_prop": ("dln", "prop", {}),
    "dln_traj": ("dln", "traj", {}),
    "adln_prop": ("adln", "prop", {}),
    "adln_aph": ("adln", "aph", {}),
    "dln_prop_span": ("dln", "prop", {"integral_span": SPAN}),
    "adln_prop_span": ("adln", "prop", {"integral_span": SPAN}),
}
#: L_prop's trajectory stages at its baseline's budget and learning rate (10 2-step epochs, 8 of
#: 0.1 s, lr 1e-3), continued from the "L_Iτ over 0.1 s" model of the same kind: that run had one
#: epoch per trajectory stage at the recipe's fine-tuning rate, so the snapshot it kept was from its
#: L_Iτ stage. λ of L_traj in L_prop = L_Iτ + λ·L_traj from :data:`FINETUNE_LAMBDAS` (the recipe's
#: first), chosen with the snapshot on the validation fifth. name -> (model it continues, epochs)
FINETUNE = {"dln_prop_span_traj": ("dln_prop_span", (10, 8))}
FINETUNE_LAMBDAS = (1e-3, 0.1, 1.0)
FINETUNE_RATE = 1e-3  # the baselines' (the reproduction's L_traj / L_aph recipe)
LABELS = {
    "nominal": "nominal analytic",
    "fitted": "fitted analytic (diagnose, no effect)",
    "diagnosed": "diagnosed (fitted + found effects)",
    "dln_prop": "DeLaN L_prop",
    "dln_traj": "DeLaN L_traj",
    "adln_prop": "augmented DeLaN L_prop",
    "adln_aph": "augmented DeLaN L_aph",
    "dln_prop_span": "DeLaN L_prop, L_Iτ over 0.1 s",
    "adln_prop_span": "augmented DeLaN L_prop, L_Iτ over 0.1 s",
    "dln_prop_span_traj": "DeLaN L_prop, L_Iτ over 0.1 s + trajectory stages",
}
ENERGY_RUN = 6  # the energy figure's test run (with --test-runs: the first of them)


def load_data():
    """Training / validation elementary trajectories of the fit runs, whole test runs."""
    pieces = [
        p
        for tr in load_qube_closed_loop(FIT_RUNS, skip_seconds=0.0)
        for p in prepare_log(tr, tr.name, skip=SKIP, split=SPLIT)
    ]
    train = [p for i, p in enumerate(pieces) if i % VALIDATION_EVERY != VALIDATION_EVERY - 1]
    val = [p for i, p in enumerate(pieces) if i % VALIDATION_EVERY == VALIDATION_EVERY - 1]
    test = [
        p
        for tr in load_qube_closed_loop(TEST_RUNS, skip_seconds=0.0)
        for p in prepare_log(tr, tr.name, skip=SKIP, split=None, min_seconds=WINDOW)
    ]
    return train, val, test


def recipe_config(kind: str, loss: str, budget: float, **changes):
    """The reproduction's TrainSettings for (kind, loss), epochs cut to :data:`SCHEDULES` × budget
    and the long horizon to :data:`WINDOW`, with ``changes``."""
    from furuta_gym.training.reproduce import ReproduceSettings, training_settings

    base = training_settings("furuta", ReproduceSettings(progress=False), 0, loss, kind)
    epochs = tuple(max(1, round(e * budget)) for e in SCHEDULES[(kind, loss)])
    horizons = tuple(WINDOW if isinstance(h, float) else h for h in base.horizons)
    # snapshots for the validation choice: a dozen over the run, each trajectory epoch of the
    # baselines (an epoch is over a hundred minibatches there)
    every = max(1, sum(epochs) // 12) if loss == "prop" else 1
    return dataclasses.replace(base, epochs=epochs, horizons=horizons, checkpoint_every=every, **changes)


def _validation_score(model, val) -> float:
    """Mean log10 RMSE of the four states on the validation windows (diverged: +inf)."""
    cells = window_errors(model, val, WINDOW)["log10_rmse"].values()
    return float("inf") if any(isinstance(v, str) for v in cells) else float(np.mean(list(cells)))


SELECTED = "selected.eqx"  # the snapshot chosen on validation, what the table scores


def train_learned(name: str, train, val, out: Path, budget: float):
    """Train :data:`LEARNED` ``name`` (or reuse a finished run in ``out``), keep the snapshot
    best on validation."""
    from furuta_gym.training.checkpoint import load_model
    from furuta_gym.training.train import train as train_model

    kind, loss, changes = LEARNED[name]
    config = recipe_config(kind, loss, budget, **changes)
    t0 = time.time()
    # resume: a finished run with these settings is reused; other settings are refused by name
    _, history = train_model(kind, "furuta", loss, train, config, out, resume=True)
    seconds = sum(r["seconds"] for r in history)
    scores = _snapshot_scores(out, val)
    best = min(scores, key=scores.get)
    # the scored model is committed as selected.eqx (the snapshots are not)
    shutil.copyfile(out / best, out / SELECTED)
    info = {
        "config": config.to_json(),
        "training_seconds": round(seconds, 1),
        "wall_seconds_this_call": round(time.time() - t0, 1),
        "validation": scores,
        "selected": best,
        "final": {k: history[-1].get(k) for k in ("itau", "traj", "penalty", "lambda")},
    }
    return load_model(out / best, expected_system="furuta"), info


def _snapshot_scores(run: Path, val) -> dict[str, float]:
    """Validation score of every snapshot a run kept, and of its final model."""
    from furuta_gym.training.checkpoint import load_model

    snaps = sorted(run.glob("model_epoch*.eqx")) + [run / "model.eqx"]
    return {p.name: _validation_score(load_model(p, expected_system="furuta"), val) for p in snaps}


def finetune_learned(name: str, train, val, out: Path, budget: float):
    """:data:`FINETUNE` ``name``: L_prop's trajectory stages from the selected model of the run it
    continues, once per λ (finished runs reused); keeps the (λ, snapshot) best on validation."""
    from furuta_gym.training.checkpoint import load_model
    from furuta_gym.training.train import train as train_model

    start_name, epochs = FINETUNE[name]
    kind, loss, changes = LEARNED[start_name]
    start = load_model(out.parent / start_name / SELECTED, expected_system="furuta")
    base = recipe_config(kind, loss, budget, **changes)
    runs, seconds = {}, 0.0
    for lam in FINETUNE_LAMBDAS:
        config = dataclasses.replace(
            base,
            epochs=tuple(max(1, round(e * budget)) for e in epochs),
            horizons=(2, WINDOW),
            learning_rate=FINETUNE_RATE,
            lambda_traj=lam,
            checkpoint_every=1,
        )
        run = out / f"lambda_{lam:g}"
        _, history = train_model(kind, "furuta", loss, train, config, run, resume=True, model=start)
        seconds += sum(r["seconds"] for r in history)
        runs[f"lambda_{lam:g}"] = {"config": config.to_json(), "validation": _snapshot_scores(run, val)}
    scores = {f"{r}/{snap}": v for r in runs for snap, v in runs[r]["validation"].items()}
    best = min(scores, key=scores.get)
    best_run = best.split("/")[0]
    shutil.copyfile(out / best, out / SELECTED)
    info = {
        "continues": start_name,
        "config": runs[best_run]["config"],
        "training_seconds": round(seconds, 1),
        "validation": scores,
        "selected": best,
        "last": f"{best_run}/model.eqx",
        "lambda_candidates": list(FINETUNE_LAMBDAS),
    }
    return load_model(out / SELECTED, expected_system="furuta"), info


def diagnosed_models(out: Path):
    """The fitted declared model and the diagnosed one (``diagnose`` on the fit runs)."""
    from furuta_gym.diagnose import diagnose

    t0 = time.time()
    res = diagnose(load_qube_closed_loop(FIT_RUNS, skip_seconds=SKIP), "furuta", window=WINDOW, oe_max_windows=64)
    doc = res.to_json()
    doc["seconds"] = round(time.time() - t0, 1)
    (out / "diagnose.json").write_text(json.dumps(doc, indent=1) + "\n")
    found = [f"{e.name}:{e.joint}" for e in res.found]
    note = "effects added: " + (", ".join(found) or "none")
    if res.input_dynamics.kind != "none":  # a delay / lag has a state: no Lagrangian form
        note += f"; found {res.input_dynamics.kind} ({res.input_dynamics.seconds:.4g} s) left out of the model"
    info = {"effects": found, "note": note, "seconds": doc["seconds"]}
    return {"fitted": res.model_before, "diagnosed": res.model_after}, info


def energy_figure(models: dict, test, path: Path) -> None:
    """E(t) along a test run as each model sees it, and each model's potential V(β) at α = 0."""
    import jax
    import jax.numpy as jnp
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from furuta_gym.training.metrics import energy_along

    run = next(tr for tr in test if tr.name == f"run{ENERGY_RUN:02d}")
    t, q, qd = run.t - run.t[0], run.q, run.qd
    beta = np.linspace(-np.pi, np.pi, 361)
    grid = jnp.stack([jnp.zeros_like(beta), jnp.asarray(beta)], axis=1)
    fig, (ax_e, ax_v) = plt.subplots(1, 2, figsize=(12, 4.8), gridspec_kw={"width_ratios": [2, 1]})
    for name, model in models.items():
        e = energy_along(model, q, qd, normalize=False)  # V(q = 0) = 0: hanging pendulum at rest
        v = np.asarray(jax.vmap(model.potential)(grid) - model.potential(jnp.zeros(2)))
        style = "--" if name in ("nominal", "fitted", "diagnosed") else "-"
        ax_e.plot(t, e * 1e3, style, lw=1.0, label=LABELS[name])
        ax_v.plot(beta, v * 1e3, style, lw=1.0, label=LABELS[name])
    ax_e.set(
        xlabel=f"time in run {ENERGY_RUN} (s, after the skipped start)",
        ylabel="E (mJ), V(0) = 0",
        title="energy along a test run (measured states) as each model sees it",
    )
    ax_v.set(xlabel="β (rad), α = 0", ylabel="V (mJ)", title="potential each model believes in")
    handles, labels = ax_e.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def potential_shape(model) -> dict:
    """What the model believes about gravity, at α = 0: the potential's rise from hanging (β = 0)
    to upright (β = π), and its curvature at the top (physically ½mp·g·Lp·(1 − cos β): a rise of
    mp·g·Lp and a curvature of −½mp·g·Lp, the top an unstable maximum). The logs stay near the top."""
    import jax
    import jax.numpy as jnp

    v = lambda b: model.potential(jnp.stack([jnp.zeros(()), b]))  # noqa: E731
    top = jnp.asarray(np.pi)
    return {
        "rise_to_top_J": float(v(top) - v(jnp.zeros(()))),
        "curvature_at_top_Nm_per_rad": float(jax.grad(jax.grad(v))(top)),
    }


def score(name: str, model, val, test, out: Path, extra: dict) -> dict:
    """Test (and validation) window errors of one model, written to ``out/<name>.json``."""
    doc = {
        "name": name,
        "label": LABELS[name],
        "test": window_errors(model, test, WINDOW),
        "validation": window_errors(model, val, WINDOW),
        "potential": potential_shape(model),
        **extra,
    }
    (out / f"{name}.json").write_text(json.dumps(doc, indent=1, default=str) + "\n")
    cells = "  ".join(f"{k}={v if isinstance(v, str) else round(v, 3)}" for k, v in doc["test"]["log10_rmse"].items())
    print(f"{LABELS[name]:40s} {cells}", flush=True)
    return doc


def _run_range(text: str) -> list[int]:
    """'1-10' -> [1, ..., 10]; '2,7' -> [2, 7]."""
    first, _, last = text.partition("-")
    return list(range(int(first), int(last) + 1)) if last else [int(r) for r in text.split(",")]


def _use_runs(ap, fit: list[int], test: list[int]) -> None:
    """Fit and test on these runs (another split than the default 1–5 / 6–15)."""
    global FIT_RUNS, TEST_RUNS, ENERGY_RUN
    if set(fit) & set(test):
        ap.error(
            f"--fit-runs and --test-runs share runs {sorted(set(fit) & set(test))}: the test runs are never fitted"
        )
    FIT_RUNS, TEST_RUNS, ENERGY_RUN = fit, test, test[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/real_models")
    ap.add_argument("--budget", type=float, default=1.0, help="scale of every schedule's epochs")
    ap.add_argument(
        "--learned",
        default=",".join([*LEARNED, *FINETUNE]),
        help="comma list of learned models to train and score (the others' result files are kept); "
        "'' reruns only the nominal, fitted and diagnosed rows",
    )
    ap.add_argument("--fit-runs", type=_run_range, default=FIT_RUNS, help="runs to fit on, e.g. 1-10 (default 1-5)")
    ap.add_argument("--test-runs", type=_run_range, default=TEST_RUNS, help="runs to score on (default 6-15)")
    args = ap.parse_args()
    _use_runs(ap, args.fit_runs, args.test_runs)
    names = [n for n in args.learned.split(",") if n]  # --learned "": only the declared-model rows
    if unknown := [n for n in names if n not in LEARNED and n not in FINETUNE]:
        ap.error(f"--learned: unknown {unknown}; expected some of {[*LEARNED, *FINETUNE]}")
    from furuta_gym.models import Furuta

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    train, val, test = load_data()
    t0 = time.time()
    models = {"nominal": Furuta()}
    extra = {"nominal": {}}
    fitted, dinfo = diagnosed_models(out)
    models.update(fitted)
    extra.update({"fitted": {"diagnose": dinfo}, "diagnosed": {"diagnose": dinfo}})
    for name in ("nominal", "fitted", "diagnosed"):
        score(name, models[name], val, test, out, extra[name])
    for name in [*LEARNED, *FINETUNE]:
        if name in names:
            learn = finetune_learned if name in FINETUNE else train_learned
            models[name], info = learn(name, train, val, out / "runs" / name, args.budget)
            score(name, models[name], val, test, out, {"training": info})
        elif (out / "runs" / name / SELECTED).is_file():  # kept from an earlier call, for the figure
            from furuta_gym.training.checkpoint import load_model

            models[name] = load_model(out / "runs" / name / SELECTED, expected_system="furuta")
    energy_figure(models, test, out / "energy.png")
    summary = {
        "command": shlex.join(["python", "studies/real_models.py", *sys.argv[1:]]),
        "fit_runs": FIT_RUNS,
        "test_runs": TEST_RUNS,
        "skip_seconds": SKIP,
        "split_seconds": SPLIT,
        "window_seconds": WINDOW,
        "validation_every": VALIDATION_EVERY,
        "velocity": "zero_phase",
        "input": "held over each sample period (RK4, 4 substeps)",
        "budget": args.budget,
        "n_train": len(train),
        "n_validation": len(val),
        "models": list(models),
        "seconds": round(time.time() - t0, 1),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": f"{platform.node()} {platform.processor() or platform.machine()}",
    }
    if not names and (out / "summary.json").is_file():
        # only the declared-model rows were rerun: the summary keeps the training run's command and
        # date, and records this rerun beside them
        kept = json.loads((out / "summary.json").read_text())
        kept["declared_rerun"] = {k: summary[k] for k in ("command", "date", "machine")}
        summary = kept
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(f"wrote {out}/*.json and {out}/energy.png")


if __name__ == "__main__":
    main()
