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


def machine() -> str:
    """CPU model, cores, load and the versions that matter, for a section's header line."""
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
