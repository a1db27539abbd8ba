"""Reproduction pipeline (issue 6): an end-to-end run smaller than --quick writes the tables
beside the paper's numbers, figures and a run record, reuses finished models, and the table logic
(N/A, X, seeds) follows the paper's conventions."""

import csv
import dataclasses
import importlib.metadata
import json
import math
import sys
from pathlib import Path

import pytest

import furuta_gym
from furuta_gym.training.reproduce import (
    METRIC_COLUMNS,
    ReproduceSettings,
    build_tables,
    load_paper_table,
    reproduce,
)

TINY = ReproduceSettings(
    quick=True,
    systems=("nmsd",),
    pairs=(("dln", "prop"),),
    prop_epochs={"nmsd": (20, 1, 0)},  # L_Iτ alone, then one epoch of the 2-step stage
    progress=False,
    ground_truth="analytic",
)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    logs = []
    paths = reproduce(out, TINY, command="pytest tiny", log=logs.append)
    return out, paths, logs


def test_tiny_run_writes_tables_beside_the_paper(tiny_run):
    out, paths, logs = tiny_run
    with open(paths["tables.csv"]) as fh:
        rows = list(csv.DictReader(fh))
    paper = load_paper_table()
    assert len(rows) == 2 * len(METRIC_COLUMNS["nmsd"])  # Chirp + Square, one model row each
    for r in rows:
        assert (r["system"], r["model"], r["loss"]) == ("nmsd", "DLN", "prop")
        assert math.isfinite(float(r["ours_mean"]))
        assert r["paper"] == paper[("nmsd", r["test_set"], "DLN", "prop", r["metric"])]
        assert r["better_or_equal"] in ("yes", "no")
    md = paths["tables.md"].read_text()
    assert "| Chirp | DLN (L_prop) |" in md and "(-0.8561)" in md and "Quick run" in md
    for name in ("predictions_nmsd", "energy_state_nmsd", "energy_time_nmsd", "forces_nmsd"):
        assert paths[name].stat().st_size > 10_000
    record = json.loads(paths["run.json"].read_text())
    assert record["command"] == "pytest tiny" and record["machine"]["cpu_count"] >= 1
    if Path("/proc/cpuinfo").is_file():  # the host's CPU beyond its model name: numerics depend on it
        assert record["machine"]["cpu_id"].startswith("family ") and len(record["machine"]["cpu_flags_sha256"]) == 16
    # the CPU numerics the run had: the pin, as the process applied it (docs/conventions.md)
    assert record["machine"]["numerics"] == json.loads(json.dumps(furuta_gym.numerics()))
    assert record["seconds"]["nmsd/dln_prop/seed0"]["status"] == "trained"
    assert (out / "data" / "nmsd" / "manifest.json").exists()


def test_rerun_reuses_finished_models_and_refuses_other_settings(tiny_run):
    out, _, _ = tiny_run
    logs = []
    paths = reproduce(out, TINY, command="again", log=logs.append)
    record = json.loads(paths["run.json"].read_text())
    assert record["seconds"]["nmsd/dln_prop/seed0"]["status"] == "reused"
    other = ReproduceSettings(**{**TINY.__dict__, "prop_epochs": {"nmsd": (20, 2, 0)}})
    with pytest.raises(ValueError, match="other settings"):
        reproduce(out, other, log=logs.append)
    # a model trained with another architecture is not reused either; a record from before the
    # architecture was recorded is trusted
    cfg_path = out / "runs" / "nmsd" / "dln_prop" / "seed0" / "reproduce_config.json"
    original = cfg_path.read_text()
    saved = json.loads(original)
    saved["model_hparams"]["hidden"] = [8, 8]
    cfg_path.write_text(json.dumps(saved))
    with pytest.raises(ValueError, match="other settings"):
        reproduce(out, TINY, log=logs.append)
    del saved["model_hparams"]
    cfg_path.write_text(json.dumps(saved))
    reproduce(out, TINY, log=logs.append)
    # without the record, the checkpoint's own header says which architecture was trained
    from furuta_gym.models import checkpoint as ckpt

    model_path = cfg_path.parent / "model.eqx"
    model_bytes = model_path.read_bytes()
    header, _ = ckpt._read(model_path)
    header["hparams"]["hidden"] = [8, 8]
    ckpt._write(
        model_path,
        {k: v for k, v in header.items() if not k.startswith("payload")},
        ckpt.load_model(model_path),
        overwrite=True,
    )
    try:
        with pytest.raises(ValueError, match="other settings"):
            reproduce(out, TINY, log=logs.append)
    finally:
        model_path.write_bytes(model_bytes)
        cfg_path.write_text(original)


