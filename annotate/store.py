"""Saved prompt-to-box pairs in a Talk2Radar root: create, reopen, edit, delete, never lose one.

Each saved pair is one new sample of the root (the Talk2Radar unit: one frame's sensors, one prompt,
the boxes it refers to), written with the pieces of :class:`scenes.talk2radar.writer.Talk2RadarWriter`:
sensor files and camera image hard-linked (or copied) from the source frame, calibration,
``label_2`` in the camera frame with projected 2D boxes, ``prompt/<id>.txt`` in the LiDAR and the
radar tree, and the ``meta/<id>.json`` sidecar (type tags, actors with velocities, annotator). A
create and an edit make the text of these files with the same function
(:func:`scenes.talk2radar.writer.sample_text`), the 2D boxes clipped to the frame's image size. The id becomes visible by
being appended to ``ImageSets/<split>.txt``; every change is recorded as one JSON line in
``<root>/annotations/manifest.jsonl`` (see ``docs/ANNOTATION.md`` for the format).

The parts: :mod:`annotate.manifest` (the manifest), :mod:`annotate.journal` (journals of
interrupted operations), :mod:`annotate.transaction` (locking, the commit point, undo and
completion: the consistency rules), :mod:`annotate.tree` (the root's split lists and sample
files), :mod:`annotate.source` (the frame a pair is made on), :mod:`annotate.pair_files` (a pair's
sidecar), :mod:`annotate.errors`. This module is the public face: :class:`AnnotationStore`.

- **Atomic files.** Every file is written to a temporary file, fsynced and renamed over the target,
  its folder fsynced (:mod:`scenes.utils.durable`); a reader sees the old or the new content, never a
  part.
- **Text.** Prompt and annotator name in the text policy's form (:mod:`scenes.utils.text_policy`).
- **Idempotent saves.** A :meth:`AnnotationStore.save` with the ``request`` key of an earlier one
  (the app's: its draft's version) writes nothing and returns that one's result.
- **Ids.** Allocated under the lock, above the highest id in any ImageSets list, sample folder,
  sidecar, the manifest and pending or set-aside journals, so concurrent clients always get
  distinct ids and no id is ever reused.
- **Errors.** A full disk (``ENOSPC``) or any other failure during an operation is undone and
  raised as :class:`~annotate.errors.DiskFullError` / :class:`~annotate.errors.SaveError`: nothing
  half-visible, earlier pairs untouched. An invalid draft raises
  :class:`annotate.validation.ValidationError` and a split the store does not offer
  (:attr:`AnnotationStore.splits`: train, val, test by default) raises
  :class:`~annotate.errors.SplitError`, both before anything is written. Every other filesystem
  error of a store method (a read-only root, an unreadable list) is a
  :class:`~annotate.errors.StoreError` with a one-line message; never a bare ``OSError``.
"""

from __future__ import annotations

import logging
import re
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

from annotate.draft import Draft
from annotate.errors import ConflictError, DiskFullError, SplitError, StoreError, fs_errors
from annotate.journal import Journals
from annotate.manifest import (
    Action,
    Manifest,
    ManifestRecord,
    PairInfo,
    conflict_message,
    last_source,
)
from annotate.pair_files import frame_image_size, pair_meta
from annotate.requests import RequestLog
from annotate.source import SourceFrame, write_source
from annotate.transaction import Transactions
from annotate.tree import RootFiles
from annotate.validation import (
    Issue,
    ValidationConfig,
    clean_annotator,
    clean_prompt,
    validate,
)
from scenes.frame import Sample
from scenes.frame.kitti import ObjectLabel, labels_to_boxes
from scenes.geometry.calib import read_calib
from scenes.geometry.classes import VOD, ClassSet
from scenes.talk2radar.layout import (
    CALIB,
    RADAR_FOLDERS,
    format_id,
    manifest_file,
    radar_folders_in,
    sample_file,
    split_dir,
)
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.writer import SampleText, Talk2RadarWriter, sample_text
from scenes.utils.durable import replace_files

_SPLIT_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")

DEFAULT_SPLITS: tuple[str, ...] = ("train", "val", "test")
"""The splits a store offers unless told otherwise (:attr:`AnnotationStore.splits`)."""

