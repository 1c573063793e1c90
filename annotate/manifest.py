"""The manifest: ``annotations/manifest.jsonl``, one JSON line per change of a saved pair.

Lines are appended with ``O_APPEND`` and fsynced (:func:`scenes.utils.durable.append_line`, called in one
place: :meth:`Manifest.append`); a failed append is truncated back, and a torn last line (a kill in
the middle of a write) is skipped by the reader (:func:`read_manifest`, over
:func:`scenes.utils.durable.read_json_lines`) and terminated before the next append. Edits and deletions record the
previous prompt and label text, so every version of a pair stays in the manifest. The line format
is described in ``docs/ANNOTATION.md``; :class:`Manifest` is the store's view of the file (records,
a pair's history and version, the listed pairs).
"""

from __future__ import annotations

import enum
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from annotate.errors import fs_errors
from scenes.talk2radar.layout import format_id
from scenes.utils.durable import append_line, read_json_lines

MANIFEST_FORMAT = 1
"""Version of the manifest line format (the ``format`` field)."""


class Action(enum.Enum):
    """What a manifest line records."""

    CREATE = "create"
    EDIT = "edit"
    DELETE = "delete"
    REVIEW = "review"
    """A reviewer's verdict on a version (:mod:`annotate.review`); the pair is unchanged."""


@dataclass(frozen=True)
class ManifestRecord:
    """One line of ``annotations/manifest.jsonl``.

    Attributes:
        action: create, edit or delete.
        sample_id: The 5-digit id of the pair's sample.
        version: 1 for a create; each edit or delete adds 1.
        time: ISO 8601 UTC time of the operation.
        annotator: Who did it.
        op: Unique operation id (hex).
        splits: The ImageSets splits the sample is (create, edit) or was (delete) listed in.
        prompt: The prompt after the operation (None for a delete).
        boxes: ``K`` boxes ``x, y, z, l, w, h, yaw`` after the operation, LiDAR frame.
        classes: Their classes.
        refers_to_nothing: The prompt refers to no object (``K = 0``).
        label_text: The ``label_2`` file written (None for a delete).
        source: Where the sensors come from: ``key``, ``root`` and ``sample_id`` of the frame.
        previous: For an edit or a delete: ``version``, ``prompt`` and ``label_text`` before.
        format: :data:`MANIFEST_FORMAT`.
        verdict: For a review: ``approved``, ``rejected`` or ``fixed``
            (:data:`scenes.talk2radar.reviews.VERDICTS`); ``version`` is the version reviewed and
            ``annotator`` the reviewer.
        note: For a review: the reviewer's note.
    """

    action: Action
    sample_id: str
    version: int
    time: str
    annotator: str
    op: str
    splits: tuple[str, ...]
    prompt: str | None = None
    boxes: tuple[tuple[float, ...], ...] = ()
    classes: tuple[str, ...] = ()
    refers_to_nothing: bool = False
    label_text: str | None = None
    source: Mapping[str, object] = field(default_factory=dict)
    previous: Mapping[str, object] | None = None
    format: int = MANIFEST_FORMAT
    verdict: str | None = None
    note: str | None = None

    def to_json(self) -> dict:
        """A JSON-serialisable dict (one manifest line; a review's has ``verdict`` and
        ``note`` too)."""
        review = {"verdict": self.verdict, "note": self.note} if self.verdict is not None else {}
        return {
            "format": self.format,
            "op": self.op,
            "action": self.action.value,
            "sample_id": self.sample_id,
            "version": self.version,
            "time": self.time,
            "annotator": self.annotator,
            "splits": list(self.splits),
            "prompt": self.prompt,
            "boxes": [list(b) for b in self.boxes],
            "classes": list(self.classes),
            "refers_to_nothing": self.refers_to_nothing,
            "label_text": self.label_text,
            "source": dict(self.source),
            "previous": None if self.previous is None else dict(self.previous),
            **review,
        }

    @staticmethod
    def from_json(data: Mapping[str, object]) -> ManifestRecord:
        """Inverse of :meth:`to_json`; raises ``KeyError`` / ``ValueError`` / ``TypeError``."""
        previous = data.get("previous")
        return ManifestRecord(
            action=Action(data["action"]),
            sample_id=format_id(data["sample_id"]),
            version=int(data["version"]),
            time=str(data["time"]),
            annotator=str(data["annotator"]),
            op=str(data["op"]),
            splits=tuple(str(s) for s in data.get("splits", ())),
            prompt=None if data.get("prompt") is None else str(data["prompt"]),
            boxes=tuple(tuple(float(v) for v in b) for b in data.get("boxes", ())),
            classes=tuple(str(c) for c in data.get("classes", ())),
            refers_to_nothing=bool(data.get("refers_to_nothing", False)),
            label_text=None if data.get("label_text") is None else str(data["label_text"]),
            source=dict(data.get("source") or {}),
            previous=None if previous is None else dict(previous),
            format=int(data.get("format", MANIFEST_FORMAT)),
            verdict=None if data.get("verdict") is None else str(data["verdict"]),
            note=None if data.get("note") is None else str(data["note"]),
        )


