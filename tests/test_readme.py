"""The README's Python tour runs as written (all ```python blocks, in order, one namespace)."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run(tmp_path, monkeypatch, capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) >= 4
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for i, code in enumerate(blocks):
        exec(compile(code, f"README.md python block {i + 1}", "exec"), namespace)
    # the controller block ends upright, the batched block prints the share of copies upright
    state = namespace["info"]["state"]
    assert abs(np.cos(state[1]) + 1) < 1e-3
    printed = capsys.readouterr().out.strip().splitlines()
    assert float(printed[-1]) == 1.0


def test_readme_is_a_five_minute_read_that_stays_inside_the_repo():
    text = README.read_text()
    assert len(text.encode()) <= 10_000
    for link in re.findall(r"\]\(([^)#]+)", text):
        assert not link.startswith(("../", "/")), link
        if not link.startswith("http"):
            assert (README.parent / link).exists(), link
    assert "known_pitfalls" not in text and "shared/" not in text


def test_readme_results_table_matches_the_reproduction_tables():
    import subprocess
    import sys

    script = README.parent / "studies" / "readme_results.py"
    out = subprocess.run([sys.executable, str(script), "--check"], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_nothing_in_the_repo_points_outside_it():
    """README, docs, code and tests stand alone: no path into the workshop beside the checkout."""
    root = README.parent
    files = [
        *root.glob("*.md"),
        *(root / "docs").rglob("*.md"),
        *(root / "furuta_gym").rglob("*.py"),
        *(root / "models").rglob("*.py"),
        *(root / "controllers").rglob("*.py"),
        *(p for p in (root / "tests").rglob("*.py") if p.name != "test_readme.py"),
    ]
    outside = [
        str(p.relative_to(root))
        for p in files
        if any(s in p.read_text(errors="replace") for s in ("../shared", "known_pitfalls"))
    ]
    assert not outside, outside
