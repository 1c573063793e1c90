"""The metadata of a checkpoint, typed: what ``python -m model.train`` and ``python -m
model.calibrate`` write and every reader reads (:class:`CheckpointMeta`).

In the file it stays the plain dict it always was (``payload["metadata"]``, JSON data, and
``model.checkpoint_metadata`` of a loaded model); :meth:`CheckpointMeta.from_dict` reads any
such dict (an older checkpoint's, or one with keys this code does not know, which are kept in
:attr:`CheckpointMeta.extra` and written back as they were) and :meth:`CheckpointMeta.to_dict`
writes it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

_ALWAYS = ("train_config", "data", "step", "epoch", "val_mAP_3d")
"""Keys a training run always writes (None included), in the order of the file."""


@dataclass(frozen=True)
class CheckpointMeta:
    """A checkpoint's metadata.

    Attributes:
        train_config: The run's :class:`model.training.config.TrainConfig` as a dict.
        data: The training data: ``root``, ``roots``, ``train_samples``.
        step, epoch: Where the run was when it wrote the checkpoint.
        val_mAP_3d: The last validation's 3D mAP (None: not validated).
        operating_threshold: The answer set's threshold chosen by ``python -m model.calibrate``
            (None: uncalibrated).
        operating_threshold_source: Where it was chosen: ``root``, ``split``, ``prompts``,
            ``set_f1``, ``exact_set``.
        training_stages: How the checkpoint was made, as written beside it (free text).
        extra: Any other key of the file, kept as it was.
    """

    train_config: Mapping[str, Any] | None = None
    data: Mapping[str, Any] | None = None
    step: int | None = None
    epoch: int | None = None
    val_mAP_3d: float | None = None  # noqa: N815 (the file's key)
    operating_threshold: Any = None
    operating_threshold_source: Mapping[str, Any] | None = None
    training_stages: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None) -> CheckpointMeta:
        """The metadata of a file's (or a model's) dict; unknown keys go to :attr:`extra`."""
        data = dict(data or {})
        known = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        given = {k: data.pop(k) for k in list(data) if k in known}
        return cls(**given, extra=data)

    @classmethod
    def of(cls, model: object) -> CheckpointMeta:
        """The metadata of a loaded model (``model.checkpoint_metadata``; empty for another)."""
        return cls.from_dict(getattr(model, "checkpoint_metadata", None))

    def to_dict(self) -> dict[str, Any]:
        """The file's dict: a training run's keys when they were given, the others when set,
        then :attr:`extra`."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name == "extra":
                continue
            value = getattr(self, f.name)
            if value is not None or (f.name in _ALWAYS and self.train_config is not None):
                out[f.name] = dict(value) if isinstance(value, Mapping) else value
        out.update(self.extra)
        return out

    def replace(self, **changes: Any) -> CheckpointMeta:
        """A copy with ``changes``."""
        return dataclasses.replace(self, **changes)


__all__ = ["CheckpointMeta"]
