"""Pairs annotated on a nuScenes root, saved as Talk2Car commands: :class:`Talk2CarStore`.

A pair made on a nuScenes sample is one Talk2Car command (docs/TALK2CAR.md, section 9): the
sentence and the **one** sample_annotation it refers to (a command refers to exactly one object;
:func:`referred_annotation` says why a draft does not), written in the release's format by
:func:`scenes.nuscenes.talk2car.write_commands` into ``<pairs>/commands/{split}_commands.json``
of its sample's split where the served root knows it (``split_of``: the command file listing the
sample's scene; another split is refused, :meth:`Talk2CarStore.split_for`):
its ``box_token``, the annotation's box in the CAM_FRONT camera frame
(:func:`scenes.nuscenes.talk2car.model_box_to_camera`), its 2D box projected into the image with
the frame's calibration (:func:`scenes.geometry.calib.boxes_2d`; whole pixels, as the release
writes it), a new ``command_token``, the
sample's CAM_FRONT sample_data token as ``sample_token``, the scene's token, ``obj_name`` = the
annotation's category and ``t2c_img`` ``img_{split}_{n}.jpg``. ``<pairs>`` is laid out as
Talk2Car's data folder: ``--talk2car <pairs>/commands`` reads the commands back
(:func:`scenes.nuscenes.talk2car.read_commands`), and the public ``talk2car.py``'s
``Talk2CarSlim(split, root=<pairs>)`` reads ``<pairs>/commands/{split}_commands.json``.

Nothing is written before the first save. A save rewrites its split's file atomically with the
commands already there (read back strictly; a file holding a command that does not resolve
against the served root is refused, never rewritten without it) and the new one; every key the
store does not write is kept (a command's keys beyond the release's eleven, top-level keys such
as ``version``), and the commands already there keep their records as read, byte for byte (the
file's layout, number spellings and escapes: :func:`scenes.utils.json_splice.splice_object`;
a new command is written in the file's own layout); saves are
idempotent per request key, as :meth:`annotate.AnnotationStore.save`'s. The pairs folder's
``commands/`` never lies inside the served nuScenes root nor inside a folder the store must not
write (the app's ``--talk2car`` folder): :func:`check_pairs_folder`. The command file keeps
no annotator, no versions and no reviews (the release's format has none): :meth:`open` refuses
to reopen a command (delete it and annotate it again), :meth:`history` and :meth:`records` are
empty.

The store answers what the Annotate tab asks of :class:`annotate.AnnotationStore` (``path``,
``validation``, ``pairs``, ``save``, ``open``, ``history``, ``records``, ``delete``); a pair's id
is its command_token.
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Callable, Sequence
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from annotate.draft import Draft
from annotate.errors import SplitError, StoreError, fs_errors
from annotate.manifest import Action, ManifestRecord, PairInfo
from annotate.requests import RequestLog
from annotate.source import SourceFrame
from annotate.store import DEFAULT_SPLITS, SaveResult
from annotate.validation import Issue, ValidationConfig, clean_prompt, validate
from scenes.geometry.boxes import wrap_yaw
from scenes.geometry.calib import boxes_2d, boxes_lidar_to_camera
from scenes.geometry.classes import VOD, ClassSet
from scenes.nuscenes.classes import model_class
from scenes.nuscenes.root import NuScenesError, NuScenesRoot
from scenes.nuscenes.talk2car import (
    CommandFileError,
    Talk2CarCommand,
    command_record,
    commands_file,
    model_box_to_camera,
    read_commands,
    write_command_file,
)
from scenes.utils.owned import inside
from scenes.utils.textfile import read_json_file

__all__ = [
    "COMMANDS_FOLDER",
    "MATCH",
    "Talk2CarStore",
    "check_pairs_folder",
    "referred_annotation",
]

COMMANDS_FOLDER = "commands"
"""The folder of a pairs root that holds ``{split}_commands.json`` (as Talk2Car's data folder)."""
MATCH = 1e-4
"""Largest difference (m, rad) between a draft box and the annotation it stands for."""


def referred_annotation(
    draft: Draft,
    boxes: np.ndarray,
    categories: tuple[str, ...],
    attributes: tuple[tuple[str, ...], ...],
    classes: ClassSet = VOD,
) -> tuple[int | None, tuple[Issue, ...]]:
    """The index of the one annotation a draft refers to, or why it does not refer to exactly one.

    Args:
        draft: The pair being made (boxes in the model frame).
        boxes: ``(K, 7)`` the sample's annotations in the model frame
            (:meth:`scenes.nuscenes.root.NuScenesRoot.annotation_boxes`).
        categories: Their ``K`` nuScenes categories.
        attributes: Their ``K`` attribute tuples.
        classes: The class set (the served model's) the categories map onto.

    Returns:
        ``(index, ())`` when the draft's one box is one annotation of the class set with the same
        class, else ``(None, issues)`` (errors that block saving, each one sentence; none for a
        draft without boxes, which :func:`annotate.validate` refuses).
    """
    if not draft.boxes and not draft.refers_to_nothing:
        return None, ()  # validate's "no boxes" says it
    if draft.refers_to_nothing or len(draft.boxes) != 1:
        return None, (
            Issue(
                "boxes",
                "a Talk2Car command refers to exactly one labelled annotation: the draft has "
                f"{len(draft.boxes)} boxes"
                + (" and refers to nothing" if draft.refers_to_nothing else ""),
            ),
        )
    item = draft.boxes[0]
    box = np.asarray(item.box, dtype=np.float64)
    ann = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(ann):
        diff = np.abs(ann - box[None])
        diff[:, 6] = np.abs(wrap_yaw(ann[:, 6] - box[6]))
        worst = diff.max(axis=1)
        index = int(np.argmin(worst))
        if worst[index] <= MATCH:
            cls = model_class(categories[index], attributes[index], classes)
            if cls is None:
                why = f"its category {categories[index]} is outside the class set"
                return None, (Issue("box[0]", f"box 1 cannot be a command's referent: {why}", 0),)
            if cls != item.cls:
                return None, (
                    Issue(
                        "box[0].cls",
                        f"box 1 is a {item.cls} but its annotation ({categories[index]}) is a "
                        f"{cls}: keep the annotation's class",
                        0,
                    ),
                )
            return index, ()
    return None, (
        Issue(
            "box[0]",
            "box 1 is not one of the sample's labelled annotations: a Talk2Car command refers to "
            "an annotation (click a labelled box, or type the sentence to pick one)",
            0,
        ),
    )


def check_pairs_folder(
    path: str | Path, root: str | Path, protected: Sequence[str | Path] = ()
) -> None:
    """Refuse a pairs folder whose ``commands/`` (where saves go) lies inside the nuScenes root
    ``root`` or is, or lies inside, one of the ``protected`` folders (the app's ``--talk2car``).

    Raises:
        StoreError: one line naming the pairs folder and the folder it would write into.
    """
    commands = Path(path) / COMMANDS_FOLDER
    if inside(commands, root):
        raise StoreError(
            f"pairs folder {path}: its commands would go into {commands}, inside the served "
            f"nuScenes root {root}, which is never written; name a pairs folder outside it"
        )
    for folder in protected:
        if inside(commands, folder):
            raise StoreError(
                f"pairs folder {path}: its commands would go into {commands}, the --talk2car "
                f"folder {folder} (or inside it), which is never written; name another pairs "
                "folder"
            )


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class Talk2CarStore:
    """Talk2Car commands annotated on one nuScenes root, saved under ``path`` (module docstring).

    Args:
        path: The pairs folder; commands go into ``path/commands/{split}_commands.json``,
            created by the first save.
        root: The nuScenes root the commands refer to.
        splits: The splits offered.
        validation: Rules checked before every save (default: the class set, the CAM_FRONT image
            size of the root's first sample).
        classes: The class set (the served model's): a command's box is an annotation whose
            category maps onto the draft box's class of this set.
        protected: Folders never written into (the served ``--talk2car`` folder).
        split_of: The split a sample token belongs to (the served root's
            :meth:`scenes.nuscenes.source.NuScenesSource.sample_split`; None: unknown): a command
            is saved into its sample's split, never another (:meth:`save`).

    Raises:
        StoreError: a pairs folder that would write into the root or a protected folder
            (:func:`check_pairs_folder`).
    """

    def __init__(
        self,
        path: str | Path,
        root: NuScenesRoot,
        splits: tuple[str, ...] = DEFAULT_SPLITS,
        validation: ValidationConfig | None = None,
        classes: ClassSet = VOD,
        protected: Sequence[str | Path] = (),
        split_of: Callable[[str], str | None] | None = None,
    ) -> None:
        check_pairs_folder(path, root.path, protected)
        self.split_of = split_of
        self.path = Path(path)
        self.classes = classes
        self.commands_dir = self.path / COMMANDS_FOLDER
        self.root = root
        self.splits = tuple(splits)
        if validation is None:
            validation = ValidationConfig(image_size=_image_size(root), classes=classes.names)
        self.validation = validation
        self.requests: RequestLog[SaveResult] = RequestLog()
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        return f"Talk2CarStore({str(self.path)!r}, root={self.root!r})"

    # ------------------------------------------------------------------ reading

    def _read(self, split: str) -> tuple[dict, tuple[Talk2CarCommand, ...], str | None]:
        """One split's file as read (its JSON object, every key in it; an empty one when the file
        does not exist), its commands, and its text as it is on disk (None: no file, or not
        UTF-8), for a rewrite that keeps the bytes of what it does not change.

        Raises:
            StoreError: the file is malformed, or holds commands that do not resolve against
                the root (they would be lost by a rewrite).
        """
        path = commands_file(self.commands_dir, split)
        if not path.is_file():
            return {"scene_tokens": [], "commands": []}, (), None
        try:
            raw = path.read_bytes()
            found = read_commands(self.commands_dir, split, self.root, self.classes)
            data = read_json_file(path, "Talk2Car command file", CommandFileError)
        except (NuScenesError, OSError) as exc:
            raise StoreError(str(exc)) from exc
        try:
            text: str | None = raw.decode("utf-8")
        except UnicodeDecodeError:
            text = None
        if found.skipped:
            reasons = "; ".join(f"{n} x {why}" for why, n in sorted(found.skipped.items()))
            raise StoreError(
                f"{path}: {sum(found.skipped.values())} command(s) do not resolve against "
                f"{self.root.path} ({reasons}); the file is not rewritten"
            )
        return data, found.commands, text

    def commands(self, split: str) -> tuple[Talk2CarCommand, ...]:
        """The commands saved in ``split`` (file order)."""
        return self._read(split)[1]

    def pairs(self) -> tuple[PairInfo, ...]:
        """Every saved command as a pair (id: its command_token; ``time``: its split and file
        position, so the latest of a split lists last)."""
        out = []
        for split in self.splits:
            for n, c in enumerate(self.commands(split)):
                time = f"{split}:{n:06d}"
                out.append(PairInfo(c.command_token, 1, (split,), c.text, 1, "", time, None))
        return tuple(out)

    def open(self, sample_id: str) -> Draft:
        """Commands are not reopened for editing (the file keeps no versions).

        Raises:
            StoreError: always, saying what to do instead.
        """
        raise StoreError(
            f"command {sample_id}: a Talk2Car command is not reopened for editing (its file keeps "
            "no versions); delete it and annotate the pair again"
        )

    def history(self, sample_id: str) -> tuple[ManifestRecord, ...]:
        """No history: the command file keeps none."""
        return ()

    def records(self) -> tuple[ManifestRecord, ...]:
        """No manifest: the command file keeps no reviews."""
        return ()

    # ------------------------------------------------------------------ writing

    def save(
        self,
        draft: Draft,
        source: SourceFrame | None = None,
        *,
        annotator: str = "anonymous",
        split: str | None = None,
        request: str | None = None,
    ) -> SaveResult:
        """Append the draft as a new command of its sample's split (``source.sample_id``: the
        sample token; ``annotator`` is not kept, the format has no field for it).

        ``split``: the split asked for; None: the sample's (:attr:`split_of`), else ``train``.
        A sample whose split is known goes there only: asking for another is refused.

        Raises:
            annotate.validation.ValidationError: the draft is invalid, or does not refer to
                exactly one labelled annotation of the sample.
            SplitError: ``split`` is not offered, or is not the sample's split.
            StoreError: no source frame, a pair being edited, or a file that cannot be read or
                written (one line naming it).
        """
        split = self.split_for(source.sample_id if source is not None else None, split)
        if request is None:
            return self._save(draft, source, split)
        result, repeated = self.requests.run(
            request, (draft, split), lambda: self._save(draft, source, split)
        )
        return replace(result, repeated=True) if repeated else result

    def split_for(self, sample_id: str | None, asked: str | None = None) -> str:
        """The split a command on ``sample_id`` is saved into: its sample's split where
        :attr:`split_of` knows it, else ``asked`` (else ``train``).

        Raises:
            SplitError: ``asked`` is not the sample's known split.
        """
        known = self.split_of(sample_id) if self.split_of is not None and sample_id else None
        if known is not None and asked is not None and asked != known:
            raise SplitError(
                f"sample {sample_id} is in split {known!r} (its scene is listed in "
                f"{known}_commands.json): a command goes into its sample's split, not {asked!r}"
            )
        return known or asked or "train"

    def _save(self, draft: Draft, source: SourceFrame | None, split: str) -> SaveResult:
        if draft.sample_id is not None or source is None or source.sample_id is None:
            raise StoreError("a Talk2Car command is saved from the sample it is annotated on")
        if split not in self.splits:
            raise SplitError(f"split {split!r} is not offered here (splits: {self.splits})")
        sample = source.sample_id
        sample_rec = self.root.tables.records["sample"].get(sample)
        if sample_rec is None:
            raise StoreError(f"{self.root.path}: no sample {sample!r}")
        calib = source.sample.calib
        report = validate(draft, self.validation, calib)
        boxes, categories, attributes = self.root.annotation_boxes(sample)
        index, issues = referred_annotation(draft, boxes, categories, attributes, self.classes)
        if issues:
            report = replace(report, issues=report.issues + issues)
        report.raise_if_invalid()
        assert index is not None
        to_camera = self.root.to_camera(sample)
        cam_token = self.root.key_data(sample)["CAM_FRONT"]
        cam = self.root.tables.get("sample_data", cam_token)
        left, top, right, bottom = boxes_2d(
            boxes_lidar_to_camera(boxes[index][None], calib),
            calib,
            (int(cam["width"]), int(cam["height"])),
        )[0]
        with self._lock:
            data, existing, text = self._read(split)
            scene_tokens = list(data.get("scene_tokens", []))
            if sample_rec["scene_token"] not in scene_tokens:
                scene_tokens.append(sample_rec["scene_token"])
            command = Talk2CarCommand(
                command_token=uuid.uuid4().hex,
                text=clean_prompt(draft).prompt,
                scene_token=sample_rec["scene_token"],
                sample_token=sample,
                cam_token=cam_token,
                box_token=self.root.annotations(sample)[index],
                category=categories[index],
                box_camera=model_box_to_camera(to_camera, boxes[index]),
                box_2d=(float(left), float(top), float(right - left), float(bottom - top)),
                t2c_img=f"img_{split}_{len(existing)}.jpg",
            )
            records = [*data["commands"], command_record(command)]
            with fs_errors(f"writing {commands_file(self.commands_dir, split)}"):
                write_command_file(
                    self.commands_dir,
                    split,
                    {**data, "scene_tokens": scene_tokens, "commands": records},
                    text,
                )
        record = ManifestRecord(
            action=Action.CREATE,
            sample_id=command.command_token,
            version=1,
            time=_now(),
            annotator="",
            op=uuid.uuid4().hex,
            splits=(split,),
            prompt=command.text,
            boxes=(tuple(float(v) for v in boxes[index]),),
            classes=(draft.boxes[0].cls,),
            source=source.describe(),
        )
        return SaveResult(command.command_token, 1, record, report.warnings)

    def delete(self, sample_id: str, annotator: str = "") -> None:
        """Remove the command ``sample_id`` (a command_token) from its split's file.

        Raises:
            StoreError: no saved command has that token, or the file cannot be rewritten.
        """
        with self._lock:
            for split in self.splits:
                data, commands, text = self._read(split)
                if any(c.command_token == sample_id for c in commands):
                    kept = [r for r in data["commands"] if r.get("command_token") != sample_id]
                    with fs_errors(f"writing {commands_file(self.commands_dir, split)}"):
                        write_command_file(
                            self.commands_dir, split, {**data, "commands": kept}, text
                        )
                    return
        raise StoreError(f"no command {sample_id!r} in {self.commands_dir}")


def _image_size(root: NuScenesRoot) -> tuple[int, int]:
    """The CAM_FRONT image size of the root's first sample (nuScenes': 1600 x 900)."""
    for sample in root.samples:
        token = root.key_data(sample).get("CAM_FRONT")
        if token is not None:
            rec = root.tables.get("sample_data", token)
            return int(rec["width"]), int(rec["height"])
    return (1600, 900)