def test_failed_figures_are_logged_and_never_lose_the_tables(tiny_run, tmp_path, monkeypatch):
    import shutil

    from furuta_gym.training import _reproduce_figures

    out, _, _ = tiny_run
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    (copy / "tables.md").unlink()

    def broken(*args, **kwargs):
        raise RuntimeError("no display")

    monkeypatch.setattr(_reproduce_figures, "make_figures", broken)
    logs = []
    paths = reproduce(copy, TINY, log=logs.append)
    assert "[nmsd] figures failed: RuntimeError: no display" in logs
    assert paths["tables.md"].exists() and not any(k.startswith("predictions") for k in paths)
    assert json.loads(paths["run.json"].read_text())["seconds"]["figures/nmsd"] >= 0


def test_a_committed_run_without_its_data_files_regenerates_them_exactly(tiny_run):
    """results/ keeps the data manifests, not the CSVs: resuming regenerates them (seeded) and
    checks them against the manifest's sha256; data that came out different are an error."""
    out, _, _ = tiny_run
    train_csv = out / "data" / "nmsd" / "train.csv"
    original = train_csv.read_bytes()
    train_csv.unlink()
    paths = reproduce(out, TINY, log=lambda msg: None)
    assert train_csv.read_bytes() == original and paths["tables.csv"].exists()
    manifest = out / "data" / "nmsd" / "manifest.json"
    meta = json.loads(manifest.read_text())
    assert meta["packages"]["mujoco"] == importlib.metadata.version("mujoco")  # what made the bytes
    good, recorded = meta["files"]["train"]["sha256"], meta["packages"]["mujoco"]
    meta["files"]["train"]["sha256"] = "0" * 64
    meta["packages"]["mujoco"] = "0.0.1"  # as if generated by another MuJoCo: the error says so
    manifest.write_text(json.dumps(meta))
    train_csv.unlink()
    try:
        with pytest.raises(ValueError, match=r"train.csv: missing, and regenerating it .* gave other data") as err:
            reproduce(out, TINY, log=lambda msg: None)
        assert f"generated with mujoco 0.0.1 (now {recorded})" in str(err.value)
        assert not train_csv.exists()
    finally:
        meta["files"]["train"]["sha256"], meta["packages"]["mujoco"] = good, recorded
        manifest.write_text(json.dumps(meta))
        train_csv.write_bytes(original)


def test_parallel_jobs_give_the_sequential_models_and_a_seed_spread(tiny_run, tmp_path):
    import dataclasses

    out, _, _ = tiny_run
    config = dataclasses.replace(TINY, seeds=(0, 1), jobs=2)
    logs = []
    paths = reproduce(tmp_path / "par", config, log=logs.append)
    record = json.loads(paths["run.json"].read_text())
    assert {record["seconds"][f"nmsd/dln_prop/seed{k}"]["status"] for k in (0, 1)} == {"trained"}
    # the figures are made in the pool once the system's models are done, and reported like
    # the sequential run's
    assert not any("figures failed" in line for line in logs)
    for name in ("predictions_nmsd", "energy_state_nmsd", "energy_time_nmsd", "forces_nmsd"):
        assert paths[name].parent == tmp_path / "par" / "figures" and paths[name].stat().st_size > 10_000
    assert record["seconds"]["figures"] == record["seconds"]["figures/nmsd"] > 0
    seq = json.loads((out / "runs" / "nmsd" / "dln_prop" / "seed0" / "metrics.json").read_text())
    par = [
        json.loads((tmp_path / "par" / "runs" / "nmsd" / "dln_prop" / f"seed{k}" / "metrics.json").read_text())
        for k in (0, 1)
    ]
    for label in ("Chirp", "Square"):
        for metric in METRIC_COLUMNS["nmsd"]:
            # a worker process trains the very model the sequential run trained
            assert par[0][label][metric] == pytest.approx(seq[label][metric], rel=1e-9)
    assert par[1]["Chirp"]["p"] != par[0]["Chirp"]["p"]  # another initialisation
    with open(paths["tables.csv"]) as fh:
        rows = list(csv.DictReader(fh))
    assert all(r["n_seeds"] == "2" and float(r["ours_std"]) > 0 and "±" in r["ours"] for r in rows)


