"""The one writer of BENCHMARKS.md sections: every bench script owns a block between markers."""

from __future__ import annotations

import re
from pathlib import Path

BENCHMARKS_MD = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"


def write_section(section: str, start: str, end: str, path: Path = BENCHMARKS_MD) -> Path:
    """Replace the block from ``start`` to ``end`` (``section`` includes both markers) in
    ``path``, or append it if the file has no such block yet."""
    text = path.read_text() if path.exists() else "# Benchmarks\n"
    pattern = re.compile(re.escape(start) + ".*?" + re.escape(end), re.S)
    if pattern.search(text):
        text = pattern.sub(lambda _: section.strip("\n"), text)
    else:
        text = text.rstrip("\n") + "\n\n" + section.strip("\n") + "\n"
    path.write_text(text)
    print(f"wrote {path}")
    return path
