"""Saved prompt-to-box pairs in a Talk2Radar root: create, reopen, edit, delete, never lose one.

Each saved pair is one new sample of the root (the Talk2Radar unit: one frame's sensors, one prompt,
the boxes it refers to), written with the pieces of :class:`scenes.root.Talk2RadarWriter`:
sensor files hard-linked (or copied) from the source frame, calibration, ``label_2`` in the camera
frame with projected 2D boxes, ``prompt/<id>.txt`` in the LiDAR and the radar tree, and the
``meta/<id>.json`` sidecar (type tags, actors with velocities, annotator). The id becomes visible by
being appended to ``ImageSets/<split>.txt``; every change is recorded as one JSON line in
``<root>/annotations/manifest.jsonl`` (see ``docs/ANNOTATION.md`` for the format).

Consistency rules:

- **Atomic files.** Every file is written to a temporary file, fsynced and renamed over the target;
  a reader sees the old or the new content, never a part.
- **Commit point.** A sample exists for readers once its id is in ``lidar/ImageSets/<split>.txt``
  (:class:`scenes.root.Talk2RadarRoot` reads the LiDAR tree's lists). A save writes the sample's
  files first, then the radar tree's list, then the LiDAR tree's list (the commit), then the
  manifest line. A deletion removes the id from the LiDAR tree's lists first.
- **Journal.** Before touching the root, an operation writes ``annotations/pending/<op>.json``
  with what it is about to do (and, for an edit, the old contents of every file it replaces). It
  removes the journal when done. A journal found later (a crash, a kill, a full disk) is resolved
  under the lock before any other operation and when a store opens: an operation that passed its
  commit point is completed (lists of both trees, manifest line); one that did not is undone (a new
  sample's files are deleted, an edit's old files are restored). Orphan files that no journal
  claims are never listed and never reused: ids are allocated beyond every id found anywhere.
- **Locking.** Operations on one root are serialised by an in-process lock (threads of one server)
  and ``fcntl.flock`` on ``annotations/.lock`` (other processes). Ids are allocated under the lock,
  above the highest id in any ImageSets list, sample folder, sidecar, the manifest and pending
  journals, so concurrent clients always get distinct ids.
- **Manifest.** Lines are appended with ``O_APPEND`` and fsynced; a failed append is truncated
  back, and a torn last line (a kill in the middle of a write) is skipped by the reader and
  terminated before the next append. Edits record the previous prompt and label text, deletions
  too, so every version stays in the manifest.
- **Errors.** A full disk (``ENOSPC``) or any other failure during an operation is undone as above
  and raised as :class:`DiskFullError` / :class:`SaveError`: nothing half-visible, earlier pairs
  untouched. An invalid draft raises :class:`annotate.validation.ValidationError` and a split the
  store does not offer (:attr:`AnnotationStore.splits`: train, val, test by default) raises
  :class:`SplitError`, both before anything is written. Every other filesystem error of a store
  method (a read-only root, an unreadable list) is a :class:`StoreError` with a one-line message;
  never a bare ``OSError``.
- **Nothing blocks the store.** A journal that recovery cannot resolve (unreadable, or its undo
  fails for a reason other than a full disk) is moved to ``annotations/unresolved/`` with a logged
  warning, and the store carries on (its id stays reserved). While the disk is full, an interrupted
  edit that still needs its old files written back keeps its journal and every operation raises
  :class:`DiskFullError` until space is freed; then the next operation finishes the undo.
"""

from __future__ import annotations

import contextlib
import enum
import errno
import hashlib
import json
import logging
import os
import re
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from annotate.draft import Draft
from annotate.suggest import SuggestConfig, scene_actors
from annotate.validation import Issue, ValidationConfig, validate
from scenes.actors import CLASSES
from scenes.calib import read_calib, vod_radar_calibration
from scenes.kitti import (
    ObjectLabel,
    atomic_write_text,
    boxes_to_labels,
    format_label_line,
    labels_to_boxes,
    read_label_file,
)
from scenes.prompts import infer_tags
from scenes.root import (
    RADAR_FOLDERS,
    Sample,
    SampleMeta,
    SensorFiles,
    Talk2RadarRoot,
    Talk2RadarWriter,
    format_id,
)
from scenes.textfile import read_text_file

try:  # POSIX only; elsewhere the in-process lock alone serialises writers.
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

MANIFEST_FORMAT = 1
"""Version of the manifest line format (the ``format`` field)."""

LABEL_DECIMALS = 6
"""Decimals of the numbers in written ``label_2`` lines (as :class:`Talk2RadarWriter`)."""

_SAMPLE_FOLDERS = ("velodyne", "calib", "label_2", "prompt")
_SPLIT_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")

DEFAULT_SPLITS: tuple[str, ...] = ("train", "val", "test")
"""The splits a store offers unless told otherwise (:attr:`AnnotationStore.splits`)."""

log = logging.getLogger(__name__)


class StoreError(RuntimeError):
    """An annotation store operation failed; the message says what and what to do."""


class SaveError(StoreError):
    """A save, edit or delete failed and was undone (or will be completed: see the message)."""


class DiskFullError(SaveError):
    """The disk filled up during an operation; it was undone and nothing is half-visible."""


