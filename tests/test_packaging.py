"""Packaging: the fixed layout maps into furuta_gym.*, nothing installs a top-level `models`."""

import importlib
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_folder_is_listed_in_pyproject():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    mapping = cfg["package-dir"]
    found = set()
    for top, folder in mapping.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder)
            found.add(".".join([top, *rel.parts]))
    assert found <= listed, f"unlisted packages: {sorted(found - listed)}"


def test_import_names_live_under_furuta_gym_only():
    for name in ("furuta_gym.models", "furuta_gym.controllers", "furuta_gym.assets"):
        importlib.import_module(name)
    code = "import importlib.util as u; print(u.find_spec('models') is None, u.find_spec('controllers') is None)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert out.stdout.split() == ["True", "True"], out.stderr


def test_cli_help_lists_subcommands():
    out = subprocess.run([sys.executable, "-m", "furuta_gym", "--help"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "furuta-gym" in out.stdout
