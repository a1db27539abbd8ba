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
    """docs/diagnose.md says no ablation of the prediction-first refit clears the diagnosis' rule
    for a gain on the fit runs' held-out windows, and that the friction law's is the best refit."""
    doc = json.loads((ROOT / "results" / "head_to_head" / "ablation.json").read_text())
    variants = doc["variants"]
    assert not any(v.get("passes_rule") for v in variants.values())
    single = {k: v for k, v in variants.items() if k not in ("current", "j1b_20ms") and not k.startswith("sysid")}
    best = min(single, key=lambda k: single[k]["heldout_rmse"])
    assert variants[best]["per_fold"][0]["train_windows"] > 0 and best in (
        "karnopp_10ms",
        "karnopp_20ms",
        "mujoco_friction",
    )
    assert variants["tanh"]["heldout_rmse"] > variants["current"]["heldout_rmse"]
