"""Scoring written prediction files (``python -m model.evaluate --labels DIR --preds DIR``):
reading a label folder and a prediction folder as strictly as :mod:`model.evaluate`'s docstring
says, and the official View-of-Delft figures of them (:func:`score_directories`).

The folders are View-of-Delft's KITTI label folders, one ``<frame id>.txt`` per frame, so the
frame id's format is the Talk2Radar layout's (:mod:`scenes.talk2radar.layout`: ``ID_WIDTH``,
``is_frame_id``, ``format_id``), imported here as the format these files are named in."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from model.evaluation.metrics import VodResult, evaluate_frames
from scenes.frame.kitti import LabelError, ObjectLabel, parse_label_line, read_label_file
from scenes.geometry.classes import VOD, ClassSet
from scenes.talk2radar.layout import ID_WIDTH, format_id, is_frame_id
from scenes.utils.textfile import read_text_file


class EvaluationInputError(ValueError):
    """Label or prediction folders that cannot be scored; the message names the files."""


@dataclass(frozen=True)
class ScoredDirectories:
    """The result of scoring a prediction folder.

    Attributes:
        result: The metric.
        frame_ids: Frames evaluated (from the label folder), sorted.
        missing_predictions: Frames with no prediction file (scored as no detections).
    """

    result: VodResult
    frame_ids: tuple[str, ...]
    missing_predictions: tuple[str, ...]


def _frame_files(folder: Path, what: str) -> dict[str, Path]:
    """``<frame id>.txt`` files of ``folder`` (not recursive; hidden files skipped) by frame id.

    Raises:
        EvaluationInputError: the folder is missing or unreadable; a ``.txt`` entry is not a
            readable file (a folder, a broken link, a symlink loop); a name is not a zero-padded
            5-digit frame id (``2.txt`` beside ``00002.txt`` would be one frame counted twice).
    """
    if not folder.is_dir():
        raise EvaluationInputError(f"{what} folder {folder} does not exist or is not a folder")
    try:
        entries = sorted(p for p in folder.iterdir() if p.suffix == ".txt")
    except OSError as exc:
        raise EvaluationInputError(
            f"{what} folder {folder}: cannot list it ({exc.strerror or exc})"
        ) from exc
    files: dict[str, Path] = {}
    for path in entries:
        if path.name.startswith("."):
            continue
        try:
            path.stat()
            regular = path.is_file()
            reason = "not a regular file"
        except OSError as exc:  # a broken link, a symlink loop
            regular, reason = False, exc.strerror or str(exc)
        if not regular:
            raise EvaluationInputError(f"{path}: cannot read this {what} file ({reason})")
        stem = path.stem
        if not is_frame_id(stem):
            if stem.isascii() and stem.isdigit() and len(stem) < ID_WIDTH:
                raise EvaluationInputError(
                    f"{path}: frame id {stem!r} is not written as {ID_WIDTH} digits; rename it "
                    f"{format_id(stem)}.txt (frame ids are zero-padded to {ID_WIDTH} digits, and "
                    "one frame has one file)"
                )
            raise EvaluationInputError(
                f"{path}: not a {what} file name: expected <{ID_WIDTH}-digit frame id>.txt, e.g. "
                f"{format_id(2)}.txt"
            )
        files[stem] = path
    return files


def load_label_dir(folder: str | Path) -> dict[str, list[ObjectLabel]]:
    """Every ``<frame id>.txt`` label file of ``folder`` -> frame id -> labels.

    Raises:
        EvaluationInputError: the folder is missing, holds no ``.txt`` files, or holds an entry
            that is not a readable ``<5-digit id>.txt`` file (see :func:`_frame_files`).
        scenes.frame.kitti.LabelError: an unreadable, non-UTF-8 or binary file, or a malformed line
            (file and line named).
    """
    folder = Path(folder)
    files = _frame_files(folder, "label")
    if not files:
        raise EvaluationInputError(f"label folder {folder} holds no .txt label files")
    return {frame: read_label_file(path) for frame, path in files.items()}


def read_prediction_file(path: str | Path) -> list[ObjectLabel]:
    """Read one prediction file (empty file -> no detections); errors name the file and line.

    Every line needs its score (the 16th field): the devkit would score a line without one as 0,
    which silently ranks it last, so here it is an error.

    Raises:
        scenes.frame.kitti.LabelError: an unreadable, non-UTF-8 or binary file, a malformed line, or a
            line without a score.
    """
    path = Path(path)
    labels: list[ObjectLabel] = []
    text = read_text_file(path, "prediction file", LabelError)
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        label = parse_label_line(line, source=f"{path}:{lineno}")
        if label.score is None:
            raise LabelError(
                f"{path}:{lineno}: prediction line without a score (15 fields; a detection "
                f"needs 16, the last one its score): {line.strip()[:80]!r}"
            )
        labels.append(label)
    return labels


def load_prediction_dir(
    folder: str | Path, frame_ids: Sequence[str]
) -> tuple[dict[str, list[ObjectLabel]], tuple[str, ...]]:
    """Predictions of ``frame_ids`` from ``folder``.

    Returns:
        ``(frame id -> detections, frames whose file is missing)``; missing files give no
        detections.

    Raises:
        EvaluationInputError: ``folder`` is missing, holds files for frames not in
            ``frame_ids``, or an entry that is not a readable ``<5-digit id>.txt`` file.
        scenes.frame.kitti.LabelError: an unreadable file, a malformed line or a line without a score
            (file and line named).
    """
    folder = Path(folder)
    files = _frame_files(folder, "prediction")
    known = set(frame_ids)
    extra = sorted(set(files) - known)
    if extra:
        shown = ", ".join(str(files[f]) for f in extra[:5])
        more = f" and {len(extra) - 5} more" if len(extra) > 5 else ""
        raise EvaluationInputError(
            f"{len(extra)} prediction file(s) have no label file: {shown}{more} "
            "(wrong label folder or split?)"
        )
    preds = {f: read_prediction_file(files[f]) for f in frame_ids if f in files}
    missing = tuple(f for f in frame_ids if f not in files)
    return preds, missing


def score_directories(
    labels: str | Path,
    preds: str | Path,
    devkit_offsets: bool = True,
    classes: ClassSet = VOD,
) -> ScoredDirectories:
    """Score the prediction folder ``preds`` against the label folder ``labels``, a row per
    class of ``classes`` (``devkit_offsets``: see :func:`model.evaluation.metrics.evaluate_frames`)."""
    gt = load_label_dir(labels)
    frame_ids = tuple(sorted(gt))
    dt, missing = load_prediction_dir(preds, frame_ids)
    return ScoredDirectories(
        result=evaluate_frames(gt, dt, devkit_offsets=devkit_offsets, classes=classes),
        frame_ids=frame_ids,
        missing_predictions=missing,
    )
