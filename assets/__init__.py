"""MJCF ground-truth models shipped with the package."""

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent

__all__ = ["ASSETS_DIR", "asset_path"]


def asset_path(name: str) -> Path:
    """Path of a shipped asset file, e.g. ``asset_path("furuta.xml")``."""
    path = ASSETS_DIR / name
    if not path.is_file():
        available = sorted(p.name for p in ASSETS_DIR.glob("*.xml"))
        raise FileNotFoundError(f"no asset {name!r} in {ASSETS_DIR}; available: {available}")
    return path
