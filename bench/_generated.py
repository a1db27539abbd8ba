"""The one writer of generated blocks: text that a script writes from committed results between
markers in a Markdown file, with a check mode that only compares.

Two marker styles, one mechanism:

* the tables in README.md and docs/: ``<!-- generated:NAME -->`` ... ``<!-- /generated:NAME -->``
  (:func:`fill_block`, :func:`update`, :func:`block_main`; written by studies/*.py);
* the sections of BENCHMARKS.md (and a few of docs/): ``<!-- NAME:start -->`` ...
  ``<!-- NAME:end -->``, markers included in the section (:func:`write_section`; written by
  bench/*.py).

In check mode nothing is written: the exit status is 1, with a message saying how to refresh the
file, when its committed text differs from what the results generate. The tests run each
script's ``--check``. studies/ scripts import this module from bench/ (bench/ stays where it is).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS_MD = ROOT / "BENCHMARKS.md"


def fill_block(text: str, name: str, body: str, *, where: object = "text", required: bool = True) -> str:
    """``text`` with the block ``name`` holding ``body``; a missing block is an error naming
    ``where`` unless not ``required`` (then ``text`` comes back unchanged)."""
    pattern = re.compile(rf"(<!-- generated:{name} -->).*?(<!-- /generated:{name} -->)", re.S)
    if required and not pattern.search(text):
        raise ValueError(f"{where}: no <!-- generated:{name} --> ... <!-- /generated:{name} --> markers")
    return pattern.sub(lambda m: m.group(1) + "\n" + body + "\n" + m.group(2), text)


def fill_section(text: str, section: str, start: str, end: str) -> str:
    """``text`` with the section from ``start`` to ``end`` replaced by ``section`` (which holds
    both markers), or with ``section`` appended when ``text`` has no such section yet."""
    pattern = re.compile(re.escape(start) + ".*?" + re.escape(end), re.S)
    if pattern.search(text):
        return pattern.sub(lambda _: section.strip("\n"), text)
    return text.rstrip("\n") + "\n\n" + section.strip("\n") + "\n"


def update(path: Path, new_text: str, check: bool, how_to_fix: str) -> int:
    """Write ``new_text`` to ``path`` (exit code 0), or with ``check`` only compare: 1 and a
    message saying ``how_to_fix`` if the file differs."""
    if path.exists() and new_text == path.read_text():
        return 0
    if check:
        print(f"{path}: out of date with its results; {how_to_fix}")
        return 1
    path.write_text(new_text)
    return 0


def write_section(
    section: str,
    start: str,
    end: str,
    path: Path = BENCHMARKS_MD,
    *,
    check: bool = False,
    how_to_fix: str = "run the bench script that writes it",
) -> int:
    """Put ``section`` (``start`` and ``end`` included) into ``path`` (BENCHMARKS.md by default),
    replacing the section between those markers or appending it; with ``check`` only compare
    (exit code 1, saying ``how_to_fix``, if the file differs)."""
    old = path.read_text() if path.exists() else "# Benchmarks\n"
    status = update(path, fill_section(old, section, start, end), check, f"{start} is stale: {how_to_fix}")
    if not check:
        print(f"wrote {path}")
    return status


def publish(section: str, start: str, end: str, write: bool = True) -> int:
    """Print a measured ``section`` and, with ``write``, put it into BENCHMARKS.md."""
    print()
    print(section)
    return write_section(section, start, end) if write else 0


def script_command(script: str) -> str:
    """How to run ``script`` (a ``__file__``) from the repository root."""
    path = Path(script).resolve()
    try:
        path = path.relative_to(ROOT)
    except ValueError:
        pass
    return f"run python {path}"


def block_main(script: str, path: Path, name: str, body: Callable[[], str], argv=None) -> int:
    """The command line of ``script`` (its ``__file__``), whose one output is the block ``name``
    of ``path``: rewrite the block and print it, or with ``--check`` only compare (exit 1 if
    stale). ``body`` is computed once."""
    ap = argparse.ArgumentParser(description=f"write the {name} block of {path.name}")
    ap.add_argument("--check", action="store_true", help="exit 1 if that block is stale")
    args = ap.parse_args(argv)
    text = body()
    new = fill_block(path.read_text(), name, text, where=path)
    status = update(path, new, args.check, script_command(script))
    if not args.check:
        print(text)
    return status


def machine() -> str:
    """CPU model, cores, load and the versions that matter, for a benchmark section's header line."""
    import os
    import platform

    import jax
    import mujoco

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (
        f"{cpu}, {os.cpu_count()} logical cores (shared; 1-min load average {load:.1f} at start), "
        f"Python {platform.python_version()}, JAX {jax.__version__} ({jax.default_backend()}), "
        f"MuJoCo {mujoco.__version__}, Gymnasium {__import__('gymnasium').__version__}"
    )
