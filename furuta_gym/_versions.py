"""Installed package versions, as run records, data manifests, checkpoints and caches note them."""

from __future__ import annotations

import functools
from importlib import metadata


@functools.lru_cache(maxsize=None)
def installed_version(name: str, missing: str = "unknown") -> str:
    """The installed version of distribution ``name`` (``missing`` if it is not installed);
    cached: versions do not change in a running process, and reading them is slow."""
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return missing


def installed_versions(names, missing: str = "unknown") -> dict[str, str]:
    """{name: installed version} for each of ``names``."""
    return {name: installed_version(name, missing) for name in names}