class ConflictError(StoreError):
    """The pair changed since the draft was opened (another client saved or deleted it)."""


class SplitError(StoreError, ValueError):
    """The split to save into is not one the store offers (nothing was written)."""


class Action(enum.Enum):
    """What a manifest line records."""

    CREATE = "create"
    EDIT = "edit"
    DELETE = "delete"


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

    def to_json(self) -> dict:
        """A JSON-serialisable dict (one manifest line)."""
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
        )


@dataclass(frozen=True)
class ManifestLog:
    """A parsed manifest: the records, and the lines that could not be read (line number, why)."""

    records: tuple[ManifestRecord, ...]
    skipped: tuple[tuple[int, str], ...] = ()


def read_manifest(path: str | Path) -> ManifestLog:
    """Read a manifest (a missing file is empty). Unreadable lines (a torn last line after a kill)
    are skipped and reported in :attr:`ManifestLog.skipped`, never fatal."""
    path = Path(path)
    if not path.is_file():
        return ManifestLog(())
    records, skipped = [], []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for lineno, line in enumerate(handle, start=1):
            if not line.strip():
                continue
            try:
                records.append(ManifestRecord.from_json(json.loads(line)))
            except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
                skipped.append((lineno, f"{path}:{lineno}: unreadable manifest line ({exc})"))
    return ManifestLog(tuple(records), tuple(skipped))


def append_manifest_line(path: Path, line: str) -> None:
    """Append one line to a JSON Lines file (O_APPEND, fsync).

    A missing newline at the end of the file (a torn line) is added first, so the new line stands
    alone; if the write fails the file is truncated back to its former size.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        size = os.fstat(fd).st_size
        prefix = b""
        if size and os.pread(fd, 1, size - 1) != b"\n":
            prefix = b"\n"
        data = prefix + line.encode("utf-8") + b"\n"
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except BaseException:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, size)
            raise
    finally:
        os.close(fd)


@dataclass(frozen=True)
class SourceFrame:
    """The frame a new pair is annotated on.

    Attributes:
        key: A readable name of the frame (recorded in the manifest; names the ``sources/``
            folder when the sensors must be written).
        sample: Its sensors (LiDAR frame), calibrations and sidecar.
        files: Sensor files on disk to hard-link (or copy); None writes ``sample``'s arrays under
            ``<root>/sources/`` once and links those.
        root: The root the frame was read from, if any.
        sample_id: Its id there, if any.
    """

    key: str
    sample: Sample
    files: SensorFiles | None = None
    root: str | None = None
    sample_id: str | None = None

    @staticmethod
    def from_root(
        root: Talk2RadarRoot | str | Path, sample_id: str | int, sample: Sample | None = None
    ) -> SourceFrame:
        """A frame of a Talk2Radar root; its sensor files are linked, not rewritten.

        ``sample`` is the frame already loaded from that root (read again when None).
        """
        r = root if isinstance(root, Talk2RadarRoot) else Talk2RadarRoot(root)
        sid = format_id(sample_id)
        sample = sample if sample is not None else r.load(sid)
        files = None
        if r.radar_dir is not None:
            files = SensorFiles(
                folder=r.path,
                lidar_bin=r.lidar_dir / "training" / "velodyne" / f"{sid}.bin",
                radar_bin=r.radar_dir / "training" / "velodyne" / f"{sid}.bin",
                lidar_calib=r.lidar_dir / "training" / "calib" / f"{sid}.txt",
                radar_calib=r.radar_dir / "training" / "calib" / f"{sid}.txt",
            )
        return SourceFrame(f"{r.path.name}/{sid}", sample, files, str(r.path.resolve()), sid)

    @staticmethod
    def from_sample(sample: Sample, key: str | None = None) -> SourceFrame:
        """A frame held in memory (e.g. generated on the fly); its sensors get written once."""
        return SourceFrame(key or f"frame-{sample.sample_id}", sample, None, None, sample.sample_id)

    def describe(self) -> dict:
        """The manifest's ``source`` field."""
        return {"key": self.key, "root": self.root, "sample_id": self.sample_id}


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


@dataclass(frozen=True)
class SaveResult:
    """What a create or edit wrote: the sample id, the new version, the manifest line, and the
    validation warnings (shown, not blocking)."""

    sample_id: str
    version: int
    record: ManifestRecord
    warnings: tuple[Issue, ...] = ()


_PROCESS_LOCKS: dict[str, threading.Lock] = {}
_PROCESS_LOCKS_GUARD = threading.Lock()


def _process_lock(path: Path) -> threading.Lock:
    key = str(path.resolve())
    with _PROCESS_LOCKS_GUARD:
        return _PROCESS_LOCKS.setdefault(key, threading.Lock())


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _is_disk_full(exc: BaseException) -> bool:
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        seen.add(id(cur))
        if isinstance(cur, OSError) and cur.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        cur = cur.__cause__ or cur.__context__
    return False


def _label_text(labels: Sequence[ObjectLabel]) -> str:
    return "".join(format_label_line(lab, LABEL_DECIMALS) + "\n" for lab in labels)


