"""One factory for the learned models, used by training, checkpoints and the CLI."""

from __future__ import annotations

import jax

from .._x64 import ensure_x64
from ..systems import get_spec
from ._aphynity import Aphynity
from ._augmented import AugmentedDeLaN
from ._delan import DeLaN

__all__ = ["MODEL_KINDS", "make_model"]

MODEL_KINDS = {"dln": DeLaN, "aph": Aphynity, "adln": AugmentedDeLaN}


def make_model(system: str, kind: str, key=None, **hparams):
    """A learned model of ``system`` ("furuta" | "nmsd") of ``kind`` ("dln" | "aph" | "adln").

    ``key`` is a JAX PRNG key (or an int seed; default 0) for the network weights; ``hparams``
    override the system defaults in :data:`furuta_gym.models.SYSTEM_DEFAULTS` (e.g.
    ``hidden=(32, 32)``). The paper's sizes are the defaults: (64, 64) N-MSD, (16, 16) Furuta.
    """
    ensure_x64()
    get_spec(system)
    if kind not in MODEL_KINDS:
        raise ValueError(f"model kind must be one of {sorted(MODEL_KINDS)}, got {kind!r}")
    if key is None:
        key = 0
    if isinstance(key, int):
        key = jax.random.PRNGKey(key)
    return MODEL_KINDS[kind](system, key=key, **hparams)
