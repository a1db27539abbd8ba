"""The batched env's copies split over JAX devices (``make_vec(..., devices=...)``).

The copies' states and actions are placed along a one-axis device mesh (``jax.sharding``), the
model's arrays replicated on every device, and the env's one jitted step runs on all of them at
once: XLA partitions the vmapped step by copy, so each device integrates its own slice and no
copy's numbers depend on the split. A batch that does not divide evenly is padded with copies of
its last row, whose results are dropped.
"""

from __future__ import annotations

from typing import Any, Sequence

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

__all__ = ["resolve_devices", "ShardedSteps"]


def resolve_devices(devices: Any) -> tuple | None:
    """``devices=`` as a tuple of JAX devices: ``None`` (this process's default, unsplit), an
    int ``k`` (the first ``k`` of :func:`jax.devices`) or a sequence of devices."""
    if devices is None:
        return None
    available = jax.devices()
    if isinstance(devices, (int, np.integer)) and not isinstance(devices, bool):
        if not 1 <= devices <= len(available):
            raise ValueError(
                f"devices={devices}: this process has {len(available)} JAX device(s) ({available}); "
                "on a CPU, XLA_FLAGS=--xla_force_host_platform_device_count=K before JAX starts makes K"
            )
        return tuple(available[: int(devices)])
    if isinstance(devices, Sequence) and not isinstance(devices, str) and devices:
        devices = tuple(devices)
        if not all(isinstance(d, jax.Device) for d in devices) or len(set(devices)) != len(devices):
            raise ValueError(f"devices must be distinct JAX devices (jax.devices()), got {devices!r}")
        return devices
    raise ValueError(f"devices must be None, a number of devices or a list of JAX devices, got {devices!r}")


class ShardedSteps:
    """Call the batched step with the copies split over ``devices``: the interface of the env's
    in-process chunking (``(fn, shared, *batched) -> outputs`` as NumPy arrays)."""

    chunks = 1

    def __init__(self, num_envs: int, devices: Sequence):
        self.num_envs = num_envs
        self.devices = tuple(devices)
        mesh = Mesh(np.array(self.devices), ("copies",))
        self._split = NamedSharding(mesh, PartitionSpec("copies"))
        self._replicated = NamedSharding(mesh, PartitionSpec())
        self._pad = (-num_envs) % len(self.devices)
        self._shared: tuple | None = None

    def _place_shared(self, shared):
        # the model's arrays change only with the task: placed once per set of arguments
        if self._shared is None or self._shared[0] != id(shared):
            self._shared = (id(shared), shared, jax.device_put(shared, self._replicated))
        return self._shared[2]

    def __call__(self, fn, shared: tuple, *batched: np.ndarray) -> tuple[np.ndarray, ...]:
        if self._pad:
            batched = tuple(np.concatenate([x, np.repeat(x[-1:], self._pad, axis=0)]) for x in batched)
        placed = [jax.device_put(np.asarray(x), self._split) for x in batched]
        out = fn(*self._place_shared(shared), *placed)
        return tuple(np.array(a)[: self.num_envs] for a in out)

    def close(self) -> None:
        self._shared = None
