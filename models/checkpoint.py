"""Checkpoints of learned models and of training runs: Equinox leaves plus a JSON header.

File layout (one file, ``.eqx`` by convention)::

    FURUTA-GYM-CHECKPOINT 1\\n
    {JSON header on one line}\\n
    <equinox.tree_serialise_leaves payload>

The header says what the file holds (``"content": "model"`` or ``"training_state"``), its form
(``"format"``, :data:`HEADER_FORMAT`; older files without one are read as form 1), the system,
the model kind and the hyper-parameters that rebuild the module's skeleton with
:func:`furuta_gym.models.make_model`, the package versions, the payload's SHA-256 (so a truncated
or corrupted file is a clear error, not garbage weights) and free-form ``meta`` (training data
hash, epoch, loss, config, scale fit, ...). Writes are atomic (temporary file + rename): a run
killed while saving leaves the previous checkpoint intact. Save → load is bit-identical.

Public: :func:`save_model`, :func:`load_model` (what ``dynamics=<path>`` in the envs uses),
:func:`read_header`, :class:`CheckpointError` (also in :mod:`furuta_gym.models`); the training
loop also uses :func:`save_training_state` / :func:`load_training_state`. It lives with the
models so that envs and the diagnosis load a checkpoint without depending on training.
"""

from __future__ import annotations

import datetime
import hashlib
import io
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from .._versions import installed_versions
from ..systems import get_spec
from ._factory import MODEL_KINDS, make_model
from ._learned import AbstractLearnedSystem

__all__ = [
    "CheckpointError",
    "save_model",
    "load_model",
    "read_header",
    "save_training_state",
    "load_training_state",
    "package_versions",
]

