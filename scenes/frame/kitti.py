"""KITTI / View-of-Delft ``label_2`` lines (15 or 16 fields) and their conversion to LiDAR boxes.

Field order (spec §1.4): type, truncated, occluded (int, ``-1`` accepted), alpha, bbox (left top
right bottom, px), dimensions (h w l, m), location (camera-frame bottom centre, m), rotation_y,
and an optional score. Parsing splits on whitespace (tolerant); writing uses single spaces, as both
official evaluators split on ``' '``. Unknown class names are kept as labels but are not metric
classes: :func:`labels_to_boxes` leaves them out.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.geometry.calib import (
    IMAGE_SIZE,
    Calibration,
    CameraBoxes,
    alpha_from,
    boxes_2d,
    boxes_camera_to_lidar,
    boxes_lidar_to_camera,
)
from scenes.geometry.classes import VOD, ClassSet
from scenes.utils.durable import atomic_write_text
from scenes.utils.textfile import read_text_file

MAX_ABS_VALUE = 1e6
"""No number of a label line may exceed this in magnitude: a location of 1e308 m would overflow the
overlaps into NaN and silently change a score; real values are pixels, metres, radians, scores."""


class LabelError(ValueError):
    """A label line is malformed; the message names the file and line."""


@dataclass(frozen=True)
class ObjectLabel:
    """One ``label_2`` line.

    Attributes:
        name: Class name as written (e.g. ``Car``, ``bicycle``).
        truncated: Float, unused by the VoD evaluation.
        occluded: Int (0, 1, 2; -1 for predictions).
        alpha: Observation angle (rad).
        bbox: ``(left, top, right, bottom)`` pixels.
        dimensions_hwl: ``(h, w, l)`` metres.
        location: Camera-frame bottom centre ``(x, y, z)`` metres.
        rotation_y: Rotation (rad), VoD convention.
        score: Optional confidence (16th field).
    """

    name: str
    truncated: float
    occluded: int
    alpha: float
    bbox: tuple[float, float, float, float]
    dimensions_hwl: tuple[float, float, float]
    location: tuple[float, float, float]
    rotation_y: float
    score: float | None = None


def parse_label_line(line: str, source: str = "<label>") -> ObjectLabel:
    """Parse one line; ``source`` (e.g. ``"path:3"``) prefixes every error message."""
    fields = line.split()
    if len(fields) not in (15, 16):
        raise LabelError(f"{source}: expected 15 or 16 fields, got {len(fields)}: {line.strip()!r}")
    try:
        nums = [float(v) for v in fields[1:]]
    except ValueError as exc:
        raise LabelError(f"{source}: non-numeric field in {line.strip()!r}") from exc
    if not np.all(np.isfinite(nums)):
        raise LabelError(f"{source}: non-finite value in {line.strip()!r}")
    if max(abs(v) for v in nums) > MAX_ABS_VALUE:
        worst = max(range(len(nums)), key=lambda i: abs(nums[i]))
        raise LabelError(
            f"{source}: field {worst + 2} ({fields[worst + 1][:24]!r}) is out of range: no "
            f"label value (pixels, metres, radians, score) exceeds {MAX_ABS_VALUE:g} in magnitude"
        )
    occluded = nums[1]
    if occluded != int(occluded):
        raise LabelError(f"{source}: occluded must be an integer, got {fields[2]!r}")
    hwl = (nums[7], nums[8], nums[9])
    if min(hwl) <= 0:
        raise LabelError(f"{source}: box size must be positive, got h w l = {hwl}")
    return ObjectLabel(
        name=fields[0],
        truncated=nums[0],
        occluded=int(occluded),
        alpha=nums[2],
        bbox=(nums[3], nums[4], nums[5], nums[6]),
        dimensions_hwl=hwl,
        location=(nums[10], nums[11], nums[12]),
        rotation_y=nums[13],
        score=nums[14] if len(nums) == 15 else None,
    )


def _fmt(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    return "0" + text[2:] if text.startswith("-0") and float(text) == 0 else text


def format_label_line(label: ObjectLabel, decimals: int = 4) -> str:
    """Format one line with single spaces (``decimals`` places, as mmdet3d's ``.4f`` by default)."""
    nums = [
        label.alpha,
        *label.bbox,
        *label.dimensions_hwl,
        *label.location,
        label.rotation_y,
    ]
    parts = [
        label.name,
        _fmt(label.truncated, 2).rstrip("0").rstrip(".") or "0",
        str(label.occluded),
    ]
    parts += [_fmt(v, decimals) for v in nums]
    if label.score is not None:
        parts.append(_fmt(label.score, decimals))
    return " ".join(parts)


def read_label_file(path: str | Path) -> list[ObjectLabel]:
    """Read a label file (empty file -> no labels); errors name the file and line.

    Raises:
        LabelError: a missing, unreadable, non-UTF-8 or binary file, or a malformed line.
    """
    path = Path(path)
    text = read_text_file(path, "label file", LabelError)
    labels = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if line.strip():
            labels.append(parse_label_line(line, source=f"{path}:{lineno}"))
    return labels


def label_file_text(labels: Sequence[ObjectLabel], decimals: int = 4) -> str:
    """The text of a label file: :func:`format_label_line` of each label, each ended by a line
    break (empty for no labels)."""
    return "".join(format_label_line(lab, decimals) + "\n" for lab in labels)


def write_label_file(path: str | Path, labels: Sequence[ObjectLabel], decimals: int = 4) -> None:
    """Write labels atomically (:func:`scenes.utils.durable.atomic_write_text`), one line each."""
    atomic_write_text(path, label_file_text(labels, decimals))


def labels_to_boxes(
    labels: Sequence[ObjectLabel], calib: Calibration, classes: ClassSet = VOD
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Labels of ``classes`` -> LiDAR-frame boxes ``(K, 7)`` and class names.

    Label names are mapped onto the class set by :meth:`scenes.geometry.classes.ClassSet.
    label_class` (case-insensitive; with ``vod`` the three names, with ``nuscenes`` also VoD's
    ``truck``, ``motor``, ``moped_scooter``, ``bicycle``, ...) and returned as the set's class
    names; labels of other classes (``rider``, ``DontCare``, ...) are left out:
    :func:`outside_class_counts` counts them.
    """
    keep = [lab for lab in labels if classes.label_class(lab.name) is not None]
    if not keep:
        return np.zeros((0, 7)), ()
    cam = CameraBoxes(
        location=np.array([lab.location for lab in keep]),
        dimensions_hwl=np.array([lab.dimensions_hwl for lab in keep]),
        rotation_y=np.array([lab.rotation_y for lab in keep]),
    )
    boxes = boxes_camera_to_lidar(cam, calib)
    return boxes, tuple(str(classes.label_class(lab.name)) for lab in keep)


def outside_class_counts(labels: Sequence[ObjectLabel], classes: ClassSet = VOD) -> dict[str, int]:
    """Label names of ``labels`` outside ``classes`` (``DontCare`` aside), with their number of
    objects: what :func:`labels_to_boxes` leaves out, for the readers to report."""
    counts: dict[str, int] = {}
    for lab in labels:
        if lab.name != "DontCare" and classes.label_class(lab.name) is None:
            counts[lab.name] = counts.get(lab.name, 0) + 1
    return dict(sorted(counts.items()))


def outside_class_phrase(counts: Mapping[str, int], noun: str = "referents") -> str:
    """The words every reader says :func:`outside_class_counts` with (evaluation, the app,
    training): ``"12 referents of classes outside the model's set (Bicycle 9, Truck 3)"``; ``""``
    for no count."""
    total = sum(counts.values())
    if not total:
        return ""
    order = sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    named = ", ".join(f"{name} {n}" for name, n in order)
    word = noun.removesuffix("s") if total == 1 else noun
    return f"{total} {word} of classes outside the model's set ({named})"


def boxes_to_labels(
    boxes: np.ndarray,
    classes: Sequence[str],
    calib: Calibration,
    scores: np.ndarray | None = None,
    image_size: tuple[int, int] = IMAGE_SIZE,
    truncated: float = 0.0,
    occluded: int = 0,
) -> list[ObjectLabel]:
    """LiDAR-frame boxes -> camera labels with alpha and the projected, clipped 2D box.

    Ground truth is written VoD-style (``truncated=0, occluded=0, score=1``); predictions pass
    ``truncated=-1, occluded=-1`` and their scores.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(classes) != len(b):
        raise ValueError(f"{len(b)} boxes but {len(classes)} class names")
    if np.any(b[:, 3:6] <= 0):
        bad = int(np.nonzero(np.any(b[:, 3:6] <= 0, axis=1))[0][0])
        raise ValueError(f"box {bad} has a non-positive size {b[bad, 3:6].tolist()}")
    cam = boxes_lidar_to_camera(b, calib)
    bbox = boxes_2d(cam, calib, image_size)
    alpha = alpha_from(cam.rotation_y, b)
    out = []
    for i, name in enumerate(classes):
        out.append(
            ObjectLabel(
                name=name,
                truncated=truncated,
                occluded=occluded,
                alpha=float(alpha[i]),
                bbox=tuple(float(v) for v in bbox[i]),
                dimensions_hwl=tuple(float(v) for v in cam.dimensions_hwl[i]),
                location=tuple(float(v) for v in cam.location[i]),
                rotation_y=float(cam.rotation_y[i]),
                score=1.0 if scores is None else float(scores[i]),
            )
        )
    return out