REMEMBERED_REQUESTS = 256
"""Successful save requests a store remembers (:meth:`AnnotationStore.save`)."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SaveResult:
    """What a create or edit wrote: the sample id, the new version, the manifest line, and the
    validation warnings (shown, not blocking)."""

    sample_id: str
    version: int
    record: ManifestRecord
    warnings: tuple[Issue, ...] = ()
    repeated: bool = False
    """A repeated request (:meth:`AnnotationStore.save`): nothing was written this time."""


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class AnnotationStore:
    """Saved prompt-to-box pairs of one Talk2Radar root (module docstring for the guarantees).

    Args:
        root: The root folder. Opening writes nothing (a missing root has no pairs; only an
            interrupted operation is resolved): the first save creates it, its split lists and
            ``annotations/`` (lock, journals, manifest).
        radar_folder: Radar tree to write; default the one the root has, else ``radar_5frames``.
            A root that already has another radar tree is refused (readers would pick the other).
        validation: Rules checked before every save.
        classes: The pairs' class set (the served model's); an edit keeps the other labels.
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
        classes: ClassSet = VOD,
    ) -> None:
        self.path = Path(root)
        self.classes = classes
        self.splits: tuple[str, ...] = tuple(DEFAULT_SPLITS if splits is None else splits)
        for name in self.splits:
            _check_split_name(name)
        present = radar_folders_in(self.path)
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
        self.manifest_path = manifest_file(self.path)
        self.journal_dir = self.annotations_dir / "pending"
        self.unresolved_dir = self.annotations_dir / "unresolved"
        self.validation = validation if validation is not None else ValidationConfig()
        self.lock_timeout = float(lock_timeout)
        self.clock = clock
        self.requests: RequestLog[SaveResult] = RequestLog(REMEMBERED_REQUESTS)
        """Save requests by key (:meth:`save`)."""
        self.files = RootFiles(self.path, self.lidar_dir)
        self.manifest = Manifest(self.manifest_path)
        self.journals = Journals(self.journal_dir, self.unresolved_dir)
        self.transactions = Transactions(
            self.files,
            self.manifest,
            self.journals,
            self.annotations_dir / ".lock",
            self.lock_timeout,
        )
        with fs_errors(f"opening the annotation store {self.path}"):
            if self.journals.pending():  # an interrupted operation: resolve it now
                with self.transactions.locked():
                    try:
                        self.transactions.recover_all()
                    except DiskFullError as exc:  # the next operation retries, once there is space
                        log.warning("%s", exc)

    def __repr__(self) -> str:
        return f"AnnotationStore({str(self.path)!r})"

    # ---------------------------------------------------------------- reading

    def records(self) -> tuple[ManifestRecord, ...]:
        """Every manifest line, oldest first."""
        return self.manifest.records()

    def history(self, sample_id: str | int) -> tuple[ManifestRecord, ...]:
        """The manifest lines of one pair, oldest first (every version)."""
        return self.manifest.history(sample_id)

    def version(self, sample_id: str | int) -> int:
        """The pair's current version (0 when the manifest never recorded it)."""
        return self.manifest.version(sample_id)

    def pairs(self) -> tuple[PairInfo, ...]:
        """The saved pairs that are not deleted, by sample id (latest version each)."""
        return self.manifest.pairs()

    def splits_of(self, sample_id: str | int) -> tuple[str, ...]:
        """The LiDAR-tree splits whose list holds the sample (empty: not visible)."""
        sid = format_id(sample_id)
        with fs_errors(f"reading the split lists of {self.path}"):
            return self.files.splits_of(sid)

    def open(self, sample_id: str | int) -> Draft:
        """Reopen a listed sample as a draft for editing (its boxes of the class set, prompt)."""
        sid = format_id(sample_id)
        if not self.splits_of(sid):
            raise StoreError(f"sample {sid} is not listed in any split of {self.path} (deleted?)")
        calib = read_calib(sample_file(self.lidar_dir, CALIB, sid))
        boxes, classes = labels_to_boxes(self.files.read_labels(sid), calib, self.classes)
        prompt = self.files.read_prompt(sid) or ""
        return Draft.from_boxes(
            boxes,
            classes,
            prompt,
            refers_to_nothing=len(boxes) == 0,
            sample_id=sid,
            base_version=self.version(sid),
        )

    # ---------------------------------------------------------------- operations

    def save(
        self,
        draft: Draft,
        source: SourceFrame | None = None,
        *,
        annotator: str = "anonymous",
        split: str = "train",
        request: str | None = None,
    ) -> SaveResult:
        """Create a new pair (``draft.sample_id`` None; needs ``source``) or edit the pair the
        draft was opened from.

        ``request``: the caller's key of this save (e.g. its draft's version). One with the key
        of a save running waits for it, of one that succeeded gets its result (``repeated``);
        a failure is forgotten (:class:`annotate.requests.RequestLog`).

        Raises:
            ValueError: ``request`` was used before for another draft or split.
            As :meth:`create` and :meth:`update`.
        """
        if request is None:
            return self._save(draft, source, annotator, split)
        result, repeated = self.requests.run(
            request, (draft, split), lambda: self._save(draft, source, annotator, split)
        )
        return replace(result, repeated=True) if repeated else result

    def _save(
        self, draft: Draft, source: SourceFrame | None, annotator: str, split: str
    ) -> SaveResult:
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
        annotator = clean_annotator(annotator)
        report = validate(draft, self.validation, source.sample.calib)
        report.raise_if_invalid()
        draft = clean_prompt(draft)
        sample = source.sample
        text = self._text(draft, sample)
        with fs_errors(f"preparing {self.path} for its first pair"):
            for folder in (split_dir(self.lidar_dir), split_dir(self.radar_dir)):
                folder.mkdir(parents=True, exist_ok=True)
        with self.transactions.transaction(f"saving a new pair in {self.path}") as tx:
            sid = format_id(self._next_id())
            record = self._record(
                Action.CREATE, sid, 1, annotator, (split,), draft, text, source.describe()
            )
            text = text.with_meta(pair_meta(draft, sample, record, self.classes))
            tx.begin(_journal(record), f"saving pair {sid}")
            files = source.files if source.files is not None else write_source(self.writer, source)
            self.writer.write_sample_text(sid, files, text)
            self.files.add_to_split(sid, split)
            self.manifest.append(record.to_json())
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
        annotator = clean_annotator(annotator)
        calib_path = sample_file(self.lidar_dir, CALIB, sid)
        if not calib_path.is_file():
            raise StoreError(f"sample {sid} has no calibration file {calib_path}")
        report = validate(draft, self.validation, read_calib(calib_path))
        report.raise_if_invalid()
        draft = clean_prompt(draft)
        with self.transactions.transaction(f"saving the edit of pair {sid}") as tx:
            splits, current = self._listed_version(sid, draft.base_version, "(deleted?); not saved")
            root = Talk2RadarRoot(self.path, radar=self.writer.radar_folder, classes=self.classes)
            sample, labels = root.load(sid), self.files.read_labels(sid)
            kept = [lab for lab in labels if self.classes.label_class(lab.name) is None]
            text = self._text(draft, sample, kept)
            record = self._record(Action.EDIT, sid, current + 1, annotator, splits, draft, text)
            text = text.with_meta(pair_meta(draft, sample, record, self.classes))
            targets = self.writer.text_files(sid, text)
            journal = _journal(record)
            journal["restore"] = {
                str(path.relative_to(self.path)): self.files.read_text(path) for path, _ in targets
            }
            tx.begin(journal, f"saving the edit of pair {sid}")
            replace_files(targets)
            self.manifest.append(record.to_json())
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
        annotator = clean_annotator(annotator)
        with self.transactions.transaction(f"deleting pair {sid}") as tx:
            splits, current = self._listed_version(sid, base_version, "(already deleted?)")
            record = self._record(Action.DELETE, sid, current + 1, annotator, splits)
            tx.begin(_journal(record), f"deleting pair {sid}")
            for tree in self.files.all_trees():  # LiDAR first: the commit
                for split in splits:
                    self.files.remove_from_split(tree, sid, split)
            self.manifest.append(record.to_json())
        return record

    def recover(self) -> tuple[str, ...]:
        """Resolve interrupted operations now (also done on open and before every operation).

        Returns one line per journal resolved (``"00012: create rolled back"``, or ``"00012:
        create set aside (...)"`` for one moved to ``annotations/unresolved/``).

        Raises:
            DiskFullError: an interrupted edit cannot be undone until disk space is freed.
        """
        with (
            self.transactions.locked(),
            fs_errors(f"recovering interrupted operations in {self.path}"),
        ):
            return self.transactions.recover_all()

    # ---------------------------------------------------------------- internals

    @staticmethod
    def _text(draft: Draft, sample: Sample, kept: Sequence[ObjectLabel] = ()) -> SampleText:
        """The pair's files without the sidecar (:func:`scenes.talk2radar.writer.sample_text`): the draft's
        boxes in the frame's calibration, clipped to its image size (:func:`frame_image_size`),
        then the ``kept`` labels."""
        size = frame_image_size(sample)
        return sample_text(
            draft.box_array, draft.classes, draft.prompt, sample.calib, size, kept=kept
        )

    def _record(
        self,
        action: Action,
        sid: str,
        version: int,
        annotator: str,
        splits: tuple[str, ...],
        draft: Draft | None = None,
        text: SampleText | None = None,
        source: dict | None = None,
    ) -> ManifestRecord:
        """The manifest line of an operation (a new ``op`` id, the clock's time). An edit or a
        deletion records the pair's current prompt and label text as ``previous`` and keeps the
        pair's last known ``source``; ``draft`` is None for a deletion."""
        previous = None
        if action is not Action.CREATE:
            previous = {
                "version": version - 1,
                "prompt": self.files.read_prompt(sid),
                "label_text": self.files.read_label_text(sid),
            }
            source = last_source(self.history(sid))
        content: dict = {}
        if draft is not None and text is not None:
            content = {
                "prompt": draft.prompt.strip(),
                "boxes": tuple(tuple(float(v) for v in b) for b in draft.box_array),
                "classes": draft.classes,
                "refers_to_nothing": draft.refers_to_nothing,
                "label_text": text.label,
            }
        return ManifestRecord(
            action=action,
            sample_id=sid,
            version=version,
            time=self.clock(),
            annotator=annotator,
            op=uuid.uuid4().hex,
            splits=splits,
            source=source or {},
            previous=previous,
            **content,
        )

    def _listed_version(
        self, sid: str, base_version: int | None, unlisted: str
    ) -> tuple[tuple[str, ...], int]:
        """The splits listing the pair and its version; :class:`StoreError` (``"... any split
        <unlisted>"``) when none lists it, :class:`ConflictError` when ``base_version`` is given
        and differs."""
        splits = self.splits_of(sid)
        if not splits:
            raise StoreError(f"sample {sid} is not listed in any split {unlisted}")
        current = self.version(sid)
        if base_version is not None and base_version != current:
            raise ConflictError(conflict_message(sid, base_version, self.history(sid)))
        return splits, current

    def _next_id(self) -> int:
        """One above the highest id anywhere in the root (lists, sample folders, sidecars,
        manifest, pending and set-aside journals), so no id is ever reused."""
        best = self.files.max_id()
        for r in self.records():
            best = max(best, int(r.sample_id))
        return max(best, self.journals.max_id()) + 1

    def _check_split(self, split: str) -> None:
        """Raise :class:`SplitError` unless ``split`` is one of :attr:`splits`."""
        _check_split_name(split)
        if split not in self.splits:
            raise SplitError(
                f"unknown split {split!r}: {self.path} offers {', '.join(self.splits)}"
            )


def _journal(record: ManifestRecord) -> dict:
    """The journal of an operation (see :mod:`annotate.journal`); an edit adds ``restore``."""
    return {
        "op": record.op,
        "action": record.action.value,
        "sample_id": record.sample_id,
        "splits": list(record.splits),
        "record": record.to_json(),
    }


def _check_split_name(split: object) -> None:
    """Raise :class:`SplitError` for a split name that could not be a file name of ImageSets."""
    if not isinstance(split, str) or not _SPLIT_NAME.fullmatch(split):
        shown = repr(split) if len(repr(split)) <= 40 else repr(split)[:37] + "..."
        raise SplitError(
            f"invalid split name {shown}: use at most 64 letters, digits, '_', '-' or '.' "
            "(e.g. 'train')"
        )


__all__ = ["DEFAULT_SPLITS", "AnnotationStore", "SaveResult"]
