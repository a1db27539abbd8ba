"""Why did L_prop learn upright as a potential *minimum* on the real balancing logs? An ablation on
simulated closed-loop data, where the true potential is known (issue 44).

The shipped QUBE runs are upright balancing under a PD controller. This script simulates that
experiment (:func:`furuta_gym.rigs.measured_like`, ``excitation="closed_loop_prbs"``, 5 runs
of 20 s) on the MuJoCo plant with the effects the diagnosis finds on all 15 real runs, prepares
it as ``studies/real_models.py`` prepares the real runs (0.5 s skipped, 1 s elementary
trajectories, zero-phase velocity estimates on the whole log), trains DeLaN on the L_Iτ stage of
L_prop (the stage the real run's kept snapshot came from; the trajectory stages are left out to
keep each run to minutes), and measures the learned potential's curvature at β = π and its rise
from 0 to π (:func:`real_models.potential_shape`) at every snapshot, and the final model's
prediction score on two held-out runs of the same experiment (0.1 s open-loop windows, as the real
table). Whether the loss or the optimiser prefers the learned shape: L_Iτ of the learned model
against the truth's on the same training windows (:func:`itau_comparison`), and the gravity
scale the loss wants with everything else true (:func:`gravity_profile`). One factor is changed
per cell (:data:`CELLS`):

* ``baseline``: as above; its snapshot at :data:`SHORT` epochs is the short budget, its end
  (2 × that, the learning rate constant) the long one — cause (d);
* ``feedforward_x4``: the independent ±0.5 V feed-forward of the balancing loop × 4, so a
  smaller share of u is the feedback's function of the state — cause (a), closed-loop correlation;
* ``exact_velocity``: the simulator's velocities instead of estimates — cause (b);
* ``exact_angles``: ``quantize=False`` (no 2048-count encoder; velocities still estimated) — (c);
* ``no_effects``: the pinned plant without the undeclared effects — cause (e);
* ``physical_start``: the baseline started from a potential with the physical curvature
  (:func:`physical_start`): do the data pull the curvature to a minimum, or only fail to fix it?

The feed-forward scale and the exact velocities are the simulator's own options
(``excitation=ClosedLoopBalancing(feedforward=...)``, ``true_velocities=True``); a subclass of
the experiment keeps each run's feed-forward for its share of u. Each run (cell × seed; data
seed and model seed both vary) writes ``results/lprop_ablation/<cell>_s<seed>.json``;
``studies/lprop_ablation_table.py`` writes the table into docs/learning.md.

    python studies/lprop_closed_loop_ablation.py [--cells baseline,...] [--seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

from furuta_gym.data import Trajectory  # noqa: E402
from furuta_gym.effects import Effect  # noqa: E402
from furuta_gym.measured import prepare_log, window_errors  # noqa: E402
from furuta_gym.rigs import ClosedLoopBalancing, measured_like  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_models import SKIP, SPLIT, WINDOW, potential_shape  # noqa: E402

#: the effects ``diagnose`` finds on all 15 real runs (docs/diagnose.md)
REAL_EFFECTS = (
    Effect("coulomb_friction", "alpha", 5.4e-4),
    Effect("spring", "alpha", 8e-4),
    Effect("com_offset", "beta", -1.7e-3),
    Effect("input_delay", "u", 0.0016),
)
N_TRAIN, N_TEST, DURATION, TEST_DURATION = 5, 2, 20.0, 10.0
#: L_Iτ epochs of the short budget (about the real DeLaN run's kept snapshot, epoch 999) and
#: the long one's factor
SHORT, LONG_FACTOR = 1000, 2


@dataclasses.dataclass(frozen=True)
class Cell:
    """One factor setting of the simulated experiment and its training budget."""

    label: str
    feedforward: float = 1.0
    exact_velocity: bool = False
    quantize: bool = True
    effects: bool = True
    epochs: int = SHORT
    physical_start: bool = False
    integral_span: int = 1


CELLS = {
    "baseline": Cell(
        "as the real runs (closed loop, 2048 counts, estimated velocities, effects)", epochs=SHORT * LONG_FACTOR
    ),
    "feedforward_x4": Cell("(a) feed-forward × 4 (less of u is state feedback)", feedforward=4.0),
    "exact_velocity": Cell("(b) exact velocities", exact_velocity=True),
    "exact_angles": Cell("(c) exact angles (no encoder)", quantize=False),
    "no_effects": Cell("(e) no undeclared effects", effects=False),
    "physical_start": Cell("(f) as the baseline, started from a physical potential", physical_start=True),
    "span_5": Cell("(g) as the real runs, L_Iτ over 20 ms (5 Simpson intervals)", integral_span=5),
    "span_25": Cell("(h) as the real runs, L_Iτ over 100 ms (25 Simpson intervals)", integral_span=25),
}


def physical_start(seed: int):
    """The DeLaN training would start from (its seed's initialisation), with one path through the
    potential net added that gives V a physical gravity term, −2.05·tanh(tanh(cos β)) × the
    potential scale: ∂²V/∂β² ≈ ∓15 mN·m/rad at β = 0, π (the physics' ±15.2). The rest of the
    net keeps its random weights (their curvature adds a few mN·m/rad)."""
    import equinox as eqx
    import jax

    from furuta_gym.models import make_model

    model = make_model("furuta", "dln", jax.random.PRNGKey(seed))
    first, middle, last = model.lagrangian_nets.potential_net.layers
    cos_beta = 2  # features (cos α, sin α, cos β, sin β)
    w0 = first.weight.at[0].set(0.0).at[0, cos_beta].set(1.0)
    w1 = middle.weight.at[:, 0].set(0.0).at[0].set(0.0).at[0, 0].set(1.0)
    w2 = last.weight.at[0, 0].set(-2.05)
    new = (
        eqx.tree_at(lambda l: (l.weight, l.bias), first, (w0, first.bias.at[0].set(0.0))),
        eqx.tree_at(lambda l: (l.weight, l.bias), middle, (w1, middle.bias.at[0].set(0.0))),
        eqx.tree_at(lambda l: l.weight, last, w2),
    )
    return eqx.tree_at(lambda m: m.lagrangian_nets.potential_net.layers, model, new)


def start_model(cell: Cell, seed: int):
    """What training starts from: the seed's initialisation, or :func:`physical_start`."""
    import jax

    from furuta_gym.models import make_model

    return physical_start(seed) if cell.physical_start else make_model("furuta", "dln", jax.random.PRNGKey(seed))


@dataclasses.dataclass(frozen=True)
class _FeedRecorded(ClosedLoopBalancing):
    """The balancing experiment, keeping each run's feed-forward (for its share of u)."""

    feeds: list = dataclasses.field(default_factory=list, compare=False)

    def signals(self, n, dt, rng):
        rotor, pendulum, feed = super().signals(n, dt, rng)
        self.feeds.append(feed)
        return rotor, pendulum, feed


def simulate(cell: Cell, n: int, duration: float, seed: int) -> tuple[list[Trajectory], float]:
    """``n`` closed-loop balancing runs of the cell's experiment, as logged (exact velocities
    attached when the cell says so), and the rms of the independent feed-forward over the rms of
    u (the rest of u is the feedback's function of the measured state), after the skipped start."""
    experiment = _FeedRecorded(feedforward=ClosedLoopBalancing().feedforward * cell.feedforward)
    runs = measured_like(
        "furuta",
        REAL_EFFECTS if cell.effects else (),
        excitation=experiment,
        n_trajectories=n,
        duration=duration,
        seed=seed,
        quantize=cell.quantize,
        true_velocities=cell.exact_velocity,
    )
    start = int(round(SKIP / runs[0].dt))
    u = np.concatenate([np.asarray(tr.u)[start:, 0] for tr in runs])
    feed = np.concatenate([f[start:] for f in experiment.feeds])
    share = float(np.sqrt(np.mean(feed**2) / np.mean(u**2)))
    return runs, share


def _pieces(runs, split):
    return [p for tr in runs for p in prepare_log(tr, tr.name, skip=SKIP, split=split, min_seconds=WINDOW)]


def config_for(cell: Cell, seed: int):
    """The reproduction's DeLaN L_prop recipe (quadrature, L_Iτ learning rate), its L_Iτ stage only."""
    from furuta_gym.training.reproduce import ReproduceSettings, training_settings

    base = training_settings("furuta", ReproduceSettings(progress=False), seed, "prop", "dln")
    lr = base.learning_rate[0] if isinstance(base.learning_rate, tuple) else base.learning_rate
    # snapshots at multiples of SHORT / 4, so a long run has one at the short budget
    return dataclasses.replace(
        base,
        epochs=(cell.epochs,),
        horizons=(None,),
        learning_rate=lr,
        checkpoint_every=max(1, SHORT // 4),
        integral_span=cell.integral_span,
    )


def _mean_log10(errors: dict) -> float | None:
    cells = list(errors["log10_rmse"].values())
    return None if any(isinstance(v, str) for v in cells) else float(np.mean(cells))


def _truth(cell: Cell, gravity_scale: float = 1.0):
    """The plant as a Lagrangian model: the analytic Furuta (gravity scaled) with the cell's
    undeclared effects except the input delay, which has no memoryless form."""
    from furuta_gym.effects import WithEffects
    from furuta_gym.models import Furuta, FurutaParameters

    base = Furuta(FurutaParameters(g=gravity_scale * FurutaParameters().g))
    memoryless = [e for e in REAL_EFFECTS if e.name != "input_delay"] if cell.effects else []
    return WithEffects(base, memoryless, coulomb_smoothing=1e-3) if memoryless else base


def itau_comparison(model, train_pieces, rule: str, cell: Cell) -> dict:
    """L_Iτ (absolute: Σ‖Z̄ − Ā‖², N²·m²·s²) on the training windows as training tiles them, of
    the learned model and of the truth without its input delay (the analytic model with the
    plant's other effects): below the truth's, the loss prefers the learned potential."""
    from furuta_gym.models import Furuta
    from furuta_gym.training.losses import integral_loss, make_windows

    windows = make_windows(train_pieces, 101, stride=100, cover_end=True)
    models = {"learned": model, "nominal analytic": Furuta(), "truth without the delay": _truth(cell)}
    # the loss the cell trained on: its span of quadrature intervals per residual
    return {
        k: float(integral_loss(m, windows, rule=rule, normalize="none", span=cell.integral_span))
        for k, m in models.items()
    }


def gravity_profile(train_pieces, rule: str, cell: Cell) -> dict:
    """Which gravity the loss wants with everything else true: L_Iτ of the truth without its
    delay with gravity scaled by s is quadratic in s (the residual is linear in V); its minimiser
    s* from three evaluations. s* < 0: the data make the loss prefer upright a minimum even with
    the true M, friction and input — the bias is in the data, not in the network's freedom."""
    from furuta_gym.training.losses import integral_loss, make_windows

    windows = make_windows(train_pieces, 101, stride=100, cover_end=True)

    def loss(scale):
        return float(integral_loss(_truth(cell, scale), windows, rule=rule, normalize="none", span=cell.integral_span))

    l0, l1, l2 = loss(0.0), loss(1.0), loss(2.0)
    curvature = (l2 - 2 * l1 + l0) / 2  # L(s) = a·s² + b·s + c
    slope = l1 - l0 - curvature
    return {"itau_at_scale_0_1_2": [l0, l1, l2], "best_scale": -slope / (2 * curvature)}


def short_budget(run_dir: Path, test_pieces) -> dict:
    """The snapshot after :data:`SHORT` epochs (the short budget; the rate is constant, so it is
    what a run of that length ends with): its potential shape and test score."""
    from furuta_gym.training.checkpoint import load_model

    # the last snapshot at or before SHORT (runs made with another cadence have none at SHORT)
    epochs = max(
        e for e in (int(p.stem.removeprefix("model_epoch")) for p in run_dir.glob("model_epoch*.eqx")) if e <= SHORT
    )
    model = load_model(run_dir / f"model_epoch{epochs:06d}.eqx", expected_system="furuta")
    test = window_errors(model, test_pieces, WINDOW)
    test["mean_log10"] = _mean_log10(test)
    return {"epochs": epochs, "potential": potential_shape(model), "test": test}


def at_snapshot(doc: dict, cell: Cell, run_dir: Path) -> dict:
    """A longer run's result fields at the cell's budget, from its snapshot at that epoch (the
    rate is constant: what a run of that length reaches, up to keep_best_itau's choice)."""
    from furuta_gym.training.checkpoint import load_model

    model = load_model(run_dir / f"model_epoch{cell.epochs:06d}.eqx", expected_system="furuta")
    train_pieces = _pieces(simulate(cell, N_TRAIN, DURATION, doc["data_seed"])[0], SPLIT)
    test = window_errors(model, _pieces(simulate(cell, N_TEST, TEST_DURATION, doc["data_seed"] + 500)[0], None), WINDOW)
    test["mean_log10"] = _mean_log10(test)
    along = {k: v for k, v in doc["potential_along_training"].items() if int(k) <= cell.epochs}
    config = {**doc["config"], "epochs": [cell.epochs]}
    return {
        "potential": potential_shape(model),
        "test": test,
        "potential_along_training": along,
        "config": config,
        "itau": itau_comparison(model, train_pieces, doc["config"]["quadrature"], cell),
        "gravity_profile": gravity_profile(train_pieces, doc["config"]["quadrature"], cell),
        "scored_at_snapshot": f"model_epoch{cell.epochs:06d} of a {doc['config']['epochs'][0]}-epoch run",
    }


def fill_missing(path: Path, work: Path) -> None:
    """Add what a result file written before it was recorded lacks: the potential at the start
    of training and a long run's :func:`short_budget`."""
    doc = json.loads(path.read_text())
    cell = CELLS[doc["cell"]]
    along = doc["potential_along_training"]
    if "0" not in along:  # the start, as train() makes it from the seed
        doc["potential_along_training"] = {"0": potential_shape(start_model(cell, doc["seed"])), **along}
    if doc["config"]["epochs"][0] > cell.epochs:  # a longer run: scored at the cell's budget
        doc.update(at_snapshot(doc, cell, work / path.stem))
    if "truth_has_effects" not in doc and cell.effects and "gravity_profile" in doc:
        doc["truth_has_effects"] = True  # the truth was the plant with the effects all along
    stale_truth = doc.get("truth_has_effects") != cell.effects  # made before the truth followed the cell
    stale_span = cell.integral_span > 1 and doc.get("itau_span") != cell.integral_span  # before L_Iτ followed the span
    if stale_truth or stale_span:
        from furuta_gym.training.checkpoint import load_model

        pieces = _pieces(simulate(cell, N_TRAIN, DURATION, doc["data_seed"])[0], SPLIT)
        model = load_model(work / path.stem / "model.eqx", expected_system="furuta")
        doc["itau"] = itau_comparison(model, pieces, doc["config"]["quadrature"], cell)
        doc["gravity_profile"] = gravity_profile(pieces, doc["config"]["quadrature"], cell)
        doc["truth_has_effects"] = cell.effects
    doc["itau_span"] = cell.integral_span
    if cell.epochs > SHORT and "short" not in doc:
        test_pieces = _pieces(simulate(cell, N_TEST, TEST_DURATION, doc["data_seed"] + 500)[0], None)
        doc["short"] = short_budget(work / path.stem, test_pieces)
    path.write_text(json.dumps(doc, indent=1, default=str) + "\n")


def run_one(name: str, seed: int, out: Path, work: Path) -> dict:
    """Simulate, train, measure one (cell, seed); writes ``out/<name>_s<seed>.json``."""
    from furuta_gym.models import Furuta
    from furuta_gym.training.checkpoint import load_model
    from furuta_gym.training.train import train

    cell, t0 = CELLS[name], time.time()
    data_seed = 1000 + seed
    train_runs, share = simulate(cell, N_TRAIN, DURATION, data_seed)
    train_pieces = _pieces(train_runs, SPLIT)
    test_pieces = _pieces(simulate(cell, N_TEST, TEST_DURATION, data_seed + 500)[0], None)
    config = config_for(cell, seed)
    run_dir = work / f"{name}_s{seed}"
    t1 = time.time()
    start = start_model(cell, seed)
    model, history = train("dln", "furuta", "prop", train_pieces, config, run_dir, resume=True, model=start)
    train_s = time.time() - t1
    snaps = {int(p.stem.removeprefix("model_epoch")): p for p in sorted(run_dir.glob("model_epoch*.eqx"))}
    along = {e: potential_shape(load_model(p, expected_system="furuta")) for e, p in sorted(snaps.items())}
    along[0], along[len(history)] = potential_shape(start), potential_shape(model)
    doc = {
        "cell": name,
        "label": cell.label,
        "settings": dataclasses.asdict(cell),
        "seed": seed,
        "data_seed": data_seed,
        "model_seed": seed,
        "n_train": len(train_pieces),
        "n_test_runs": N_TEST,
        "feedforward_rms_over_u_rms": round(share, 4),
        "potential_along_training": {str(e): v for e, v in sorted(along.items())},
        "potential": along[len(history)],
        "truth": potential_shape(Furuta()),
        "test": window_errors(model, test_pieces, WINDOW),
        "nominal_test": window_errors(Furuta(), test_pieces, WINDOW),
        "final_itau": history[-1].get("itau"),
        "training_seconds": round(sum(r["seconds"] for r in history), 1),
        "training_seconds_this_call": round(train_s, 1),
        "seconds": round(time.time() - t0, 1),
        "config": config.to_json(),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": platform.node(),
    }
    for key in ("test", "nominal_test"):
        doc[key]["mean_log10"] = _mean_log10(doc[key])
    if cell.epochs > SHORT:
        doc["short"] = short_budget(run_dir, test_pieces)
    doc["itau"] = itau_comparison(model, train_pieces, config.quadrature, cell)
    doc["gravity_profile"] = gravity_profile(train_pieces, config.quadrature, cell)
    doc["truth_has_effects"] = cell.effects
    (out / f"{name}_s{seed}.json").write_text(json.dumps(doc, indent=1, default=str) + "\n")
    p = doc["potential"]
    print(
        f"{name} s{seed}: curvature {1e3 * p['curvature_at_top_Nm_per_rad']:+.2f} mN·m/rad, rise "
        f"{1e3 * p['rise_to_top_J']:+.1f} mJ, test mean log10 {doc['test']['mean_log10']}, "
        f"{doc['seconds']:.0f} s",
        flush=True,
    )
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", default=",".join(CELLS), help=f"comma list of {list(CELLS)}")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--out", type=Path, default=Path("results/lprop_ablation"))
    ap.add_argument("--work", type=Path, default=Path("runs/lprop_ablation"), help="checkpoints (not committed)")
    args = ap.parse_args()
    names = args.cells.split(",")
    unknown = [n for n in names if n not in CELLS]
    if unknown:
        ap.error(f"--cells: unknown {unknown}; expected some of {list(CELLS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for seed in (int(s) for s in args.seeds.split(",")):
        for name in names:
            path = args.out / f"{name}_s{seed}.json"
            if not path.is_file():
                run_one(name, seed, args.out, args.work)
            fill_missing(path, args.work)


if __name__ == "__main__":
    main()