def _int_or_none(text: str) -> int | None:
    text = text.strip()
    return int(text) if text.isdigit() else None


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class AnnotationStore:
    """Saved prompt-to-box pairs of one Talk2Radar root (module docstring for the guarantees).

    Args:
        root: The root folder; created (``lidar/`` and a radar tree) when missing.
        radar_folder: Radar tree to write; default the one the root has, else ``radar_5frames``.
            A root that already has another radar tree is refused (readers would pick the other).
        validation: Rules checked before every save.
        lock_timeout: Seconds to wait for another writer before :class:`StoreError`.
        clock: Returns the time written to the manifest (ISO 8601 text); default UTC now.
        splits: The splits a pair may be saved into (default :data:`DEFAULT_SPLITS`); names of
            letters, digits, ``_``, ``-`` and ``.``, at most 64 characters.

    Raises:
        StoreError: the root cannot be prepared (e.g. read-only), or another radar tree is there.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        radar_folder: str | None = None,
        validation: ValidationConfig | None = None,
        lock_timeout: float = 30.0,
        clock: Callable[[], str] = _utc_now,
        splits: Sequence[str] | None = None,
    ) -> None:
        self.path = Path(root)
        self.splits: tuple[str, ...] = tuple(DEFAULT_SPLITS if splits is None else splits)
        for name in self.splits:
            _check_split_name(name)
        present = [name for name in RADAR_FOLDERS if (self.path / name).is_dir()]
        if radar_folder is None:
            radar_folder = present[0] if present else RADAR_FOLDERS[0]
        elif present and radar_folder != present[0]:
            raise StoreError(
                f"{self.path}: the root has the radar tree {present[0]!r}; "
                f"cannot write {radar_folder!r} beside it"
            )
        self.writer = Talk2RadarWriter(self.path, radar_folder)
        self.lidar_dir, self.radar_dir = self.writer.trees
        self.annotations_dir = self.path / "annotations"
        self.manifest_path = self.annotations_dir / "manifest.jsonl"
        self.journal_dir = self.annotations_dir / "pending"
        self.unresolved_dir = self.annotations_dir / "unresolved"
        self.validation = validation if validation is not None else ValidationConfig()
        self.lock_timeout = float(lock_timeout)
        self.clock = clock
        with _fs_errors(f"opening the annotation store {self.path}"):
            for folder in (
                self.lidar_dir / "ImageSets",
                self.radar_dir / "ImageSets",
                self.journal_dir,
            ):
                folder.mkdir(parents=True, exist_ok=True)
            self._thread_lock = _process_lock(self.path)
            with self._locked():
                try:
                    self._recover_all()
                except DiskFullError as exc:  # the next operation retries, once there is space
                    log.warning("%s", exc)

    def __repr__(self) -> str:
        return f"AnnotationStore({str(self.path)!r})"

    # ---------------------------------------------------------------- locking

    @contextlib.contextmanager
    def _locked(self) -> Iterator[None]:
        if not self._thread_lock.acquire(timeout=self.lock_timeout):
            raise StoreError(f"{self.path}: another save is still running; try again")
        try:
            try:
                fd = os.open(self.annotations_dir / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise _fs_error(
                    exc, f"opening the lock file {self.annotations_dir / '.lock'}"
                ) from exc
            try:
                if fcntl is not None:
                    deadline = time.monotonic() + self.lock_timeout
                    while True:
                        try:
                            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                            break
                        except BlockingIOError:
                            if time.monotonic() > deadline:
                                raise StoreError(
                                    f"{self.path}: another process holds the annotation lock "
                                    f"({self.annotations_dir / '.lock'}); try again"
                                ) from None
                            time.sleep(0.01)
                yield
            finally:
                os.close(fd)  # releases the flock
        finally:
            self._thread_lock.release()

    # ---------------------------------------------------------------- reading

    def records(self) -> tuple[ManifestRecord, ...]:
        """Every manifest line, oldest first."""
        with _fs_errors(f"reading the manifest {self.manifest_path}"):
            return read_manifest(self.manifest_path).records

    def history(self, sample_id: str | int) -> tuple[ManifestRecord, ...]:
        """The manifest lines of one pair, oldest first (every version)."""
        sid = format_id(sample_id)
        return tuple(r for r in self.records() if r.sample_id == sid)

    def version(self, sample_id: str | int) -> int:
        """The pair's current version (0 when the manifest never recorded it)."""
        hist = self.history(sample_id)
        return hist[-1].version if hist else 0

    def pairs(self) -> tuple[PairInfo, ...]:
        """The saved pairs that are not deleted, by sample id (latest version each)."""
        latest: dict[str, ManifestRecord] = {}
        for r in self.records():
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

    def splits_of(self, sample_id: str | int) -> tuple[str, ...]:
        """The LiDAR-tree splits whose list holds the sample (empty: not visible)."""
        sid = int(format_id(sample_id))
        out = []
        with _fs_errors(f"reading the split lists of {self.path}"):
            for path in sorted((self.lidar_dir / "ImageSets").glob("*.txt")):
                if any(_int_or_none(line) == sid for line in _read_list(path)):
                    out.append(path.stem)
        return tuple(out)

    def open(self, sample_id: str | int) -> Draft:
        """Reopen a listed sample as a draft for editing (its metric-class boxes and prompt)."""
        sid = format_id(sample_id)
        if not self.splits_of(sid):
            raise StoreError(f"sample {sid} is not listed in any split of {self.path} (deleted?)")
        training = self.lidar_dir / "training"
        calib = read_calib(training / "calib" / f"{sid}.txt")
        labels = self._read_labels(sid)
        boxes, classes = labels_to_boxes(labels, calib)
        prompt = self._read_prompt(sid) or ""
        return Draft.from_boxes(
            boxes,
            classes,
            prompt,
            refers_to_nothing=len(boxes) == 0,
            sample_id=sid,
            base_version=self.version(sid),
        )

    def _read_labels(self, sid: str) -> list[ObjectLabel]:
        path = self.lidar_dir / "training" / "label_2" / f"{sid}.txt"
        if not path.is_file():
            return []
        return read_label_file(path)

    # ---------------------------------------------------------------- operations

    def save(
        self,
        draft: Draft,
        source: SourceFrame | None = None,
        *,
        annotator: str = "anonymous",
        split: str = "train",
    ) -> SaveResult:
        """Create a new pair (``draft.sample_id`` None; needs ``source``) or edit the pair the
        draft was opened from."""
        if draft.sample_id is None:
            if source is None:
                raise ValueError("saving a new pair needs the source frame")
            return self.create(draft, source, annotator=annotator, split=split)
        return self.update(draft, annotator=annotator)

    def create(
        self,
        draft: Draft,
        source: SourceFrame,
        *,
        annotator: str = "anonymous",
        split: str = "train",
    ) -> SaveResult:
        """Add the draft as a new sample listed in ``split``; returns its id and version 1.

        Raises:
            ValidationError: The draft is invalid (nothing written).
            SplitError: ``split`` is not one of :attr:`splits` (nothing written).
            DiskFullError, SaveError: Writing failed (undone; earlier pairs intact).
            StoreError: The root cannot be read or locked.
        """
        self._check_split(split)
        annotator = _clean_annotator(annotator)
        report = validate(draft, self.validation, source.sample.calib)
        report.raise_if_invalid()
        prompt = draft.prompt.strip()
        boxes, classes = draft.box_array, draft.classes
        calib = source.sample.calib
        labels = boxes_to_labels(boxes, list(classes), calib)
        with self._locked(), _fs_errors(f"saving a new pair in {self.path}"):
            self._recover_all()
            sid = format_id(self._next_id())
            op = uuid.uuid4().hex
            record = ManifestRecord(
                action=Action.CREATE,
                sample_id=sid,
                version=1,
                time=self.clock(),
                annotator=annotator,
                op=op,
                splits=(split,),
                prompt=prompt,
                boxes=tuple(tuple(float(v) for v in b) for b in boxes),
                classes=classes,
                refers_to_nothing=draft.refers_to_nothing,
                label_text=_label_text(labels),
                source=source.describe(),
            )
            meta = _build_meta(draft, source.sample, record)
            journal = {"op": op, "action": "create", "sample_id": sid, "splits": [split]}
            journal["record"] = record.to_json()
            self._write_journal(journal)
            try:
                files = source.files if source.files is not None else self._write_source(source)
                self.writer.write_sample(sid, files, boxes, classes, prompt, meta, calib=calib)
                self._sync_sample_dirs()
                self._add_to_split(sid, split)
                append_manifest_line(self.manifest_path, json.dumps(record.to_json()))
            except BaseException as exc:
                self._fail(journal, exc, f"saving pair {sid}")
            self._remove_journal(op)
        return SaveResult(sid, 1, record, report.warnings)

    def update(self, draft: Draft, *, annotator: str = "anonymous") -> SaveResult:
        """Write the draft as a new version of the pair it was opened from.

        The sample's prompt, labels and sidecar are replaced atomically (all new files are
        written and fsynced before the first replaces an old one); the manifest line keeps the
        previous prompt and label text. Labels of non-metric classes in the old file are kept.

        Raises:
            ConflictError: The pair changed since the draft was opened (``draft.base_version``).
            StoreError: The sample is not listed (deleted).
            ValidationError, DiskFullError, SaveError: As :meth:`create`.
        """
        if draft.sample_id is None:
            raise ValueError("this draft is not an opened pair (sample_id is None): use create()")
        sid = format_id(draft.sample_id)
        annotator = _clean_annotator(annotator)
        calib_path = self.lidar_dir / "training" / "calib" / f"{sid}.txt"
        if not calib_path.is_file():
            raise StoreError(f"sample {sid} has no calibration file {calib_path}")
        calib = read_calib(calib_path)
        report = validate(draft, self.validation, calib)
        report.raise_if_invalid()
        prompt = draft.prompt.strip()
        boxes, classes = draft.box_array, draft.classes
        with self._locked(), _fs_errors(f"saving the edit of pair {sid}"):
            self._recover_all()
            splits = self.splits_of(sid)
            if not splits:
                raise StoreError(f"sample {sid} is not listed in any split (deleted?); not saved")
            current = self.version(sid)
            if draft.base_version != current:
                raise ConflictError(_conflict_message(sid, draft.base_version, self.history(sid)))
            old_labels = self._read_labels(sid)
            kept = [lab for lab in old_labels if lab.name.lower() not in _METRIC]
            label_text = _label_text(boxes_to_labels(boxes, list(classes), calib) + kept)
            old_prompt = self._read_prompt(sid)
            old_label_text = self._read_text(self.lidar_dir / "training" / "label_2" / f"{sid}.txt")
            op = uuid.uuid4().hex
            record = ManifestRecord(
                action=Action.EDIT,
                sample_id=sid,
                version=current + 1,
                time=self.clock(),
                annotator=annotator,
                op=op,
                splits=splits,
                prompt=prompt,
                boxes=tuple(tuple(float(v) for v in b) for b in boxes),
                classes=classes,
                refers_to_nothing=draft.refers_to_nothing,
                label_text=label_text,
                source=_last_source(self.history(sid)),
                previous={"version": current, "prompt": old_prompt, "label_text": old_label_text},
            )
            sample = Talk2RadarRoot(self.path, radar=self.writer.radar_folder).load(sid)
            meta = _build_meta(draft, sample, record)
            targets: list[tuple[Path, str]] = [
                (self.path / "meta" / f"{sid}.json", _meta_text(meta))
            ]
            for folder, text in (("prompt", prompt + "\n"), ("label_2", label_text)):
                for tree in self.writer.trees:
                    targets.append((tree / "training" / folder / f"{sid}.txt", text))
            journal = {
                "op": op,
                "action": "edit",
                "sample_id": sid,
                "splits": list(splits),
                "record": record.to_json(),
                "restore": {
                    str(path.relative_to(self.path)): self._read_text(path) for path, _ in targets
                },
            }
            self._write_journal(journal)
            try:
                _replace_all(targets, op)
                self._sync_sample_dirs()
                append_manifest_line(self.manifest_path, json.dumps(record.to_json()))
            except BaseException as exc:
                self._fail(journal, exc, f"saving the edit of pair {sid}")
            self._remove_journal(op)
        return SaveResult(sid, current + 1, record, report.warnings)

    def delete(
        self,
        sample_id: str | int,
        *,
        annotator: str = "anonymous",
        base_version: int | None = None,
    ) -> ManifestRecord:
        """Remove a pair from every split (its files stay on disk, unlisted; its id is never
        reused); the manifest line keeps its last prompt and label text.

        Raises:
            ConflictError: ``base_version`` is given and the pair changed since.
            StoreError: The sample is not listed.
            DiskFullError, SaveError: As :meth:`create`.
        """
        sid = format_id(sample_id)
        annotator = _clean_annotator(annotator)
        with self._locked(), _fs_errors(f"deleting pair {sid}"):
            self._recover_all()
            splits = self.splits_of(sid)
            if not splits:
                raise StoreError(f"sample {sid} is not listed in any split (already deleted?)")
            current = self.version(sid)
            if base_version is not None and base_version != current:
                raise ConflictError(_conflict_message(sid, base_version, self.history(sid)))
            op = uuid.uuid4().hex
            record = ManifestRecord(
                action=Action.DELETE,
                sample_id=sid,
                version=current + 1,
                time=self.clock(),
                annotator=annotator,
                op=op,
                splits=splits,
                source=_last_source(self.history(sid)),
                previous={
                    "version": current,
                    "prompt": self._read_prompt(sid),
                    "label_text": self._read_text(
                        self.lidar_dir / "training" / "label_2" / f"{sid}.txt"
                    ),
                },
            )
            journal = {"op": op, "action": "delete", "sample_id": sid, "splits": list(splits)}
            journal["record"] = record.to_json()
            self._write_journal(journal)
            try:
                for tree in (self.lidar_dir, *self._radar_trees()):  # LiDAR first: the commit
                    for split in splits:
                        self._remove_from_split(tree, sid, split)
                append_manifest_line(self.manifest_path, json.dumps(record.to_json()))
            except BaseException as exc:
                self._fail(journal, exc, f"deleting pair {sid}")
            self._remove_journal(op)
        return record

    def recover(self) -> tuple[str, ...]:
        """Resolve interrupted operations now (also done on open and before every operation).

        Returns one line per journal resolved (``"00012: create rolled back"``, or ``"00012:
        create set aside (...)"`` for one moved to ``annotations/unresolved/``).

        Raises:
            DiskFullError: an interrupted edit cannot be undone until disk space is freed.
        """
        with self._locked(), _fs_errors(f"recovering interrupted operations in {self.path}"):
            return self._recover_all()

    # ---------------------------------------------------------------- internals

    def _radar_trees(self) -> list[Path]:
        return [self.path / n for n in RADAR_FOLDERS if (self.path / n).is_dir()]

    def _all_trees(self) -> list[Path]:
        return [self.lidar_dir, *self._radar_trees()]

    @staticmethod
    def _read_text(path: Path) -> str | None:
        if not path.is_file():
            return None
        return read_text_file(path, "file", StoreError)

    def _read_prompt(self, sid: str) -> str | None:
        text = self._read_text(self.lidar_dir / "training" / "prompt" / f"{sid}.txt")
        return None if text is None else text.strip()

    def _next_id(self) -> int:
        """One above the highest id anywhere in the root (lists, sample folders, sidecars,
        manifest, pending journals), so no id is ever reused."""
        best = -1
        for tree in self._all_trees():
            for path in (tree / "ImageSets").glob("*.txt"):
                for line in _read_list(path):
                    value = _int_or_none(line)
                    if value is not None:
                        best = max(best, value)
            for folder in _SAMPLE_FOLDERS:
                best = max(best, _max_stem(tree / "training" / folder))
        best = max(best, _max_stem(self.path / "meta"))
        for r in self.records():
            best = max(best, int(r.sample_id))
        for folder in (self.journal_dir, self.unresolved_dir):
            for path in folder.glob("*.json"):
                with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
                    best = max(best, int(json.loads(path.read_text())["sample_id"]))
        return best + 1

    def _write_source(self, source: SourceFrame) -> SensorFiles:
        """Write an in-memory frame's sensors under ``sources/`` once (reused when present)."""
        sample = source.sample
        radar_calib = (
            sample.radar_calib if sample.radar_calib is not None else vod_radar_calibration()
        )
        digest = hashlib.sha1(usedforsecurity=False)
        digest.update(np.ascontiguousarray(sample.lidar, dtype="<f4").tobytes())
        digest.update(np.ascontiguousarray(sample.radar, dtype="<f4").tobytes())
        digest.update(sample.calib.to_text().encode())
        digest.update(radar_calib.to_text().encode())
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", source.key).strip("._")[:60] or "frame"
        key = f"{safe}-{digest.hexdigest()[:10]}"
        folder = self.path / "sources" / key
        names = ("lidar.bin", "radar.bin", "lidar_calib.txt", "radar_calib.txt")
        if all((folder / n).is_file() for n in names):
            return SensorFiles(folder, *(folder / n for n in names))
        return self.writer.write_sensors(key, sample.lidar, sample.radar, sample.calib, radar_calib)

    def _sync_sample_dirs(self) -> None:
        for tree in self.writer.trees:
            for folder in _SAMPLE_FOLDERS:
                _fsync_dir(tree / "training" / folder)
        _fsync_dir(self.path / "meta")

    def _split_path(self, tree: Path, split: str) -> Path:
        return tree / "ImageSets" / f"{split}.txt"

    def _in_split(self, tree: Path, sid: str, split: str) -> bool:
        path = self._split_path(tree, split)
        if not path.is_file():
            return False
        return any(_int_or_none(line) == int(sid) for line in _read_list(path))

    def _add_to_split(self, sid: str, split: str) -> None:
        """Append the id to the split's list: radar tree(s) first, the LiDAR tree (commit) last."""
        for tree in (*self._radar_trees(), self.lidar_dir):
            path = self._split_path(tree, split)
            text = read_text_file(path, "split list", StoreError) if path.is_file() else ""
            if any(_int_or_none(line) == int(sid) for line in text.splitlines()):
                continue
            if text and not text.endswith("\n"):
                text += "\n"
            atomic_write_text(path, text + sid + "\n")
            _fsync_dir(path.parent)

    def _remove_from_split(self, tree: Path, sid: str, split: str) -> None:
        path = self._split_path(tree, split)
        if not path.is_file():
            return
        lines = read_text_file(path, "split list", StoreError).splitlines(keepends=True)
        kept = [line for line in lines if _int_or_none(line) != int(sid)]
        if len(kept) != len(lines):
            atomic_write_text(path, "".join(kept))
            _fsync_dir(path.parent)

    def _journal_path(self, op: str) -> Path:
        return self.journal_dir / f"{op}.json"

    def _write_journal(self, journal: dict) -> None:
        try:
            atomic_write_text(self._journal_path(journal["op"]), json.dumps(journal))
        except Exception as exc:
            raise _error(exc, "starting the operation", "nothing was saved") from exc
        _fsync_dir(self.journal_dir)

    def _remove_journal(self, op: str) -> None:
        """Remove a finished operation's journal; a failure is only logged (the operation is
        done, and a journal left behind resolves as "done" next time)."""
        try:
            self._journal_path(op).unlink(missing_ok=True)
        except OSError as exc:
            log.warning("cannot remove the journal %s: %s", self._journal_path(op), exc)
        _fsync_dir(self.journal_dir)

    def _fail(self, journal: dict, exc: BaseException, what: str) -> None:
        """Undo (or complete) an interrupted operation, then raise a clear error.

        Returns normally only when the operation could be completed after all (its commit point
        had passed and the rest succeeded on the second try).
        """
        try:
            outcome = self._resolve(journal)
        except Exception as rec_exc:
            if not isinstance(exc, Exception):
                raise
            raise _error(
                exc,
                what,
                f"it will be resolved the next time the store opens (journal "
                f"{self._journal_path(journal['op'])}; recovery failed: {rec_exc})",
            ) from exc
        self._remove_journal(journal["op"])
        if not isinstance(exc, Exception):
            raise exc
        if outcome == "completed":
            return
        raise _error(exc, what, "nothing was saved; earlier pairs are intact") from exc

    def _resolve(self, journal: Mapping[str, object]) -> str:
        """Complete or undo one journalled operation; returns ``"completed"``, ``"rolled back"``
        or ``"done"`` (it had finished; only the journal was left)."""
        op = str(journal["op"])
        sid = format_id(journal["sample_id"])  # type: ignore[arg-type]
        action = str(journal["action"])
        splits = [str(s) for s in journal.get("splits", ())]  # type: ignore[attr-defined]
        record = journal.get("record")
        if any(r.op == op for r in self.records()):
            return "done"
        if action == "create":
            committed = any(self._in_split(self.lidar_dir, sid, s) for s in splits)
            if committed:
                for s in splits:
                    self._add_to_split(sid, s)
                append_manifest_line(self.manifest_path, json.dumps(record))
                return "completed"
            for tree in self._radar_trees():
                for s in splits:
                    self._remove_from_split(tree, sid, s)
            self._remove_sample_files(sid)
            return "rolled back"
        if action == "edit":
            restore = journal.get("restore") or {}
            targets = []
            for rel, text in restore.items():  # type: ignore[union-attr]
                path = self.path / rel
                if text is None:
                    path.unlink(missing_ok=True)
                elif not _holds(path, str(text)):  # unchanged files need no writing back
                    targets.append((path, str(text)))
            _replace_all(targets, op)
            self._remove_temporaries(sid)
            return "rolled back"
        if action == "delete":
            committed = any(not self._in_split(self.lidar_dir, sid, s) for s in splits)
            if not committed:
                return "rolled back"
            for tree in self._all_trees():
                for s in splits:
                    self._remove_from_split(tree, sid, s)
            append_manifest_line(self.manifest_path, json.dumps(record))
            return "completed"
        raise StoreError(f"unknown action {action!r} in journal {self._journal_path(op)}")

    def _remove_sample_files(self, sid: str) -> None:
        for tree in self._all_trees():
            for folder, ext in zip(_SAMPLE_FOLDERS, ("bin", "txt", "txt", "txt"), strict=True):
                (tree / "training" / folder / f"{sid}.{ext}").unlink(missing_ok=True)
        (self.path / "meta" / f"{sid}.json").unlink(missing_ok=True)
        self._remove_temporaries(sid)

    def _remove_temporaries(self, sid: str) -> None:
        folders = [self.path / "meta"]
        folders += [t / "training" / f for t in self._all_trees() for f in _SAMPLE_FOLDERS]
        for folder in folders:
            for tmp in folder.glob(f".{sid}.*.tmp*"):
                tmp.unlink(missing_ok=True)

    def _recover_all(self) -> tuple[str, ...]:
        """Resolve every pending journal (under the lock); also sweep stale temporary lists.

        A journal that cannot be resolved is set aside (:meth:`_set_aside`) and never blocks the
        store; one whose undo needs disk space that is missing stays, and :class:`DiskFullError`
        is raised after the others are resolved.
        """
        done: list[str] = []
        full: list[str] = []
        journals = []
        for path in self.journal_dir.glob("*.json"):
            with contextlib.suppress(OSError):  # vanished meanwhile
                journals.append((path.stat().st_mtime, path))
        for _, path in sorted(journals):
            try:
                journal = json.loads(read_text_file(path, "journal", StoreError))
                if not isinstance(journal, dict):
                    raise StoreError(f"{path}: the journal is not a JSON object")
                what = f"{format_id(journal['sample_id'])}: {journal['action']}"
                outcome = self._resolve(journal)
                path.unlink(missing_ok=True)
                done.append(f"{what} {outcome}")
            except Exception as exc:
                if _is_disk_full(exc):
                    full.append(path.name)
                    continue
                done.append(self._set_aside(path, exc))
        with contextlib.suppress(OSError):
            for folder in (self.journal_dir, *(t / "ImageSets" for t in self._all_trees())):
                for tmp in folder.glob(".*.tmp*"):
                    tmp.unlink(missing_ok=True)
        if done:
            _fsync_dir(self.journal_dir)
        if full:
            raise DiskFullError(
                f"the disk is full: {len(full)} interrupted operation(s) in {self.journal_dir} "
                f"cannot be undone yet ({', '.join(full)}); nothing else was changed. Free some "
                "space and try again."
            )
        return tuple(done)

    def _set_aside(self, path: Path, exc: BaseException) -> str:
        """Move a journal recovery cannot resolve to ``annotations/unresolved/`` (its id stays
        reserved) and log a warning; returns the line :meth:`recover` reports."""
        why = _one_line(f"{type(exc).__name__}: {exc}")
        target = self.unresolved_dir / path.name
        try:
            self.unresolved_dir.mkdir(parents=True, exist_ok=True)
            os.replace(path, target)
            _fsync_dir(self.journal_dir)
            where = f"moved to {target}"
        except OSError as move_exc:
            where = f"left in place: cannot move it ({move_exc.strerror or move_exc})"
        log.warning(
            "%s: an interrupted operation could not be resolved (%s); %s; the store carries on, "
            "check that operation's files by hand",
            path,
            why,
            where,
        )
        return f"{path.stem}: set aside ({why}; {where})"

    def _check_split(self, split: str) -> None:
        """Raise :class:`SplitError` unless ``split`` is one of :attr:`splits`."""
        _check_split_name(split)
        if split not in self.splits:
            raise SplitError(
                f"unknown split {split!r}: {self.path} offers {', '.join(self.splits)}"
            )