def test_a_pool_starts_the_longest_models_first():
    from furuta_gym.training._reproduce_executors import _longest_first
    from furuta_gym.training.reproduce import EXPECTED_SECONDS, PAPER_PAIRS

    for quick in (True, False):
        config = ReproduceSettings(quick=quick)
        tasks = [(s, k, l, seed) for s in config.systems for k, l in PAPER_PAIRS for seed in (0, 1)]
        table = EXPECTED_SECONDS["quick" if quick else "full"]
        assert set(table) == {t[:3] for t in tasks}  # every model of the run has an estimate
        ordered = _longest_first(tasks, config)
        assert sorted(ordered) == sorted(tasks)
        costs = [table[t[:3]] for t in ordered]
        assert costs == sorted(costs, reverse=True)
        # the seeds of one model stay in the order given
        assert [t[3] for t in ordered if t[:3] == ordered[0][:3]] == [0, 1]
    # the full run's longest are the Furuta augmented DeLaN's L_prop (the Hermite rule, 24 000 L_Iτ
    # epochs) and the N-MSD DeLaN's, not the Furuta runs started first before (two seeds each: the
    # first four tasks)
    longest = {t[:3] for t in _longest_first(tasks, ReproduceSettings())[:4]}
    assert longest == {("furuta", "adln", "prop"), ("nmsd", "dln", "prop")}


def test_evaluate_cli_on_the_trained_checkpoint(tiny_run, tmp_path):
    from furuta_gym.cli import main

    out, _, _ = tiny_run
    ckpt = out / "runs" / "nmsd" / "dln_prop" / "seed0" / "model.eqx"
    js = tmp_path / "m.json"
    assert (
        main(["evaluate", str(ckpt), "--data", str(out / "data" / "nmsd" / "test_square.csv"), "--json", str(js)]) == 0
    )
    result = json.loads(js.read_text())
    (metrics,) = result["results"].values()
    stored = json.loads((ckpt.parent / "metrics.json").read_text())["Square"]
    for name in METRIC_COLUMNS["nmsd"]:
        assert metrics[name] == pytest.approx(stored[name], abs=1e-6)
    assert (
        main(["evaluate", str(ckpt), "--data", str(out / "data" / "nmsd" / "test_square.csv"), "--json", str(js)]) == 2
    )  # never overwrites


def test_table_conventions_na_x_and_seed_spread():
    cfg = ReproduceSettings(systems=("furuta",), pairs=(("dln", "prop"), ("aph", "aph")), seeds=(0, 1, 2))
    good = {m: -2.0 for m in METRIC_COLUMNS["furuta"]}
    results = {
        ("furuta", "dln", "prop"): [
            {"Free": {**good, "alpha": -1.0}, "Forced": good},
            {"Free": {**good, "alpha": -3.0}, "Forced": {**good, "alpha": "X"}},
            {"Free": good, "Forced": good},
        ],
        ("furuta", "aph", "aph"): [{"Free": good, "Forced": {**good, "beta": "X"}}] * 3,
    }
    rows = {(r["test_set"], r["model"], r["metric"]): r for r in build_tables(results, cfg)}
    r = rows[("Free", "DLN", "alpha")]
    assert float(r["ours_mean"]) == pytest.approx(-2.0) and float(r["ours_std"]) == pytest.approx(1.0)
    assert r["paper"] == "-0.3147" and r["better_or_equal"] == "yes"
    assert rows[("Forced", "DLN", "alpha")]["ours"].endswith("(1/3 X)")
    assert rows[("Forced", "DLN", "alpha")]["ours_per_seed"] == "-2.0000 X -2.0000"
    assert rows[("Free", "APH", "inertial")]["ours_per_seed"] == ""
    assert rows[("Forced", "APH", "beta")]["ours"] == "X"
    assert rows[("Forced", "APH", "beta")]["better_or_equal"] == "no"
    assert rows[("Free", "APH", "inertial")]["ours"] == "N/A" and rows[("Free", "APH", "inertial")]["paper"] == "N/A"


