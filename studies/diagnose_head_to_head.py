"""Head to head on the real QUBE-Servo runs: which model of the rig predicts runs it never saw?

One split for every method: **fit on runs 1–10, score on runs 11–15** of the 15 shipped
closed-loop runs (``furuta_gym.datasets.load_qube_closed_loop``, 500 Hz, upright balancing).
Ten runs, because the rotor's cable spring shows only where the rotor wanders far from its
neutral (runs 1, 9 and 10 among the first ten; docs/diagnose.md, per-run table) and five runs hold
too few such stretches; runs 11–15 hold one wandering run (14) and four that stay near zero, so the
score covers both. Rows:

* **nominal**: ``furuta_gym.models.Furuta``, the datasheet parameters.
* **public simulators** with their published parameters (``qube_baselines.py``: equations,
  values, sources and the mapping onto our convention): gym_brt, quanser_robots / SimuRLacra, and
  Armandpl/furuta's own rig.
* **mujoco.sysid**: the shipped MJCF's native terms fitted by ``mujoco.sysid.optimize`` on every
  back-to-back 0.1 s window of the fit runs (``head_to_head_sysid.py``); and the same with only
  the terms the declared model has (inertias, damping, motor gain), beside "fitted".
* **furuta-gym fitted**: ``diagnose`` with no candidate effects (the declared model's lumped
  parameters, equation error refined by output error).
* **furuta-gym diagnosed**: ``diagnose`` with the library, its found effects and input delay —
  the README's recipe (0.5 s start dropped, 0.1 s windows, 64 output-error windows).
* **furuta-gym diagnosed, prediction-first**: the same diagnosis with ``finish="prediction"``
  (``diagnose --prediction-first``): its final model, inconsistent effects and every joint's
  Coulomb friction refitted by output error on every fit-set window, kept if it predicts the
  held-out windows of the fit runs better; the plant it returns is scored. The diagnosis is run
  again (the finish needs its fitting context), compared with the committed one, and its own
  plants are scored too; its wall time is the diagnosis' and the finish's.

Scored identically: back-to-back 0.1 s open-loop windows of runs 11–15 (0.5 s start dropped,
zero-phase velocities estimated on the whole log), each started from the measured state with the
logged input held over each 2 ms period (delayed by a row's fitted input delay, from the log's own
earlier samples), RK4 with 4 substeps; dry friction holds a joint at rest as in the diagnosis'
predictions (``forward_dynamics_with_dry_friction``); the sysid row is rolled out by MuJoCo itself
(its identified MJCF, constraint solver on, one RK4 step per period). Errors: RMSE of α and β (rad)
and of their velocities (rad/s) over every predicted sample, and the position RMSE of both angles
together (the diagnosis' ``trajectory_rmse``). Wall times are each fit's own, on one core.

Two what-ifs on the fits, no refit (``--rescore-only`` recomputes them from the committed
files): the sysid fit with each term beyond the declared model's set to zero, and the diagnosed
plant with the effects its diagnosis reported ``inconsistent`` added at their tested coefficients
(``res.plant(include_inconsistent=True)``; a row of its own, ``diagnosed_inconsistent``).

Writes ``results/head_to_head/<row>.json`` and ``summary.json`` (machine, date, settings);
``studies/head_to_head_table.py`` puts the table into docs/diagnose.md.

    python studies/diagnose_head_to_head.py [--out results/head_to_head] [--rows a,b]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import time
from pathlib import Path

import furuta_gym  # first: it pins NumPy's BLAS before NumPy loads it (docs/conventions.md)

# isort: split
import numpy as np

furuta_gym.enable_x64()

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import head_to_head_sysid as hsysid  # noqa: E402
from furuta_gym.datasets import load_qube_closed_loop  # noqa: E402
from furuta_gym.diagnose import InputDynamics  # noqa: E402
from furuta_gym.effects import Effect, WithEffects, can_join, merge_spring_rests  # noqa: E402
from furuta_gym.envs import Plant  # noqa: E402
from furuta_gym.lagrangian import forward_dynamics_with_dry_friction  # noqa: E402
from furuta_gym.measured import prediction_windows, prepare_log  # noqa: E402
from furuta_gym.models import Furuta, LumpedSystem  # noqa: E402
from furuta_gym.simulate import rollout_zoh  # noqa: E402
from qube_baselines import BASELINES  # noqa: E402

FIT_RUNS, TEST_RUNS = list(range(1, 11)), list(range(11, 16))
SKIP, WINDOW, SUBSTEPS, OE_WINDOWS = 0.5, 0.1, 4, 64
STATES = ("alpha", "beta", "alpha_dot", "beta_dot")
#: mujoco.sysid rows: every MJCF term of head_to_head_sysid.PARAMETERS, and only the terms the
#: declared model has (inertias, damping, motor gain), beside "fitted"
SYSID_ROWS = {
    "sysid": ("mujoco.sysid (MJCF terms)", tuple(hsysid.PARAMETERS)),
    "sysid_rigid": (
        "mujoco.sysid (rigid body, damping, gain only)",
        (
            "rotor_inertia",
            "pendulum_com",
            "pendulum_armature",
            "arm_length",
            "alpha_damping",
            "beta_damping",
            "motor_gain",
        ),
    ),
}
ROWS = ("nominal", *BASELINES, *SYSID_ROWS, "fitted", "diagnosed", "diagnosed_prediction")
PREDICTION_FIRST_LABEL = "furuta-gym diagnosed, prediction-first"


def load_runs(runs: list[int]):
    """Whole runs, velocities estimated on the whole log, start dropped (as scored)."""
    return [
        prepare_log(tr, tr.name, skip=SKIP, split=None, min_seconds=WINDOW)[0]
        for tr in load_qube_closed_loop(runs, skip_seconds=0.0)
    ]


def with_input(trajs, inputs: InputDynamics):
    """The runs with the input the plant sees (a delay or lag, from each log's own samples)."""
    if inputs.kind == "none":
        return trajs
    return [dataclasses.replace(tr, u=inputs.apply(np.asarray(tr.u, float), tr.dt)) for tr in trajs]


def predict_field(field, x0, us, dt: float) -> np.ndarray:
    """Open-loop states (W, L + 1, 4) of ``field(x, u) -> ẋ`` in our frame, input held."""
    run = jax.jit(jax.vmap(lambda x, u: rollout_zoh(None, x, u, dt, SUBSTEPS, field)))
    return np.asarray(run(jnp.asarray(x0), jnp.asarray(us)))


def lagrangian_field(base, effects=(), dt: float = 0.002):
    """ẋ of ``base`` with memoryless ``effects``; dry friction holds a joint at rest."""
    dry = [e for e in effects if e.kind.is_dry_friction]
    rest = [e for e in effects if not e.kind.is_dry_friction and not e.kind.on_input]
    model = WithEffects(base, rest) if rest else base
    n, h = base.spec.n_dof, dt / SUBSTEPS

    def field(x, u):
        q, qd = x[:n], x[n:]
        limit = jnp.zeros(n)
        for e in dry:
            j = e.joint_index(base.spec)
            limit = limit.at[j].add(jnp.maximum(e.dry_friction_limit()(qd[j]), 0.0))
        return jnp.concatenate([qd, forward_dynamics_with_dry_friction(model, limit, q, qd, u, h)])

    return field


def score(pred: np.ndarray, xs: np.ndarray) -> dict:
    """RMSE per state over all predicted samples (the start sample, measured, left out), and of
    both angles together; windows whose prediction blew up are counted and left out."""
    k = pred.shape[-1]
    bad = ~np.all(np.isfinite(pred) & (np.abs(pred) < 1e6), axis=(1, 2))
    err = (pred - xs[..., :k])[~bad][:, 1:].reshape(-1, k)
    rmse = {s: float(np.sqrt(np.mean(err[:, i] ** 2))) for i, s in enumerate(STATES[:k])}
    return {
        "rmse": rmse,
        "position_rmse": float(np.sqrt(np.mean(err[:, :2] ** 2))),
        "n_windows": int(len(pred)),
        "n_diverged": int(bad.sum()),
    }


def score_field(field, trajs, inputs: InputDynamics = InputDynamics(), stride: float | None = None) -> dict:
    x0, us, xs = prediction_windows(with_input(trajs, inputs), WINDOW, stride)
    return score(predict_field(field, x0, us, trajs[0].dt), xs)


def row_doc(name: str, label: str, result: dict, wall: float | None, **extra) -> dict:
    return {
        "name": name,
        "label": label,
        "fit_runs": FIT_RUNS if wall is not None else [],
        "test_runs": TEST_RUNS,
        "wall_seconds": None if wall is None else round(wall, 1),
        **result,
        **extra,
    }


def fixed_rows(test) -> list[dict]:
    """The nominal model and the public simulators: nothing fitted."""
    rows = [row_doc("nominal", "nominal (datasheet)", score_field(lagrangian_field(Furuta()), test), None)]
    for b in BASELINES.values():
        rows.append(
            row_doc(
                b.name,
                b.label,
                score_field(b.vector_field, test),
                None,
                source=b.source,
                parameters=b.params,
                frame=dataclasses.asdict(b.frame),
            )
        )
    return rows


def score_plant(plant, test, stride: float | None = None) -> dict:
    """A diagnosed plant (lumped values, effects) on the test runs."""
    base = LumpedSystem.of("furuta", plant.lumped)
    joint_effects = [e for e in plant.effects if not e.kind.on_input]
    return score_field(lagrangian_field(base, joint_effects), test, InputDynamics.of_effects(plant.effects), stride)


def run_diagnosis(candidates, finish=None):
    """``diagnose`` on the fit runs with the README's recipe; (result, wall seconds)."""
    from furuta_gym.diagnose import diagnose

    t0 = time.perf_counter()
    res = diagnose(
        load_qube_closed_loop(FIT_RUNS, skip_seconds=SKIP),
        "furuta",
        candidates=candidates,
        window=WINDOW,
        oe_max_windows=OE_WINDOWS,
        finish=finish,
    )
    return res, time.perf_counter() - t0


def diagnose_row(name: str, candidates, test) -> dict:
    """``diagnose`` on the fit runs (the README's recipe), timed, and its plant scored."""
    res, wall = run_diagnosis(candidates)
    plant = res.plant()
    label = "furuta-gym fitted (no effects)" if name == "fitted" else "furuta-gym diagnosed"
    found = [f"{e.name}:{e.joint}" for e in plant.effects]
    return row_doc(
        name,
        label,
        score_plant(plant, test),
        wall,
        found=found,
        parameters=dict(plant.lumped),
        effects=[{"name": e.name, "joint": e.joint, "coefficient": e.coefficient} for e in plant.effects],
        diagnosis=res.to_json(),
    )


def plant_effects(plant) -> list[dict]:
    return [
        {"name": e.name, "joint": e.joint, "coefficient": e.coefficient, "reference": e.reference}
        for e in plant.effects
    ]


def against_committed(doc: dict, before: dict) -> dict:
    """How a rerun diagnosis compares with the committed one: the same effects with the same
    statuses (the order of those tested alike may differ), and the largest relative difference of a found effect's coefficient or a fitted
    parameter (reruns on other library versions move the fits' stopping points a little)."""
    key = lambda e: (e["name"], e["joint"], e["status"])  # noqa: E731
    committed = {(e["name"], e["joint"]): e["coefficient"] for e in before["effects"]}
    pairs = [(e["coefficient"], committed.get((e["name"], e["joint"]))) for e in doc["effects"] if e["significant"]]
    pairs += [(v, before["parameters_after"][k]) for k, v in doc["parameters_after"].items()]
    return {
        "same_effects": sorted(map(key, doc["effects"])) == sorted(map(key, before["effects"])),
        "largest_relative_difference": max(abs(a - b) / max(abs(a), abs(b), 1e-300) for a, b in pairs),
    }


def prediction_first_row(test, committed: Path) -> dict:
    """The diagnosis with its prediction-first finish, timed; the plant it returns scored (and the
    refit's too when it was not kept), beside the same run's diagnosed plant with and without its
    inconsistent effects. Its report is compared with the committed diagnosis."""
    res, wall = run_diagnosis(None, finish="prediction")
    finish = res.prediction
    assert finish is not None
    doc = res.to_json()
    doc.pop("prediction_finish")
    versus = against_committed(doc, json.loads(committed.read_text())["diagnosis"]) if committed.is_file() else None
    extra = {} if finish.kept or finish.refit is None else {"refit_score": score_plant(finish.refit, test)}
    # the same rerun's own plants, so that the finish is judged against the diagnosis it refitted
    same_run = {
        "diagnosed": score_plant(res.plant(), test)["position_rmse"],
        "with_inconsistent": score_plant(res.plant(include_inconsistent=True), test)["position_rmse"],
    }
    return row_doc(
        "diagnosed_prediction",
        PREDICTION_FIRST_LABEL,
        score_plant(finish.plant, test),
        wall,
        kept=finish.kept,
        diagnosis_vs_committed=versus,
        same_run_position_rmse=same_run,
        found=[f"{e.name}:{e.joint}" for e in res.found],
        parameters=dict(finish.plant.lumped),
        effects=plant_effects(finish.plant),
        prediction_finish=finish.to_json(),
        **extra,
        diagnosis=doc,
    )


def sysid_row(name: str, fit, test, every: int, max_iters: int) -> dict:
    label, names = SYSID_ROWS[name]
    t0 = time.perf_counter()
    fitted, values, half, record = hsysid.fit(fit, WINDOW, every=every, max_iters=max_iters, names=names)
    wall = time.perf_counter() - t0
    x0, _, xs = prediction_windows(test, WINDOW)
    _, u_ext, _ = hsysid.windows_for_sysid(test, WINDOW)
    pred = hsysid.predictor(fitted)(x0, u_ext, test[0].dt)
    return row_doc(
        name, label, score(pred, xs), wall, parameters=values, half_widths_95=half, fit=record, window_every=every
    )


#: terms of the sysid fit beyond the declared model's, each set to zero in turn at the fitted
#: values (no refit): which of them carries the prediction on the unseen runs
SYSID_EXTRA_TERMS = (
    "alpha_stiffness",
    "alpha_frictionloss",
    "beta_frictionloss",
    "pendulum_com_lateral",
    "input_delay",
)


def sysid_without_terms(values: dict, test) -> dict:
    """Position RMSE on the test runs of the sysid fit with each extra term zeroed ("none": the
    fit as written to its result file, rebuilt from its SI values)."""
    x0, _, xs = prediction_windows(test, WINDOW)
    _, u_ext, _ = hsysid.windows_for_sysid(test, WINDOW)
    out = {"none": score(hsysid.predictor(hsysid.from_physical(values))(x0, u_ext, test[0].dt), xs)["position_rmse"]}
    for term in SYSID_EXTRA_TERMS:
        params = hsysid.from_physical({**values, term: 0.0})
        out[term] = score(hsysid.predictor(params)(x0, u_ext, test[0].dt), xs)["position_rmse"]
    return out


def add_sysid_ablation(path: Path, test) -> None:
    """Write the leave-one-term-out scores into a sysid row's result file."""
    doc = json.loads(path.read_text())
    doc["position_rmse_without"] = sysid_without_terms(doc["parameters"], test)
    path.write_text(json.dumps(doc, indent=1, default=float) + "\n")


PREDICTIVE_LABEL = "furuta-gym diagnosed, with its inconsistent effects"


def predictive_row(diagnosed: dict, test) -> dict | None:
    """The diagnosed plant with the effects its diagnosis reported ``inconsistent`` added at their
    tested coefficients, no refit: ``res.plant(include_inconsistent=True)``, rebuilt here from the
    committed diagnosis (its fit and wall time are the diagnosed row's). None without any."""
    evidence = diagnosed["diagnosis"]["effects"]
    found = [Effect(e["name"], e["joint"], e["coefficient"]) for e in evidence if e["significant"]]
    candidates = [
        Effect(e["name"], e["joint"], e["coefficient"])
        for e in evidence
        if e["status"] == "inconsistent" and e["coefficient"] is not None
    ]
    extra = [e for e in candidates if can_join(e, found)]
    added = [f"{e.name}:{e.joint}" for e in extra]
    if not added:
        return None
    effects = merge_spring_rests(found + extra)
    plant = dataclasses.replace(Plant.from_json(diagnosed["diagnosis"]["plant"]), effects=tuple(effects))
    return row_doc(
        "diagnosed_inconsistent",
        PREDICTIVE_LABEL,
        score_plant(plant, test),
        diagnosed["wall_seconds"],
        added=added,
        effects=plant_effects(plant),
    )


def rescore(out: Path, test) -> None:
    """The what-ifs on committed fits: sysid without each extra term, the diagnosed plant with its
    inconsistent effects (a row of its own)."""
    if (out / "sysid.json").is_file():
        add_sysid_ablation(out / "sysid.json", test)
    if (out / "diagnosed.json").is_file():
        diagnosed = json.loads((out / "diagnosed.json").read_text())
        if diagnosed.pop("with_inconsistent", None) is not None:  # the sentence the row replaced
            (out / "diagnosed.json").write_text(json.dumps(diagnosed, indent=1, default=float) + "\n")
        row = predictive_row(diagnosed, test)
        if row is not None:
            stamp = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
            (out / "diagnosed_inconsistent.json").write_text(
                json.dumps({**row, **stamp}, indent=1, default=float) + "\n"
            )


#: windows starting every 10 ms: every point of the runs' 0.1 s input cycle alike (back-to-back
#: windows from each run's first sample all start at the same point of it)
EVERY_PHASE = 0.01


def row_plant(doc: dict, folder: Path):
    """The committed plant of a furuta-gym row (None for the other rows)."""
    if doc["name"] in ("fitted", "diagnosed"):
        return Plant.from_json(doc["diagnosis"]["plant"])
    if doc["name"] == "diagnosed_prediction":
        return Plant.from_json(doc["prediction_finish"]["plant"])
    if doc["name"] == "diagnosed_inconsistent":
        base = Plant.from_json(json.loads((folder / "diagnosed.json").read_text())["diagnosis"]["plant"])
        effects = [Effect(e["name"], e["joint"], e["coefficient"], e.get("reference")) for e in doc["effects"]]
        return dataclasses.replace(base, effects=tuple(effects))
    return None


def without_dead_band(doc: dict):
    """The prediction-first row's refit without its dead band (None for other rows, or without one)."""
    plant = doc.get("prediction_finish", {}).get("mujoco_plant") if doc["name"] == "diagnosed_prediction" else None
    return None if plant is None else Plant.from_json(plant)


def score_row(doc: dict, folder: Path, test, stride: float | None) -> dict:
    """A committed row's fit scored again on ``test``, its windows one every ``stride`` s."""
    name = doc["name"]
    if name in SYSID_ROWS:
        x0, u_ext, _ = hsysid.windows_for_sysid(test, WINDOW, stride=stride)
        _, _, xs = prediction_windows(test, WINDOW, stride)
        return score(hsysid.predictor_from_values(doc["parameters"])(x0, u_ext, test[0].dt), xs)
    if name == "nominal":
        return score_field(lagrangian_field(Furuta()), test, stride=stride)
    if name in BASELINES:
        return score_field(BASELINES[name].vector_field, test, stride=stride)
    return score_plant(row_plant(doc, folder), test, stride)


def rescore_every_phase(out: Path, test) -> None:
    """Each committed row scored on windows starting every :data:`EVERY_PHASE` s (no refit),
    written into its file as ``every_phase``; each row's back-to-back score is recomputed first
    and must equal the committed one (the same fit rebuilt)."""
    for name in ROWS + ("diagnosed_inconsistent",):
        path = out / f"{name}.json"
        if not path.is_file():
            continue
        doc = json.loads(path.read_text())
        again = score_row(doc, out, test, None)["position_rmse"]
        assert abs(again - doc["position_rmse"]) <= 1e-6 * doc["position_rmse"], (name, again, doc["position_rmse"])
        doc["every_phase"] = {**score_row(doc, out, test, EVERY_PHASE), "stride_seconds": EVERY_PHASE}
        if (without := without_dead_band(doc)) is not None:  # what --mjcf writes of it, in our simulator
            doc["without_dead_band"] = {
                "position_rmse": score_plant(without, test)["position_rmse"],
                "every_phase_position_rmse": score_plant(without, test, EVERY_PHASE)["position_rmse"],
            }
        path.write_text(json.dumps(doc, indent=1, default=float) + "\n")
        print(
            f"{doc['label']:55s} back to back {1e3 * again:.3f} mrad, every phase "
            f"{1e3 * doc['every_phase']['position_rmse']:.3f}",
            flush=True,
        )


def machine() -> str:
    return f"{platform.node()} {platform.processor() or platform.machine()}"


def _arguments() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/head_to_head")
    ap.add_argument("--rows", default=",".join(ROWS), help=f"comma list of rows to run, of {list(ROWS)}")
    ap.add_argument("--sysid-every", type=int, default=1, help="sysid fits every k-th window of the fit runs")
    ap.add_argument("--sysid-iterations", type=int, default=30)
    ap.add_argument(
        "--rescore-only",
        action="store_true",
        help="only the what-ifs on the committed fits (sysid without each extra term, the diagnosis "
        "with its inconsistent effects)",
    )
    ap.add_argument(
        "--every-phase",
        action="store_true",
        help="only score the committed fits again on windows starting every 10 ms (no refit)",
    )
    args = ap.parse_args()
    args.rows = args.rows.split(",")
    if unknown := [r for r in args.rows if r not in ROWS]:
        ap.error(f"--rows: unknown {unknown}; expected some of {list(ROWS)}")
    return args


def _run_rows(args, rows: list[str], fit, test, out: Path, stamp: dict) -> None:
    """Each requested row, written as it is made: the prediction-first row reads the diagnosed one."""

    def write(d: dict) -> None:
        (out / f"{d['name']}.json").write_text(json.dumps({**d, **stamp}, indent=1, default=float) + "\n")
        print(f"{d['label']:55s} position RMSE {d['position_rmse']:.5f} rad  wall {d['wall_seconds']} s", flush=True)

    for d in fixed_rows(test):
        if d["name"] in rows:
            write(d)
    for name in SYSID_ROWS:
        if name in rows:
            write(sysid_row(name, fit, test, args.sysid_every, args.sysid_iterations))
    for name, candidates in (("fitted", []), ("diagnosed", None)):
        if name in rows:
            write(diagnose_row(name, candidates, test))
    if "diagnosed_prediction" in rows:
        write(prediction_first_row(test, out / "diagnosed.json"))


def main() -> None:
    args = _arguments()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fit, test = load_runs(FIT_RUNS), load_runs(TEST_RUNS)
    if args.rescore_only:
        return rescore(out, test)
    if args.every_phase:
        return rescore_every_phase(out, test)
    stamp = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    _run_rows(args, args.rows, fit, test, out, stamp)
    summary = {
        "fit_runs": FIT_RUNS,
        "test_runs": TEST_RUNS,
        "skip_seconds": SKIP,
        "window_seconds": WINDOW,
        "substeps": SUBSTEPS,
        "oe_windows": OE_WINDOWS,
        "velocity": "zero_phase",
        "rows": list(ROWS),
        "cpu": "one core (taskset -c 1), XLA single-threaded",
        **stamp,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    rescore(out, test)


if __name__ == "__main__":
    main()