_METRIC = {c.lower() for c in CLASSES}


def _max_stem(folder: Path) -> int:
    best = -1
    if folder.is_dir():
        with os.scandir(folder) as it:
            for entry in it:
                stem = entry.name.split(".", 1)[0]
                if stem.isdigit():
                    best = max(best, int(stem))
    return best


def _replace_all(targets: Sequence[tuple[Path, str]], op: str) -> None:
    """Write every ``(path, text)`` to a temporary file (fsynced) first, then rename each over its
    target: a full disk stops the first phase, before any target changed."""
    staged: list[tuple[Path, Path]] = []
    try:
        for path, text in targets:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.tmp-{op[:12]}")
            staged.append((tmp, path))
            with open(tmp, "w", encoding="utf-8") as handle:
                handle.write(text)
                handle.flush()
                os.fsync(handle.fileno())
        for tmp, path in staged:
            os.replace(tmp, path)
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)


def _meta_text(meta: SampleMeta) -> str:
    return json.dumps(meta.to_json(), indent=1)


def _build_meta(draft: Draft, sample: Sample, record: ManifestRecord) -> SampleMeta:
    """The sidecar of a saved pair: keyword type tags of the prompt, the draft boxes as actors
    (ids ``0..K-1``, velocities from the frame's known actors or its radar) plus the frame's other
    known actors, and the annotation facts in ``extra``."""
    base = sample.meta
    actors = scene_actors(
        draft.box_array,
        draft.classes,
        base.actors if base is not None else (),
        sample.radar,
        SuggestConfig(),
    )
    extra = dict(base.extra) if base is not None else {}
    extra.update(
        {
            "annotator": record.annotator,
            "annotated_at": record.time,
            "version": record.version,
            "source": dict(record.source),
            "refers_to_nothing": record.refers_to_nothing,
        }
    )
    return SampleMeta(
        tags=infer_tags(draft.prompt.strip()),
        actors=actors.all,
        referent_ids=tuple(a.actor_id for a in actors.referents),
        weather=base.weather if base is not None else "clear",
        ego_velocity=base.ego_velocity if base is not None else 0.0,
        world_id=base.world_id if base is not None else -1,
        radar_scans=base.radar_scans if base is not None else 5,
        extra=extra,
    )


