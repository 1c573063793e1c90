"""Every labelled object of a frame, from a View-of-Delft release (``--scene-labels VOD_ROOT``).

A Talk2Radar ``label_2`` lists only the referents of the frame's prompt; View-of-Delft's own
``lidar/training/label_2/<id>.txt`` lists every annotated object of the same frame id under VoD's
class names (``Car``, ``Pedestrian``, ``Cyclist`` and ``bicycle``, ``rider``, ``moped_scooter``,
``motor``, ``truck``, ``bicycle_rack``, ``ride_other``, ``vehicle_other``, ``human_depiction``,
``ride_uncertain``, ``DontCare``). Training on a real root takes its detection targets from here
(the three classes are positives; the others are never positives, and the real streets are full of
them), grounding over labelled boxes takes its candidates from here, and the annotation tool
pre-selects referents among them. VoD annotates only the camera's field of view within 50 m: :func:`fov_mask`
tells the annotated region of the BEV, outside of which nothing is background.

Nothing here reads a Talk2PC sidecar: a VoD root (or any root laid out as one) is read through its
label and calibration files only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.frame.kitti import ObjectLabel, read_label_file
from scenes.geometry.calib import (
    IMAGE_SIZE,
    Calibration,
    CameraBoxes,
    boxes_camera_to_lidar,
    read_calib,
)
from scenes.geometry.classes import VOD, ClassSet
from scenes.geometry.projection import in_annotated_area
from scenes.talk2radar.layout import CALIB, LABEL, LIDAR_FOLDER, format_id, sample_dir, sample_file
from scenes.utils.errors import RootError

DONT_CARE = "DontCare"
"""VoD's name for a region whose objects are neither positives nor negatives."""


@dataclass(frozen=True)
class FrameObjects:
    """The labelled objects of one frame, in the LiDAR frame.

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw`` (z at the geometric centre).
        names: ``K`` class names as written in the file (VoD spelling).
        labels: ``(K,)`` int64: index into the reader's class set (``vod`` by default: the three
            metric classes, matched case-insensitively; :meth:`scenes.geometry.classes.ClassSet.
            label_index`), ``-1`` for every other class.
        calib: The frame's LiDAR calibration (LiDAR -> camera), for :func:`fov_mask`.
    """

    boxes: np.ndarray
    names: tuple[str, ...]
    labels: np.ndarray
    calib: Calibration
    classes: ClassSet = VOD

    def __len__(self) -> int:
        return len(self.names)

    def metric(self) -> tuple[np.ndarray, np.ndarray]:
        """``boxes (K', 7)`` and ``labels (K',)`` of the class set's classes only."""
        keep = self.labels >= 0
        return self.boxes[keep], self.labels[keep]

    def others(self) -> np.ndarray:
        """``(K'', 7)`` boxes of the non-metric classes other than ``DontCare`` (parked
        bicycles, riders, mopeds, ...): never positives."""
        keep = (self.labels < 0) & np.array([n != DONT_CARE for n in self.names], dtype=bool)
        return self.boxes[keep.reshape(-1)] if len(self.names) else self.boxes


def class_index(name: str, classes: ClassSet = VOD) -> int:
    """Index of the class label name ``name`` maps onto in ``classes`` (case-insensitive), or
    ``-1`` (:meth:`scenes.geometry.classes.ClassSet.label_index`)."""
    return classes.label_index(name)


def objects_from_labels(
    labels: list[ObjectLabel], calib: Calibration, classes: ClassSet = VOD
) -> FrameObjects:
    """:class:`FrameObjects` of parsed ``label_2`` lines (camera frame) under ``calib``, their
    labels indexing ``classes``."""
    if not labels:
        return FrameObjects(np.zeros((0, 7)), (), np.zeros(0, dtype=np.int64), calib, classes)
    cam = CameraBoxes(
        location=np.array([lab.location for lab in labels], dtype=np.float64),
        dimensions_hwl=np.array([lab.dimensions_hwl for lab in labels], dtype=np.float64),
        rotation_y=np.array([lab.rotation_y for lab in labels], dtype=np.float64),
    )
    return FrameObjects(
        boxes=boxes_camera_to_lidar(cam, calib),
        names=tuple(lab.name for lab in labels),
        labels=np.array([classes.label_index(lab.name) for lab in labels], dtype=np.int64),
        calib=calib,
        classes=classes,
    )


class SceneLabels:
    """Reader of a View-of-Delft root's full frame labels (``<root>/lidar/training/label_2``).

    A VoD release opened directly is its own scene-labels root; a Talk2Radar root is paired with
    the VoD release its frames come from (same frame ids). ``classes``: the class set the labels
    are read into (:class:`FrameObjects`).
    """

    def __init__(self, root: str | Path, classes: ClassSet = VOD) -> None:
        self.root = Path(root)
        self.classes = classes
        self.tree = self.root / LIDAR_FOLDER
        if not sample_dir(self.tree, LABEL).is_dir():
            raise RootError(
                f"{self.root}: no {LIDAR_FOLDER}/training/{LABEL}/ folder: not a View-of-Delft "
                "root with labels (--scene-labels expects the release's root folder)"
            )

    def __repr__(self) -> str:
        return f"SceneLabels({str(self.root)!r})"

    def label_path(self, sample_id: str | int) -> Path:
        """The frame's label file."""
        return sample_file(self.tree, LABEL, format_id(sample_id))

    def has(self, sample_id: str | int) -> bool:
        """Whether the frame has a label file here."""
        return self.label_path(sample_id).is_file()

    def load(self, sample_id: str | int) -> FrameObjects:
        """Every labelled object of the frame.

        Raises:
            RootError: the label or calibration file is missing.
            scenes.frame.kitti.LabelError, scenes.geometry.calib.CalibError: a malformed file (named).
        """
        sid = format_id(sample_id)
        path = self.label_path(sid)
        calib_path = sample_file(self.tree, CALIB, sid)
        if not path.is_file():
            raise RootError(f"{path}: no scene label file for frame {sid}")
        if not calib_path.is_file():
            raise RootError(f"{calib_path}: no calibration file for frame {sid}")
        return objects_from_labels(read_label_file(path), read_calib(calib_path), self.classes)


CELL_PROBE = (1.0, 1.0, 1.0)
"""Size (l, w, h, m) of the probe box :func:`fov_mask` tests at each position."""
PROBE_Z = -1.0
"""LiDAR-frame z of the probe's centre: a road user's centre height (the ground is near -1.7)."""


def fov_mask(
    xy: np.ndarray, calib: Calibration, image_size: tuple[int, int] = IMAGE_SIZE
) -> np.ndarray:
    """Which BEV positions lie in the region VoD annotates (:func:`scenes.synth.vod_labels.
    in_annotated_area`: within its range and partly in the camera's view), tested with a small
    probe box (:data:`CELL_PROBE`) at each position.

    Args:
        xy: ``(N, 2)`` LiDAR-frame ground positions (m).
        calib: LiDAR -> camera calibration.
        image_size: ``(width, height)`` pixels.

    Returns:
        ``(N,)`` bool.
    """
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0, dtype=bool)
    probes = np.column_stack(
        [pts, np.full(len(pts), PROBE_Z), np.tile(CELL_PROBE, (len(pts), 1)), np.zeros(len(pts))]
    )
    return in_annotated_area(probes, calib, image_size)


__all__ = [
    "DONT_CARE",
    "FrameObjects",
    "SceneLabels",
    "class_index",
    "fov_mask",
    "objects_from_labels",
]