@dataclass(frozen=True)
class ManifestLog:
    """A parsed manifest: the records, and the lines that could not be read (line number, why)."""

    records: tuple[ManifestRecord, ...]
    skipped: tuple[tuple[int, str], ...] = ()


def read_manifest(path: str | Path) -> ManifestLog:
    """Read a manifest (a missing file is empty). Unreadable lines (a torn last line after a kill)
    are skipped and reported in :attr:`ManifestLog.skipped`, never fatal."""
    log = read_json_lines(path, ManifestRecord.from_json)
    return ManifestLog(
        tuple(record for _, record in log.entries),
        tuple(
            (lineno, f"{log.path}:{lineno}: unreadable manifest line ({why})")
            for lineno, why in log.unreadable
        ),
    )


@dataclass(frozen=True)
class PairInfo:
    """A saved pair as listed by :meth:`AnnotationStore.pairs` (its latest manifest line)."""

    sample_id: str
    version: int
    splits: tuple[str, ...]
    prompt: str
    num_boxes: int
    annotator: str
    time: str
    source_key: str | None


class Manifest:
    """The manifest of one store (``path``): reading it and appending to it.

    Every append goes through :meth:`append` (the one place a manifest line is written).
    """

    def __init__(self, path: Path) -> None:
        self.path = path

    def records(self) -> tuple[ManifestRecord, ...]:
        """Every manifest line, oldest first (errors: :class:`~annotate.errors.StoreError`)."""
        with fs_errors(f"reading the manifest {self.path}"):
            return read_manifest(self.path).records

    def history(self, sample_id: str | int) -> tuple[ManifestRecord, ...]:
        """The manifest lines of one pair that changed it, oldest first (every version; its
        reviews are :meth:`reviews`)."""
        sid = format_id(sample_id)
        return tuple(
            r for r in self.records() if r.sample_id == sid and r.action is not Action.REVIEW
        )

    def reviews(self, sample_id: str | int) -> tuple[ManifestRecord, ...]:
        """The review lines of one pair, oldest first."""
        sid = format_id(sample_id)
        return tuple(r for r in self.records() if r.sample_id == sid and r.action is Action.REVIEW)

    def version(self, sample_id: str | int) -> int:
        """The pair's current version (0 when the manifest never recorded it)."""
        hist = self.history(sample_id)
        return hist[-1].version if hist else 0

    def pairs(self) -> tuple[PairInfo, ...]:
        """The saved pairs that are not deleted, by sample id (latest version each)."""
        latest: dict[str, ManifestRecord] = {}
        for r in self.records():
            if r.action is not Action.REVIEW:
                latest[r.sample_id] = r
        out = []
        for sid in sorted(latest):
            r = latest[sid]
            if r.action is Action.DELETE:
                continue
            out.append(
                PairInfo(
                    sample_id=sid,
                    version=r.version,
                    splits=r.splits,
                    prompt=r.prompt or "",
                    num_boxes=len(r.boxes),
                    annotator=r.annotator,
                    time=r.time,
                    source_key=str(r.source["key"]) if r.source.get("key") else None,
                )
            )
        return tuple(out)

    def has_op(self, op: str) -> bool:
        """Whether the operation ``op`` wrote its line (it finished)."""
        return any(r.op == op for r in self.records())

    def append(self, record: Mapping[str, object]) -> None:
        """Append one record (:meth:`ManifestRecord.to_json`)."""
        append_line(self.path, json.dumps(record))


def last_source(history: Sequence[ManifestRecord]) -> dict:
    """The ``source`` of the latest record of a pair that has one (empty when none has)."""
    for r in reversed(history):
        if r.source:
            return dict(r.source)
    return {}


def conflict_message(sid: str, base: int, history: Sequence[ManifestRecord]) -> str:
    """Why an edit of pair ``sid`` opened at version ``base`` is refused."""
    last = history[-1] if history else None
    who = f" by {last.annotator} at {last.time}" if last is not None else ""
    return (
        f"pair {sid} was changed{who} (now version {last.version if last else 0}, this draft "
        f"was opened at version {base}); reopen it and apply your changes again"
    )


__all__ = [
    "MANIFEST_FORMAT",
    "Action",
    "Manifest",
    "ManifestLog",
    "ManifestRecord",
    "PairInfo",
    "conflict_message",
    "last_source",
    "read_manifest",
]