def _last_source(history: Sequence[ManifestRecord]) -> dict:
    for r in reversed(history):
        if r.source:
            return dict(r.source)
    return {}


def _conflict_message(sid: str, base: int, history: Sequence[ManifestRecord]) -> str:
    last = history[-1] if history else None
    who = f" by {last.annotator} at {last.time}" if last is not None else ""
    return (
        f"pair {sid} was changed{who} (now version {last.version if last else 0}, this draft "
        f"was opened at version {base}); reopen it and apply your changes again"
    )


def _check_split_name(split: object) -> None:
    """Raise :class:`SplitError` for a split name that could not be a file name of ImageSets."""
    if not isinstance(split, str) or not _SPLIT_NAME.fullmatch(split):
        shown = repr(split) if len(repr(split)) <= 40 else repr(split)[:37] + "..."
        raise SplitError(
            f"invalid split name {shown}: use at most 64 letters, digits, '_', '-' or '.' "
            "(e.g. 'train')"
        )


def _holds(path: Path, text: str) -> bool:
    """Whether the file ``path`` exists and holds exactly ``text`` (False when unreadable)."""
    try:
        return path.is_file() and path.read_bytes() == text.encode("utf-8")
    except OSError:
        return False


def _read_list(path: Path) -> list[str]:
    """The lines of an ImageSets list (errors: :class:`StoreError` naming the file)."""
    return read_text_file(path, "split list", StoreError).splitlines()


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _fs_error(exc: OSError | UnicodeError, what: str) -> StoreError:
    """A store error for a filesystem error met while doing ``what``."""
    if _is_disk_full(exc):
        return DiskFullError(f"the disk is full: {what} failed. Free some space and try again.")
    if isinstance(exc, OSError):
        where = f" ({exc.filename})" if exc.filename else ""
        reason = exc.strerror or str(exc)
    else:
        where, reason = "", str(exc)
    return StoreError(_one_line(f"{what} failed{where}: {reason}"))


@contextlib.contextmanager
def _fs_errors(what: str) -> Iterator[None]:
    """Turn a bare ``OSError`` / ``UnicodeError`` raised inside into a :class:`StoreError`."""
    try:
        yield
    except (OSError, UnicodeError) as exc:
        raise _fs_error(exc, what) from exc


def _clean_annotator(name: str) -> str:
    text = " ".join(str(name).split())
    return text or "anonymous"


def _error(exc: BaseException, what: str, outcome: str) -> SaveError:
    if _is_disk_full(exc):
        return DiskFullError(
            f"the disk is full: {what} failed; {outcome}. Free some space and try again."
        )
    return SaveError(f"{what} failed ({type(exc).__name__}: {exc}); {outcome}")


__all__ = [
    "DEFAULT_SPLITS",
    "MANIFEST_FORMAT",
    "Action",
    "AnnotationStore",
    "ConflictError",
    "DiskFullError",
    "ManifestLog",
    "ManifestRecord",
    "PairInfo",
    "SaveError",
    "SaveResult",
    "SourceFrame",
    "SplitError",
    "StoreError",
    "append_manifest_line",
    "read_manifest",
]
