"""One factory for the learned models, used by training, checkpoints and the CLI."""

from __future__ import annotations

import jax

from .._x64 import ensure_x64
from ..systems import get_spec
from ._aphynity import Aphynity
from ._augmented import AugmentedDeLaN
from ._delan import DeLaN
from ._learned import AbstractLearnedSystem

__all__ = ["MODEL_KINDS", "model_kind", "make_model"]

#: every model kind by its name: the model classes, each carrying what differs between kinds
#: (``label``, ``analytic_prior``, ``has_augmentation``, ``form_1_hparams``); a new kind is one
#: subclass of AbstractLearnedSystem listed here
MODEL_KINDS: dict[str, type[AbstractLearnedSystem]] = {cls.kind: cls for cls in (DeLaN, Aphynity, AugmentedDeLaN)}


def model_kind(name: str) -> type[AbstractLearnedSystem]:
    """The model class of kind ``name`` (the public spelling: "dln", "aph", "adln")."""
    try:
        return MODEL_KINDS[name]
    except (KeyError, TypeError):
        raise ValueError(f"model kind must be one of {sorted(MODEL_KINDS)}, got {name!r}") from None


def make_model(system: str, kind: str, key=None, **hparams):
    """A learned model of ``system`` ("furuta" | "nmsd") of ``kind`` ("dln" | "aph" | "adln").

    ``key`` is a JAX PRNG key (or an int seed; default 0) for the network weights; ``hparams``
    override the system defaults in :data:`furuta_gym.models.SYSTEM_DEFAULTS` (e.g.
    ``hidden=(32, 32)``). The paper's sizes are the defaults: (64, 64) N-MSD, (16, 16) Furuta.
    """
    ensure_x64()
    get_spec(system)
    cls = model_kind(kind)
    if key is None:
        key = 0
    if isinstance(key, int):
        key = jax.random.PRNGKey(key)
    # every kind is built as (system, *, key, **hparams); the abstract base declares no __init__
    return cls(system, key=key, **hparams)  # pyright: ignore[reportCallIssue]