def test_cli_seeds_0_1_2_write_mean_and_spread_beside_the_paper(tiny_run, tmp_path):
    """``reproduce --seeds 0 1 2`` with the tiny run's settings: seed 0 is the tiny run's (reused),
    1 and 2 are trained; every cell is mean ± std over the three, with each seed's value kept."""
    import shutil
    import statistics

    from furuta_gym.cli import main

    out = tmp_path / "seeds"
    shutil.copytree(tiny_run[0], out)
    assert (
        main(
            [
                "reproduce",
                "--quick",
                "--out",
                str(out),
                "--system",
                "nmsd",
                "--pair",
                "dln:prop",
                "--prop-epochs",
                "20",
                "1",
                "0",
                "--ground-truth",
                "analytic",
                "--jobs",
                "1",
                "--no-figures",
                "--no-progress",
                "--seeds",
                "0",
                "1",
                "2",
            ]
        )
        == 0
    )
    seconds = json.loads((out / "run.json").read_text())["seconds"]
    assert [seconds[f"nmsd/dln_prop/seed{k}"]["status"] for k in (0, 1, 2)] == ["reused", "trained", "trained"]
    with open(out / "tables.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * len(METRIC_COLUMNS["nmsd"])
    for r in rows:
        per_seed = [float(v) for v in r["ours_per_seed"].split()]
        assert r["n_seeds"] == "3" and len(per_seed) == 3 and len(set(per_seed)) == 3
        assert float(r["ours_mean"]) == pytest.approx(statistics.mean(per_seed), abs=1e-4)
        assert float(r["ours_std"]) == pytest.approx(statistics.stdev(per_seed), abs=1e-4)
        assert r["ours"] == f"{float(r['ours_mean']):.2f} ± {float(r['ours_std']):.2f}" and r["paper"]
    md = (out / "tables.md").read_text()
    assert "over 3 model-initialisation seeds (0, 1, 2" in md
    chirp_p = next(r for r in rows if (r["test_set"], r["metric"]) == ("Chirp", "p"))
    assert f"**{chirp_p['ours']}**" in md and f"({chirp_p['paper']})" in md
    from furuta_gym.cli import build_parser
    from furuta_gym.cli.reproduce import config_from_args

    with pytest.raises(ValueError, match="must differ"):
        config_from_args(build_parser().parse_args(["reproduce", "--seeds", "1", "1"]))


def test_the_main_claim_is_counted_seed_by_seed_with_several_seeds():
    from furuta_gym.training._reproduce_tables import _summary_lines

    cfg = ReproduceSettings(systems=("furuta",), pairs=(("dln", "traj"), ("dln", "prop")), seeds=(0, 1, 2))
    good = {m: -2.0 for m in METRIC_COLUMNS["furuta"]}
    prop = [{label: {**good, "inertial": v} for label in ("Free", "Forced")} for v in (-3.0, -2.5, -1.0)]
    traj = [{label: {**good, "inertial": -2.0} for label in ("Free", "Forced")}] * 3
    rows = build_tables({("furuta", "dln", "prop"): prop, ("furuta", "dln", "traj"): traj}, cfg)
    lines = "\n".join(_summary_lines(rows, cfg))
    # the mean (-2.17) holds, on two of the three seeds
    assert "inertial -2.17 vs -2.00 (holds; on 2 of 3 seeds)" in lines
    one = ReproduceSettings(systems=("furuta",), pairs=cfg.pairs)
    lines = "\n".join(
        _summary_lines(
            build_tables({("furuta", "dln", "prop"): prop[:1], ("furuta", "dln", "traj"): traj[:1]}, one), one
        )
    )
    assert "inertial -3.00 vs -2.00 (holds)" in lines


def test_config_rejects_pairs_the_paper_does_not_report():
    with pytest.raises(ValueError, match="not one the paper reports"):
        ReproduceSettings(pairs=(("dln", "aph"),))
    with pytest.raises(ValueError, match="unknown system"):
        ReproduceSettings(systems=("cartpole",))


def test_full_run_gives_single_models_a_longer_itau_stage_and_overrides_win():
    from furuta_gym.training.reproduce import FULL_PROP_EPOCHS, training_settings

    full = ReproduceSettings()
    adln = training_settings("furuta", full, 0, "prop", "adln")
    dln = training_settings("furuta", full, 0, "prop", "dln")
    assert adln.epochs == (24000, *FULL_PROP_EPOCHS["furuta"][1:])
    assert dln.epochs == (12000, *FULL_PROP_EPOCHS["furuta"][1:])
    assert training_settings("furuta", full, 0, "prop", "aph").epochs == FULL_PROP_EPOCHS["furuta"]
    assert training_settings("nmsd", full, 0, "prop", "adln").epochs == FULL_PROP_EPOCHS["nmsd"]
    assert training_settings("nmsd", full, 0, "prop", "dln").epochs == (8000, *FULL_PROP_EPOCHS["nmsd"][1:])
    # the baselines, --quick and an explicit schedule are not touched
    assert (
        training_settings("furuta", full, 0, "aph", "adln").epochs
        == training_settings("furuta", full, 0, "aph", "aph").epochs
    )
    assert training_settings("furuta", ReproduceSettings(quick=True), 0, "prop", "adln").epochs == (300, 4, 1)
    own = ReproduceSettings(prop_epochs={"furuta": (50, 2, 1), "nmsd": (50, 2, 1)})
    assert training_settings("furuta", own, 0, "prop", "adln").epochs == (50, 2, 1)


def test_full_run_fine_tunes_at_smaller_steps_where_the_recipe_says_so():
    """The Furuta DeLaN, augmented DeLaN and both APHYNITYs run their two L_Iτ + λ·L_traj stages
    at FULL_PROP_FINETUNE_LEARNING_RATE after the L_Iτ stage's own rate; the N-MSD DeLaN and
    augmented DeLaN, the baselines, --quick, an explicit schedule and an explicit learning_rate
    keep what they had."""
    from furuta_gym.training.reproduce import FULL_PROP_FINETUNE_LEARNING_RATE, training_settings

    full = ReproduceSettings()
    for system, kind, itau_step in (
        ("furuta", "adln", 1e-3),
        ("furuta", "dln", 1e-3),
        ("furuta", "aph", 1e-3),
        ("nmsd", "aph", 1e-2),
    ):
        step = FULL_PROP_FINETUNE_LEARNING_RATE[(system, kind)]
        assert step < 1e-3
        assert training_settings(system, full, 0, "prop", kind).learning_rate == (itau_step, step, step)
    assert training_settings("nmsd", full, 0, "prop", "adln").learning_rate == (1e-2, 1e-3, 1e-3)
    assert training_settings("furuta", full, 0, "aph", "adln").learning_rate == 1e-3
    assert training_settings("furuta", ReproduceSettings(quick=True), 0, "prop", "adln").learning_rate == 1e-3
    own = ReproduceSettings(prop_epochs={"furuta": (50, 2, 1), "nmsd": (50, 2, 1)})
    assert training_settings("furuta", own, 0, "prop", "adln").learning_rate == 1e-3
    rate = ReproduceSettings(train_overrides={"learning_rate": 3e-3})
    assert training_settings("furuta", rate, 0, "prop", "adln").learning_rate == 3e-3


def test_full_run_gives_single_l_prop_models_their_own_quadrature_and_overrides_win(tmp_path):
    """FULL_PROP_QUADRATURE names the full run's L_prop models with their own L_Iτ rule; every
    other run (the baselines, whose Furuta scale fit takes the rule too, the other models,
    --quick, an own schedule) keeps REPRODUCE_QUADRATURE, --quadrature sets every run's, and the
    run record says which model used what."""
    from furuta_gym.training._reproduce_run_record import _write_run_record
    from furuta_gym.training.reproduce import FULL_PROP_QUADRATURE, REPRODUCE_QUADRATURE, training_settings

    full = ReproduceSettings()
    assert FULL_PROP_QUADRATURE
    for (system, kind), rule in FULL_PROP_QUADRATURE.items():
        assert rule != REPRODUCE_QUADRATURE
        assert training_settings(system, full, 0, "prop", kind).quadrature == rule
        for loss in ("traj", "aph"):
            assert training_settings(system, full, 0, loss, kind).quadrature == REPRODUCE_QUADRATURE
        for other in (
            ReproduceSettings(quick=True),
            ReproduceSettings(prop_epochs={"furuta": (50, 2, 1), "nmsd": (50, 2, 1)}),
        ):
            assert training_settings(system, other, 0, "prop", kind).quadrature == REPRODUCE_QUADRATURE
        forced = ReproduceSettings(train_overrides={"quadrature": "trapezoid"})
        assert training_settings(system, forced, 0, "prop", kind).quadrature == "trapezoid"
    untouched = [
        (s, k) for s in ("furuta", "nmsd") for k in ("dln", "aph", "adln") if (s, k) not in FULL_PROP_QUADRATURE
    ]
    assert untouched
    for system, kind in untouched:
        assert training_settings(system, full, 0, "prop", kind).quadrature == REPRODUCE_QUADRATURE
    record = json.loads(_write_run_record(tmp_path / "run.json", full, "test", {}, {}).read_text())
    assert record["quadrature"] == REPRODUCE_QUADRATURE
    assert record["quadrature_by_model"] == {f"{s}/{k}": r for (s, k), r in FULL_PROP_QUADRATURE.items()}
    record = json.loads(_write_run_record(tmp_path / "run.json", forced, "test", {}, {}).read_text())
    assert record["quadrature"] == "trapezoid" and record["quadrature_by_model"] == {}


def test_runs_record_the_augmentation_weight_they_used():
    """μ is written into each L_prop run's settings (not left to a None default), per system and
    kind; an explicit override wins; models without F_a and the baselines carry none."""
    from furuta_gym.training.reproduce import training_settings
    from furuta_gym.training.train import AUGMENTATION_WEIGHT

    full = ReproduceSettings()
    for (system, kind), mu in AUGMENTATION_WEIGHT.items():
        assert training_settings(system, full, 0, "prop", kind).augmentation_weight == mu
    assert AUGMENTATION_WEIGHT[("furuta", "adln")] != AUGMENTATION_WEIGHT[("nmsd", "adln")]
    assert training_settings("furuta", full, 0, "prop", "dln").augmentation_weight is None
    assert training_settings("furuta", full, 0, "aph", "adln").augmentation_weight is None
    own = ReproduceSettings(train_overrides={"augmentation_weight": 0.5})
    assert training_settings("furuta", own, 0, "prop", "adln").augmentation_weight == 0.5


def test_run_records_compare_within_their_form_and_a_later_setting_as_its_default():
    """A record of another form (RUN_RECORD_SCHEMA) is never reused; a record without the key is
    form 1. Within a form, a training setting the record lacks counts as its default; a model
    hyper-parameter it lacks makes it another model."""
    from furuta_gym.training.reproduce import RUN_RECORD_SCHEMA, run_settings, same_settings

    current = run_settings("furuta", "adln", "prop", 0, ReproduceSettings())
    assert current["schema"] == RUN_RECORD_SCHEMA == 1
    unversioned = {k: v for k, v in current.items() if k != "schema"}
    assert same_settings(unversioned, current)
    assert not same_settings(dict(current, schema=2), current)
    older = json.loads(json.dumps(current))
    del older["train"]["fast_compile"]  # added later, default False: what runs did before
    assert same_settings(older, current)
    assert not same_settings(older, dict(current, train=dict(current["train"], fast_compile=True)))
    no_option = json.loads(json.dumps(current))
    del no_option["model_hparams"]["odd_in_velocity"]
    assert not same_settings(no_option, current)


def test_cli_quadrature_reaches_every_run_and_the_default_is_the_recipe():
    from furuta_gym.cli import build_parser
    from furuta_gym.cli.reproduce import config_from_args
    from furuta_gym.training.reproduce import REPRODUCE_QUADRATURE, training_settings

    parser = build_parser()
    _, config = config_from_args(parser.parse_args(["reproduce", "--quadrature", "hermite", "--system", "furuta"]))
    for kind, loss in config.pairs:  # L_Iτ and, for the Furuta, every run's scale fit
        assert training_settings("furuta", config, 0, loss, kind).quadrature == "hermite"
    _, default = config_from_args(parser.parse_args(["reproduce"]))
    assert training_settings("nmsd", default, 0, "prop", "dln").quadrature == REPRODUCE_QUADRATURE
    with pytest.raises(SystemExit):
        parser.parse_args(["reproduce", "--quadrature", "boole"])


def test_cli_executor_ray_without_ray_is_one_line_before_any_work(tmp_path, monkeypatch, capsys):
    from furuta_gym.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)  # as without the [cluster] extra
    out = tmp_path / "repro"
    assert main(["reproduce", "--quick", "--executor", "ray", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["furuta-gym reproduce: error: --executor ray needs Ray: pip install 'furuta-gym[cluster]'"]
    assert not out.exists()  # no data generated, no folder made


def test_cli_executor_options_and_what_a_ray_worker_is_told():
    from furuta_gym.cli import build_parser
    from furuta_gym.cli.reproduce import config_from_args
    from furuta_gym.training._ray_sweep import worker_env

    parser = build_parser()
    _, config = config_from_args(
        parser.parse_args(["reproduce", "--executor", "ray", "--address", "auto", "--cpus-per-task", "2"])
    )
    assert (config.executor, config.address, config.cpus_per_task) == ("ray", "auto", 2)
    _, default = config_from_args(parser.parse_args(["reproduce"]))
    assert (default.executor, default.address) == ("local", None)  # the local pool stays the default
    with pytest.raises(ValueError, match="executor"):
        ReproduceSettings(executor="dask")
    with pytest.raises(ValueError, match="needs executor='ray'"):
        ReproduceSettings(address="auto")
    # a task's threads follow its CPU request; the node's other XLA flags and the caches stay,
    # after the thread setting, and a word XLA would stop reading at (not a -- flag) is dropped
    env = worker_env(
        2,
        {
            "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=8 "
            "--xla_force_host_platform_device_count=2",
            "JAX_COMPILATION_CACHE_DIR": "/cache",
            "HOME": "/root",
        },
    )
    assert env["XLA_FLAGS"].split() == [
        "--xla_cpu_multi_thread_eigen=true",
        "--xla_force_host_platform_device_count=2",
    ]
    assert env["JAX_COMPILATION_CACHE_DIR"] == "/cache" and "HOME" not in env
    assert env["XLA_PYTHON_CLIENT_PREALLOCATE"] == "false" and env["OMP_NUM_THREADS"] == "2"
    assert "multi_thread_eigen=false" in worker_env(1, {})["XLA_FLAGS"]


def test_model_overrides_reach_the_recorded_architecture_and_refuse_unknown_keys():
    """A run trained with a model option records it, so it is never reused for the default model."""
    from furuta_gym.training._reproduce_one_model import _default_hparams
    from furuta_gym.training.reproduce import same_settings

    default = _default_hparams("furuta", "adln")
    odd = _default_hparams("furuta", "adln", {"odd_in_velocity": True})
    assert default["odd_in_velocity"] is False and odd["odd_in_velocity"] is True
    assert {k: v for k, v in odd.items() if k != "odd_in_velocity"} == {
        k: v for k, v in default.items() if k != "odd_in_velocity"
    }
    record = {"system": "furuta", "model": "adln", "loss": "prop", "seed": 0, "train": {}}
    assert not same_settings(dict(record, model_hparams=odd), dict(record, model_hparams=default))
    with pytest.raises(ValueError, match="unknown DeLaN hyper-parameters|unknown"):
        _default_hparams("furuta", "dln", {"odd_in_velocity": True})


def test_quick_runs_compile_their_steps_fast_and_full_runs_do_not():
    """--quick trains a few hundred steps per model, so its steps are compiled unoptimised
    (``fast_compile``); the full run's are not."""
    from furuta_gym.training.reproduce import training_settings

    for kind, loss in (("dln", "traj"), ("adln", "prop"), ("aph", "aph")):
        assert training_settings("furuta", ReproduceSettings(quick=True), 0, loss, kind).fast_compile
        assert not training_settings("furuta", ReproduceSettings(), 0, loss, kind).fast_compile


@pytest.mark.parametrize(
    "system, files, labels",
    [
        # the Furuta's run takes a minute more: what only it adds, the scale fit's set, is checked
        # by the next test; its datasets by tests/test_validation_data.py
        pytest.param(
            "furuta",
            ["train.csv", "val_forced.csv", "val_free.csv", "val_scale_fit.csv"],
            {"Free", "Forced"},
            marks=pytest.mark.slow,
        ),
        # the N-MSD's validation labels are not its test labels: its tables are written from them
        ("nmsd", ["train.csv", "val_multisine.csv", "val_steps.csv"], {"Multisine", "Steps"}),
    ],
)
def test_a_validation_run_never_writes_or_scores_a_test_set(tmp_path, system, files, labels):
    """A selection run (split="validation") trains on the same training data, fits the Furuta scale
    on val_scale_fit and scores the validation sets only: no test file, no test label, no paper
    value; its runs record the split, so a test run never reuses them (and vice versa)."""
    config = ReproduceSettings(
        quick=True,
        systems=(system,),
        pairs=(("dln", "prop"),),
        prop_epochs={system: (10, 1, 0)},
        progress=False,
        ground_truth="analytic",
        split="validation",
    )
    paths = reproduce(tmp_path, config, log=lambda msg: None)
    data = tmp_path / "data" / system
    assert sorted(p.name for p in data.glob("*.csv")) == files
    metrics = json.loads((tmp_path / f"runs/{system}/dln_prop/seed0/metrics.json").read_text())
    assert set(metrics) - {"_seconds"} == labels
    assert all(math.isfinite(float(metrics[label]["energy"])) for label in labels)
    record = json.loads((tmp_path / f"runs/{system}/dln_prop/seed0/reproduce_config.json").read_text())
    assert record["split"] == "validation"
    rows = list(csv.DictReader(paths["tables.csv"].open()))
    assert rows and all(r["paper"] == "" for r in rows) and not any(k.startswith("fig") for k in paths)
    assert {r["test_set"] for r in rows} == labels
    table = paths["tables.md"].read_text()
    assert all(f"| {label} | DLN (L_prop)" in table for label in labels)
    with pytest.raises(ValueError, match="split='validation' .this run: 'test'."):
        reproduce(tmp_path, dataclasses.replace(config, split="test"), log=lambda msg: None)
    with pytest.raises(ValueError, match="split must be one of"):
        ReproduceSettings(split="train")


def test_a_validation_run_fits_the_furuta_scale_on_its_own_forced_set_and_a_test_run_on_the_test_one():
    """The scale-fit set each split's run takes (the Furuta's; the N-MSD fits none): a name that
    the generated data do not have would leave the scale unfitted."""
    from furuta_gym.training._reproduce_data import _training_data
    from furuta_gym.training.datagen import DATASET_NAMES, VALIDATION_NAMES

    data = {name: [name] for name in (*DATASET_NAMES["furuta"], *VALIDATION_NAMES["furuta"])}
    for split, expected in (("test", "scale_fit"), ("validation", "val_scale_fit")):
        config = ReproduceSettings(systems=("furuta",), split=split)
        assert _training_data("furuta", data, config)[1] == [expected]
    del data["val_scale_fit"]
    with pytest.raises(ValueError, match="furuta validation data: no 'val_scale_fit' set to fit the scale on"):
        _training_data("furuta", data, ReproduceSettings(systems=("furuta",), split="validation"))
    nmsd = {name: [name] for name in (*DATASET_NAMES["nmsd"], *VALIDATION_NAMES["nmsd"])}
    assert _training_data("nmsd", nmsd, ReproduceSettings(systems=("nmsd",), split="validation"))[1] is None


def _decision_log_rows() -> list[str]:
    """The rows of docs/reproduce.md's decision log (the table under "**Decision log.**")."""
    from pathlib import Path

    docs = (Path(__file__).resolve().parents[1] / "docs" / "reproduce.md").read_text()
    log = docs[docs.index("**Decision log.**") :]
    table = log[log.index("| choice |") :]
    return table[: table.index("\n\n")].splitlines()[2:]


def test_every_recipe_row_cites_rows_of_the_decision_log():
    """The recipe is one table (furuta_gym.training.recipe); each of its choices names a row of
    docs/reproduce.md's decision log, which must exist."""
    from furuta_gym.training.recipe import RECIPE

    choices = [line.split("|")[1].strip() for line in _decision_log_rows()]
    assert len(RECIPE) == 12
    for key, row in RECIPE.items():
        assert row.decisions, key
        for decision in row.decisions:
            assert any(c.startswith(decision) for c in choices), (key, decision)


def _seed_differences(node) -> list[list[float]]:
    """Every ``differences`` list (seed by seed, against the recipe's value) in a selection JSON."""
    if isinstance(node, dict):
        found = [node["differences"]] if isinstance(node.get("differences"), list) else []
        return found + [d for v in node.values() for d in _seed_differences(v)]
    if isinstance(node, list):
        return [d for v in node for d in _seed_differences(v)]
    return []


def test_decision_log_quotes_match_their_evidence():
    """The seed-by-seed differences the decision log quotes — "(a, b, c)", a range "a … b", or
    for a candidate stopped once beaten "beaten on seed 0 (a)" / "on seed 1 (a, b)" — are those
    of a selection result the same row links to, to the decimals quoted."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    number = r"[+−-]?\d+\.\d+"
    value = lambda text: float(text.replace("−", "-"))  # noqa: E731
    matches = lambda quoted, actual: all(  # noqa: E731
        abs(a - value(q)) <= 0.5 * 10.0 ** -len(q.split(".")[1]) + 1e-12 for q, a in zip(quoted, actual, strict=True)
    )
    checked = 0
    for row in _decision_log_rows():
        evidence = [
            d
            for link in re.findall(r"\]\(\.\./(results/[^)]+)\.md\)", row)
            if (root / f"{link}.json").exists()
            for d in _seed_differences(json.loads((root / f"{link}.json").read_text()))
        ]
        for triple in re.findall(rf"\(({number}), ({number}), ({number})\)", row):
            assert any(len(d) == 3 and matches(triple, d) for d in evidence), (row[:40], triple)
            checked += 1
        # a quote placed away from its "beaten on seed N" would escape the check below
        assert not re.search(r"beaten on seed \d(?! \()", row), row[:40]
        for stopped in re.findall(rf"beaten on seed \d \(({number}(?:, {number})*)\)", row):
            quoted = stopped.split(", ")
            assert any(len(d) == len(quoted) and matches(quoted, d) for d in evidence), (row[:40], stopped)
            checked += 1
        for low, high in re.findall(rf"({number}) … ({number})", row):
            assert any(matches((low, high), (min(d), max(d))) for d in evidence), (row[:40], low, high)
            checked += 1
    assert checked >= 8


@pytest.mark.parametrize("script", ["reproduce_summary.py", "recipe_table.py", "reproduce_seeds_table.py"])
def test_docs_reproduce_tables_match_their_sources(script):
    """docs/reproduce.md's recipe table is the recipe (training/recipe.py) and its results summary
    is results/reproduce: a quoted number that disagrees with its source fails here."""
    import subprocess
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "studies" / script
    out = subprocess.run([sys.executable, str(path), "--check"], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