MAGIC = b"FURUTA-GYM-CHECKPOINT 1\n"


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: corrupt, not a checkpoint, or for another system/kind."""


def package_versions() -> dict[str, str]:
    """Versions of the packages a checkpoint depends on (recorded in every header)."""
    return installed_versions(("furuta-gym", "jax", "jaxlib", "equinox", "diffrax", "optax", "numpy"))


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    return value


def _tuplify(value):
    if isinstance(value, list):
        return tuple(_tuplify(v) for v in value)
    return value


def _write(path: Path, header: dict, tree: Any, overwrite: bool, sync: bool = True) -> None:
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: already exists; pass overwrite=True to replace it")
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, tree)
    payload = buf.getvalue()
    header = dict(header)
    header["payload_sha256"] = hashlib.sha256(payload).hexdigest()
    header["payload_bytes"] = len(payload)
    line = json.dumps(_jsonable(header), separators=(",", ":"), allow_nan=True).encode()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(MAGIC)
            fh.write(line + b"\n")
            fh.write(payload)
            if sync:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _read(path: Path) -> tuple[dict, bytes]:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such checkpoint file")
    raw = path.read_bytes()
    if not raw.startswith(MAGIC):
        raise CheckpointError(f"{path}: not a furuta-gym checkpoint (missing the header line)")
    rest = raw[len(MAGIC) :]
    end = rest.find(b"\n")
    if end < 0:
        raise CheckpointError(f"{path}: corrupt checkpoint (truncated JSON header)")
    try:
        header = json.loads(rest[:end].decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{path}: corrupt checkpoint header ({exc})") from None
    payload = rest[end + 1 :]
    if hashlib.sha256(payload).hexdigest() != header.get("payload_sha256"):
        raise CheckpointError(
            f"{path}: corrupt checkpoint: the weights do not match the header's checksum "
            f"({len(payload)} bytes, expected {header.get('payload_bytes')})"
        )
    return header, payload


def read_header(path: str | Path) -> dict:
    """The JSON header of a checkpoint (validated against its payload checksum)."""
    return _read(Path(path))[0]


def _model_header(model, meta: dict | None) -> dict:

    if not isinstance(model, AbstractLearnedSystem):
        raise TypeError(
            f"save_model saves learned models (DeLaN, Aphynity, AugmentedDeLaN); got {type(model).__name__}"
        )
    return {
        "content": "model",
        "format": HEADER_FORMAT,
        "system": model.spec.name,
        "model_kind": model.kind,
        "hparams": model.hyperparameters,
        "versions": package_versions(),
        "saved_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "meta": dict(meta or {}),
    }


#: The header's form. 2: ``hparams`` holds every hyper-parameter the model was built with.
#: 1 (a header without ``"format"``): written before some F_a options existed; where such a
#: header is silent, the model was built as its kind's ``form_1_hparams`` says.
HEADER_FORMAT = 2


def _skeleton(header: dict, path: Path, expected_system: str | None, expected_kind: str | None = None):

    system, kind = header.get("system"), header.get("model_kind")
    if expected_system is not None:
        want = get_spec(expected_system).name
        if system != want:
            raise CheckpointError(f"{path}: this checkpoint is a {system!r} model; expected a {want!r} model")
    if expected_kind is not None and kind != expected_kind:
        raise CheckpointError(f"{path}: this checkpoint is a {kind!r} model; expected {expected_kind!r}")
    if kind not in MODEL_KINDS:
        raise CheckpointError(f"{path}: unknown model kind {kind!r} in header")
    if not isinstance(system, str):
        raise CheckpointError(f"{path}: the header names no system")
    hparams = {k: _tuplify(v) for k, v in header.get("hparams", {}).items()}
    form = header.get("format", 1)
    if form not in (1, HEADER_FORMAT):
        raise CheckpointError(
            f"{path}: checkpoint header format {form!r}; this furuta-gym reads formats 1 and "
            f"{HEADER_FORMAT} (a newer version wrote it?)"
        )
    if form == 1:
        # what its model was trained with: back-EMF in APHYNITY's prior, no linear W, F_a even in q̇, tanh
        hparams = MODEL_KINDS[kind].form_1_hparams(hparams)
    try:
        return make_model(system, kind, jax.random.PRNGKey(0), **hparams)
    except (ValueError, TypeError) as exc:
        raise CheckpointError(f"{path}: cannot rebuild the model from its header: {exc}") from None


def save_model(path: str | Path, model, meta: dict | None = None, *, overwrite: bool = False) -> Path:
    """Save a learned model (weights + JSON header with system, kind, hyper-parameters, ``meta``).

    ``meta`` is free-form JSON (e.g. training data hash, epoch, losses). Refuses to replace an
    existing file unless ``overwrite``. Returns the path.
    """
    path = Path(path)
    _check_finite(model, path)
    _write(path, _model_header(model, meta), model, overwrite)
    return path


def load_model(path: str | Path, expected_system: str | None = None):
    """Load a model saved by :func:`save_model` (or the model inside a training state).

    ``expected_system`` ("furuta" / "nmsd"): loading a checkpoint of the other system raises
    :class:`CheckpointError` naming both. A missing file raises FileNotFoundError; a corrupt or
    foreign file raises CheckpointError.
    """
    path = Path(path)
    header, payload = _read(path)
    skeleton = _skeleton(header, path, expected_system)
    try:
        if header.get("content") == "training_state":
            # payload is (model, opt_state): read the model part only
            model, _ = _deserialise_prefix(payload, skeleton)
            return model
        if header.get("content") != "model":
            raise CheckpointError(f"{path}: unknown checkpoint content {header.get('content')!r}")
        return eqx.tree_deserialise_leaves(io.BytesIO(payload), skeleton)
    except CheckpointError:
        raise
    except Exception as exc:  # shape/dtype mismatch: the header does not describe these weights
        raise CheckpointError(f"{path}: weights do not fit the model described by its header ({exc})") from None


def _deserialise_prefix(payload: bytes, skeleton):
    buf = io.BytesIO(payload)
    model = eqx.tree_deserialise_leaves(buf, skeleton)
    return model, buf


def _check_finite(tree, path) -> None:

    leaves = [l for l in jax.tree_util.tree_leaves(eqx.filter(tree, eqx.is_inexact_array))]
    if not all(bool(jnp.all(jnp.isfinite(l))) for l in leaves):
        raise ValueError(f"{path}: refusing to save a model with NaN/inf weights")


def save_training_state(path: str | Path, model, opt_state, header_extra: dict, best_model=None) -> Path:
    """Save a resumable training state: model + optimiser state + JSON (epoch, λ, history, seed...),
    and ``best_model`` (the running stage's lowest-loss iterate) when there is one."""
    path = Path(path)
    _check_finite(model, path)
    header = _model_header(model, header_extra.pop("meta", None))
    header["content"] = "training_state"
    header["state"] = header_extra
    header["has_best_model"] = best_model is not None
    payload = (model, opt_state) if best_model is None else (model, opt_state, best_model)
    # no fsync: written after every epoch, and the rename is atomic against a killed process
    _write(path, header, payload, overwrite=True, sync=False)
    return path


def load_training_state(
    path: str | Path, model_skeleton, opt_state_skeleton, *, with_best: bool = False
) -> tuple[Any, ...]:
    """(model, opt_state, header) from :func:`save_training_state`; skeletons give the structure.
    ``with_best``: (model, opt_state, header, best model or None)."""
    path = Path(path)
    header, payload = _read(path)
    if header.get("content") != "training_state":
        raise CheckpointError(f"{path}: not a training state (content {header.get('content')!r})")
    has_best = bool(header.get("has_best_model", False))
    skeleton = (model_skeleton, opt_state_skeleton) + ((model_skeleton,) if has_best else ())
    try:
        loaded = eqx.tree_deserialise_leaves(io.BytesIO(payload), skeleton)
    except Exception as exc:
        raise CheckpointError(f"{path}: training state does not fit this run's model/optimiser ({exc})") from None
    model, opt_state = loaded[:2]
    if with_best:
        return model, opt_state, header, (loaded[2] if has_best else None)
    return model, opt_state, header
