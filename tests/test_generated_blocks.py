"""bench/_generated.py, the one writer of generated blocks (docs' tables and BENCHMARKS.md's
sections): a check compares and never writes, and fails on a block that differs from its results."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _writer():
    spec = importlib.util.spec_from_file_location("bench_generated", ROOT / "bench" / "_generated.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_benchmark_section_is_replaced_appended_and_checked(tmp_path, capsys):
    gen = _writer()
    start, end = "<!-- x:start -->", "<!-- x:end -->"
    path = tmp_path / "BENCHMARKS.md"
    path.write_text(f"# Benchmarks\n\n{start}\nold\n{end}\n\ntail\n")
    section = f"{start}\nnew\n{end}"
    assert gen.write_section(section, start, end, path, check=True) == 1
    assert "old" in path.read_text()  # a check never writes
    assert "stale" in capsys.readouterr().out
    assert gen.write_section(section, start, end, path) == 0
    assert path.read_text() == f"# Benchmarks\n\n{start}\nnew\n{end}\n\ntail\n"
    assert gen.write_section(section, start, end, path, check=True) == 0
    other = "<!-- y:start -->\ny\n<!-- y:end -->"
    gen.write_section(other, "<!-- y:start -->", "<!-- y:end -->", path)
    assert path.read_text().endswith("tail\n\n" + other + "\n")


def test_a_docs_block_is_checked_against_its_body(tmp_path):
    gen = _writer()
    path = tmp_path / "doc.md"
    path.write_text("a\n<!-- generated:t -->\n1\n<!-- /generated:t -->\nb\n")
    assert gen.block_main("x.py", path, "t", lambda: "1", ["--check"]) == 0
    assert gen.block_main("x.py", path, "t", lambda: "2", ["--check"]) == 1
    assert "\n1\n" in path.read_text()


def test_functional_env_benchmark_section_matches_its_results():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "functional_env_speed.py"), "--check"],
        capture_output=True,
        text=True,
        cwd=ROOT / "bench",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_diagnosis_speed_section_matches_its_results():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "diagnose_speed.py"), "--check"],
        capture_output=True,
        text=True,
        cwd=ROOT / "bench",
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_head_to_head_ablation_table_matches_its_results():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "head_to_head_ablation_table.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_head_to_head_ablation_prose_matches_its_results():
    """docs/diagnose.md's reading of the ablation: the finish now refits on staggered windows,
    which clears the diagnosis' rule for a gain on its own held-out windows and predicts better,
    short of the rule, where the head to head scores and on windows starting every 10 ms; a refit
    on the head-to-head's grid (as sysid fits) is better there and worse elsewhere; the relaxed
    friction with the rest clears the rule on windows starting every 10 ms only; and on runs 1-10
    the ranking of sysid and the prediction-first plant turns with where the windows start."""
    doc = json.loads((ROOT / "results" / "head_to_head" / "ablation.json").read_text())
    v = doc["variants"]
    assert v["staggered"]["passes_rule"]
    for placement in ("grid", "starts"):
        entry = v["staggered"]["by_placement"][placement]
        assert entry["improvement"] > 0 and not entry["passes_rule"]
    grid = v["grid"]["by_placement"]
    assert grid["grid"]["passes_rule"] and grid["starts"]["improvement"] < -0.03
    sysid = v["sysid_plant"]["by_placement"]
    assert sysid["grid"]["improvement"] > 0.05 and sysid["starts"]["improvement"] < 0
    combined = v["starts_sampled_all"]["by_placement"]
    assert combined["starts"]["passes_rule"] and combined["grid"]["improvement"] < 0
    for name in ("staggered_all", "staggered_delay_j1b"):  # just short of the rule, better on the grid
        staggered = v[name]["by_placement"]
        assert 0.02 < staggered["starts"]["improvement"] < 0.03 and staggered["starts"]["z_score"] >= 3
        assert not staggered["starts"]["passes_rule"] and staggered["grid"]["improvement"] > 0
    models = ("one_fold", "converged", "nominal_start", "delay", "j1b", "karnopp_5ms", "karnopp_10ms")
    models += ("karnopp_20ms", "mujoco_friction", "tanh")
    best = max(models, key=lambda k: v[k]["by_placement"]["starts"]["improvement"])
    assert best == "karnopp_10ms" and not v[best]["by_placement"]["starts"]["passes_rule"]
    assert all(v["tanh"]["by_placement"][p]["improvement"] < 0 for p in ("grid", "starts"))
    assert v["tanh"]["heldout_rmse"] > v["current"]["heldout_rmse"]
    ins = doc["in_sample"]
    assert ins["sysid"] < ins["prediction_first"]
    assert ins["every_phase"]["prediction_first"] < ins["every_phase"]["sysid"]


def test_head_to_head_input_dead_band_prose_matches_its_results():
    """docs/diagnose.md's reading of ``head_to_head_ablation.py --input-residual`` and the
    dead-band row: the rotor's acceleration error is odd in the input and largest at a few tenths
    of a volt, where the rig accelerates less than the plant, of the same sign whichever way the
    rotor turns below a volt; about zero by the rotor's speed, and the input's sign explains many
    times more of it than the speed's; the finish with a dead band beats the finish now on all
    three placements by the rule for a gain, its error follows the input's sign far less, the
    delay refitted and J1b freed beside it gain a little more, and its rotor Coulomb friction
    drops."""
    doc = json.loads((ROOT / "results" / "head_to_head" / "ablation.json").read_text())
    r = doc["input_residual"]
    by_input = {tuple(b["bin"]): b for b in r["by_input"]}
    mean = lambda cell: cell[0]  # noqa: E731
    counted = [b for b in by_input.values() if b["all"] and b["all"][2] >= 100]  # as the block lists them
    largest = max(counted, key=lambda b: abs(mean(b["all"])))
    assert max(abs(x) for x in largest["bin"]) <= 0.3 and min(abs(x) for x in largest["bin"]) >= 0.1
    for b in r["by_input"]:
        lo, hi = b["bin"]
        if -1.0 <= lo and hi <= 1.0 and b["all"] is not None:
            sign = -1 if lo >= 0 else 1  # positive input: the rig accelerates less than the plant
            for cell in (b["all"], b["pos"], b["neg"]):
                assert sign * mean(cell) > 2 * cell[1], b
    assert all(abs(mean(b["all"])) < 0.4 for b in r["by_speed"] if b["all"] and b["all"][2] >= 500)
    assert r["on_input"]["r2"] > 20 * r["on_speed"]["r2"]
    banded, finish = doc["variants"]["staggered_dead_band"], doc["variants"]["staggered"]
    assert banded["vs_finish"]["passes_rule"]
    assert all(banded["by_placement"][p]["vs_finish"]["passes_rule"] for p in ("grid", "starts"))
    plants = r["fold_plants"]  # with the band, the error follows the input's sign far less
    assert plants["staggered_dead_band"]["rmse"] < plants["staggered"]["rmse"]
    assert plants["staggered_dead_band"]["on_input"]["r2"] < 0.1 * plants["staggered"]["on_input"]["r2"]
    more = doc["variants"]["staggered_dead_band_delay_j1b"]  # with the delay and J1b: a little more
    assert 0 < more["vs_finish"]["improvement"] - banded["vs_finish"]["improvement"] < 0.03
    assert (
        more["by_placement"]["starts"]["vs_finish"]["improvement"]
        > banded["by_placement"]["starts"]["vs_finish"]["improvement"]
    )
    for with_band, without in zip(banded["per_fold"], finish["per_fold"], strict=True):
        assert with_band["dead_band"] > 0
        assert with_band["effects"]["coulomb_friction:alpha"] < without["effects"]["coulomb_friction:alpha"]


def test_head_to_head_ablation_in_sample_refit_prose_matches_its_results():
    """docs/diagnose.md's reading of ``head_to_head_ablation.py --oe-in-sample``: the refit beats
    sysid's values on its own objective and loses on the head-to-head's windows; started from
    sysid's values it ends beside its own refit and moves up on those windows; on sysid's objective
    it reaches one point from either start, below sysid's values; each plant's error grows about
    as much like t as like t², with a small rest of rounding, on both placements; with start
    velocities refitted the plants come within 3 % of each other; the rotor's start angle squared
    carries the refit's acceleration errors, a few per cent of its error, less on runs left out
    of its fit, most on run 9 and none on run 1; each window's own force error taken away leaves
    most of the error, and a smooth function of state and input takes a few per cent on runs left
    out; the refit freed of the
    start-velocity error predicts every placement worse than the finish."""
    spec = importlib.util.spec_from_file_location("ablation_table", ROOT / "studies" / "head_to_head_ablation_table.py")
    assert spec is not None and spec.loader is not None
    table = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(table)
    error_shares = table.error_shares
    doc = json.loads((ROOT / "results" / "head_to_head" / "ablation.json").read_text())
    o, pf, sy = doc["oe_in_sample"], "prediction_first", "sysid"
    assert o["finish_objective"][pf] < o["finish_objective"][sy] and o["grid"][sy] < o["grid"][pf]
    assert abs(o["from_sysid"]["finish_objective"] / o["finish_objective"][pf] - 1) < 0.01
    assert o["from_sysid"]["grid"] > o["grid"][sy]
    fits = o["grid_fit"]
    assert abs(fits["from_sysid"] / fits["from_finish_start"] - 1) < 0.001 and fits["from_sysid"] < o["grid"][sy]
    for placement in ("grid", "phases"):
        for plant in (pf, sy):
            profile = o["profile"][placement][plant]
            shares = error_shares(profile, doc["window_seconds"] / len(profile), o["quantisation_rmse"])
            assert 0.35 < shares["velocity"] < 0.65 and 0.35 < shares["force"] < 0.65 and shares["rounding"] < 0.1
        refined = o["refined_start"][placement]
        assert abs(refined[pf] / refined[sy] - 1) < 0.03
    rotor = o["rotor_angle_residual"]  # far from zero on either side the rotor accelerates more than predicted
    assert all(c < -0.3 for c in rotor["correlation_alpha_squared"])
    assert rotor["coefficients"][0][2] < 0 and 0.01 < 1 - rotor["rmse_without"] / rotor["rmse"] < 0.1
    assert rotor["rmse_without"] < rotor["rmse_without_run_out"] < rotor["rmse"]  # less on runs left out
    change = {doc["fit_runs"][int(k)]: after / before - 1 for k, (before, after) in rotor["per_run"].items()}
    assert min(change, key=lambda k: change[k]) == 9 and change[1] > 0  # run 9 gains most, run 1 loses
    force = o["force_error_bounds"]  # a smooth force of start state and mean input takes a few per cent
    best = min(force["ridge"].values())
    assert force["oracle"] > 0.75 * force["rmse"] and 0.01 < 1 - best / force["rmse"] < 0.05
    # the input's dead band, acting on each sample's input, takes much more (RMSE on every 10 ms)
    banded = doc["variants"]["staggered_dead_band"]["by_placement"]["starts"]["vs_finish"]["improvement"]
    assert 1 - (1 - banded) ** 0.5 > 2 * (1 - best / force["rmse"])
    worse = doc["variants"]["staggered_refined_starts"]
    staggered = doc["variants"]["staggered"]
    assert worse["heldout_rmse"] > staggered["heldout_rmse"]
    for placement in ("grid", "starts"):
        assert worse["by_placement"][placement]["heldout_rmse"] > staggered["by_placement"][placement]["heldout_rmse"]
