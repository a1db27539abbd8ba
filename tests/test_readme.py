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
