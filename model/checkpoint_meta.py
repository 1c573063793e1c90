"""The metadata of a checkpoint, typed: what ``python -m model.train`` and ``python -m
model.calibrate`` write and every reader reads (:class:`CheckpointMeta`).

A loaded model holds it as ``model.checkpoint_metadata`` (a :class:`CheckpointMeta`, the only
form the code passes around). In the file it stays the plain dict it always was
(``payload["metadata"]``, JSON data): :meth:`CheckpointMeta.from_dict` reads any such dict (an
older checkpoint's, or one with keys this code does not know, which are kept in
:attr:`CheckpointMeta.extra` and written back as they were) and :meth:`CheckpointMeta.to_dict`
writes it.

Paths: the metadata holds no absolute path of the machine that wrote it. The writers
(``model.train``, ``model.calibrate``) store a path as the user gave it, made relative to the
working folder where it lies under it (:func:`portable_path`: ``data/train-vod-s21``, which
resolves from the repository root as the documented commands are run);
:meth:`CheckpointMeta.with_portable_paths` applies that to every path-like string of a
metadata. Older checkpoints, written with absolute paths, load as they are.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath, PureWindowsPath
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
        class_remap: The run (or, through ``--init``, the ancestor) that started from a
            checkpoint of another class set (``--init-other-classes``): source, both sets, the
            shared classes, the tensors remapped and re-initialised
            (:class:`model.training.class_remap.ClassRemap`); None: none did.
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
    class_remap: Mapping[str, Any] | None = None
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
        """The metadata of a loaded model (``model.checkpoint_metadata``; empty for a model
        without one; a plain dict there, as a stand-in model may hold, is read as the file's)."""
        held = getattr(model, "checkpoint_metadata", None)
        return held if isinstance(held, CheckpointMeta) else cls.from_dict(held)

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

    def with_portable_paths(self, base: str | os.PathLike[str] | None = None) -> CheckpointMeta:
        """A copy whose absolute paths under ``base`` (default: the working folder) are
        relative to it (:func:`portable_path`), in every section (training settings, data,
        threshold source, extra keys)."""
        base_path = Path.cwd() if base is None else Path(base)
        changes = {
            f.name: _portable(getattr(self, f.name), base_path)
            for f in dataclasses.fields(self)
            if f.name not in ("step", "epoch", "val_mAP_3d", "operating_threshold")
        }
        return dataclasses.replace(self, **changes)


def is_machine_path(text: str) -> bool:
    """Whether ``text`` is an absolute path of some machine: ``/...``, ``~...``, ``C:\\...``
    or ``\\\\server\\...``."""
    return text.startswith(("/", "~")) or PureWindowsPath(text).is_absolute()


def portable_path(path: str | os.PathLike[str], base: str | os.PathLike[str] | None = None) -> str:
    """``path`` as the metadata stores it: relative to ``base`` (default: the working folder)
    when it lies under it, else as given (a relative path stays as the user typed it).

    ``portable_path("/work/main/data/x", "/work/main") == "data/x"``.
    """
    text = os.fspath(path)
    if not is_machine_path(text):
        return text
    base_path = Path.cwd() if base is None else Path(base)
    given = Path(text).expanduser()
    for candidate, under in (
        (given.absolute(), base_path.absolute()),
        (given.resolve(), base_path.resolve()),
    ):
        try:
            inside = candidate.relative_to(under)
        except ValueError:
            continue
        return str(PurePosixPath(*inside.parts)) if inside.parts else "."
    return text


def _portable(value: Any, base: Path) -> Any:
    """``value`` (plain data) with every path-like string made portable."""
    if isinstance(value, str):
        return portable_path(value, base) if is_machine_path(value) else value
    if isinstance(value, Mapping):
        return {k: _portable(v, base) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_portable(v, base) for v in value)
    return value


__all__ = ["CheckpointMeta", "is_machine_path", "portable_path"]
