"""Writing a Talk2Radar root: :class:`Talk2RadarWriter`, the sensor files a frame shares
(:class:`SensorFiles`), and the one function that turns a sample into its text files
(:func:`sample_text`), used by the writer's creates and the annotation store's edits alike.

Paths come from :mod:`scenes.talk2radar.layout`; every file is written through :mod:`scenes.utils.durable`. The
reader is :class:`scenes.talk2radar.root.Talk2RadarRoot`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scenes.frame.image import check_principal_point, label_image_size, write_jpeg
from scenes.frame.kitti import ObjectLabel, boxes_to_labels, label_file_text
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.calib import Calibration, read_calib, sensor_to_lidar, transform_points
from scenes.talk2radar.layout import (
    CALIB,
    IMAGE,
    LABEL,
    LIDAR_FOLDER,
    PROMPT,
    RADAR_FOLDER_OF_SCANS,
    RADAR_FOLDERS,
    SOURCE_IMAGE,
    SOURCE_SENSORS,
    VELODYNE,
    format_id,
    meta_file,
    sample_file,
    source_dir,
    split_file,
)
from scenes.talk2radar.pointcloud import write_points
from scenes.talk2radar.poses import Pose, write_pose
from scenes.utils.durable import atomic_write_text, link_or_copy
from scenes.utils.textfile import claim_root

__all__ = [
    "LABEL_DECIMALS",
    "RADAR_SCANS",
    "SampleText",
    "SensorFiles",
    "Talk2RadarWriter",
    "sample_text",
]

LABEL_DECIMALS = 6
"""Decimals of the numbers of every ``label_2`` line a root is written with (creates and edits)."""

RADAR_SCANS = tuple(sorted(RADAR_FOLDER_OF_SCANS))
"""The numbers of accumulated radar scans a root can hold (one radar tree each, as VoD:
:meth:`Talk2RadarWriter.for_radar_scans`)."""


@dataclass(frozen=True)
class SensorFiles:
    """The sensor files of one source frame, shared (hard-linked) by the samples made from it.

    Attributes:
        folder: ``<root>/sources/<frame_key>`` (or the root a frame is linked from).
        lidar_bin, radar_bin, lidar_calib, radar_calib: Paths of the four files.
        image: The camera image (``image.jpg``; ``.jpg`` or ``.png`` from a root), or None where
            the frame has none.
        image_size: ``(width, height)`` of that image when known (else read from its header where
            needed: :func:`label_image_size`).
    """

    folder: Path
    lidar_bin: Path
    radar_bin: Path
    lidar_calib: Path
    radar_calib: Path
    image: Path | None = None
    image_size: tuple[int, int] | None = None

    @staticmethod
    def in_folder(folder: Path) -> SensorFiles:
        """The sensor files of a ``sources/<frame>/`` folder (without the image)."""
        return SensorFiles(folder, *(folder / name for name in SOURCE_SENSORS))

    def label_image_size(self) -> tuple[int, int]:
        """The size the 2D boxes of samples of this frame are clipped to (:func:`label_image_size`)."""
        return label_image_size(self.image, self.image_size)


@dataclass(frozen=True)
class SampleText:
    """The text files of one sample, as :func:`sample_text` makes them.

    Attributes:
        label: The ``label_2`` file (:data:`LABEL_DECIMALS` decimals; empty for no box).
        prompt: The prompt file: the stripped prompt and a line break.
        meta: The sidecar ``meta/<id>.json`` (JSON, indent 1), or None for none.
    """

    label: str
    prompt: str
    meta: str | None = None

    def with_meta(self, meta: SampleMeta | None) -> SampleText:
        """The same files with the sidecar of ``meta`` (None: without one)."""
        return replace(self, meta=None if meta is None else json.dumps(meta.to_json(), indent=1))


def sample_text(
    boxes: np.ndarray,
    classes: Sequence[str],
    prompt: str,
    calib: Calibration,
    image_size: tuple[int, int],
    meta: SampleMeta | None = None,
    kept: Sequence[ObjectLabel] = (),
) -> SampleText:
    """The text files of a sample: the one place a sample becomes files, for a create
    (:meth:`Talk2RadarWriter.write_sample`) and an edit (the annotation store) alike.

    Args:
        boxes: ``(K, 7)`` referred boxes, LiDAR frame.
        classes: Their ``K`` class names.
        prompt: The sentence (stripped; must not be empty).
        calib: The LiDAR calibration (LiDAR -> camera) the labels are written in.
        image_size: ``(width, height)`` the 2D boxes are clipped to (:func:`label_image_size`).
        meta: The sidecar, or None.
        kept: Labels written after the boxes' (an edit keeps the non-metric ones).

    Raises:
        ValueError: an empty prompt, a box of non-positive size, or a class count that differs.
    """
    if not prompt or not prompt.strip():
        raise ValueError("the prompt is empty")
    labels = boxes_to_labels(boxes, list(classes), calib, image_size=image_size)
    text = SampleText(label_file_text([*labels, *kept], LABEL_DECIMALS), prompt.strip() + "\n")
    return text.with_meta(meta)


class Talk2RadarWriter:
    """Writes samples in the Talk2Radar layout (:mod:`scenes.talk2radar.layout`) that
    :class:`Talk2RadarRoot` and the official VoD evaluation read.

    Every file is written atomically (:mod:`scenes.utils.durable`). ``label_2`` and ``prompt`` are
    written identically into the LiDAR and the radar tree, as in Talk2Radar.
    """

    def __init__(self, root: str | Path, radar_folder: str = "radar_5frames") -> None:
        if radar_folder not in RADAR_FOLDERS:
            raise ValueError(f"radar_folder must be one of {RADAR_FOLDERS}, got {radar_folder!r}")
        self.root = Path(root)
        claim_root(self.root)
        self.radar_folder = radar_folder
        self.trees = (self.root / LIDAR_FOLDER, self.root / radar_folder)

    @classmethod
    def for_radar_scans(cls, root: str | Path, radar_scans: int) -> Talk2RadarWriter:
        """A writer whose radar tree holds ``radar_scans`` accumulated scans (:data:`RADAR_SCANS`:
        ``radar``, ``radar_3frames``, ``radar_5frames``)."""
        if radar_scans not in RADAR_FOLDER_OF_SCANS:
            raise ValueError(f"radar_scans must be one of {RADAR_SCANS}, got {radar_scans!r}")
        return cls(root, radar_folder=RADAR_FOLDER_OF_SCANS[radar_scans])

    @staticmethod
    def holds_root(path: str | Path) -> bool:
        """Whether ``path`` already holds a Talk2Radar root (its LiDAR tree exists)."""
        return (Path(path) / LIDAR_FOLDER).exists()

    def has_samples(self, sample_ids: Sequence[str | int]) -> bool:
        """Whether every sample of ``sample_ids`` is complete in both trees (its ``label_2``, the
        last file :meth:`write_sample_text` writes, exists)."""
        return all(
            sample_file(tree, LABEL, format_id(sid)).is_file()
            for tree in self.trees
            for sid in sample_ids
        )

    def write_pose(self, sample_id: str | int, pose: Pose) -> None:
        """Write a sample's ego pose file into both trees (:func:`scenes.talk2radar.poses.write_pose`)."""
        for tree in self.trees:
            write_pose(tree, sample_id, pose)

    def write_sensors(
        self,
        frame_key: str,
        lidar: np.ndarray,
        radar: np.ndarray,
        lidar_calib: Calibration,
        radar_calib: Calibration,
        image: np.ndarray | None = None,
        jpeg_quality: int = 90,
    ) -> SensorFiles:
        """Write one frame's sensors under ``sources/<frame_key>/``.

        Args:
            lidar: ``(N, 4)`` LiDAR frame.
            radar: ``(M, 7)`` in the LiDAR frame; stored in the radar frame as VoD does.
            image: ``(H, W, 3)`` uint8 camera image whose projection is ``lidar_calib.P2``
                (written as ``image.jpg``), or None.
            jpeg_quality: JPEG quality of the image.
        """
        folder = source_dir(self.root, frame_key)
        files = SensorFiles.in_folder(folder)
        if image is not None:
            image = np.asarray(image)
            if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
                raise ValueError(
                    f"{frame_key}: the image must be (H, W, 3) uint8, got {image.shape} {image.dtype}"
                )
            size = (int(image.shape[1]), int(image.shape[0]))
            problem = check_principal_point(
                size, (float(lidar_calib.P2[0, 2]), float(lidar_calib.P2[1, 2])), frame_key
            )
            if problem is not None:
                raise ValueError(problem)
            files = replace(files, image=folder / SOURCE_IMAGE, image_size=size)
            write_jpeg(files.image, image, jpeg_quality)
        lidar_to_radar = np.linalg.inv(sensor_to_lidar(lidar_calib, radar_calib))
        write_points(files.lidar_bin, np.asarray(lidar, dtype=np.float32).reshape(-1, 4))
        radar_arr = np.asarray(radar, dtype=np.float64).reshape(-1, 7)
        write_points(files.radar_bin, transform_points(radar_arr, lidar_to_radar))
        atomic_write_text(files.lidar_calib, lidar_calib.to_text())
        atomic_write_text(files.radar_calib, radar_calib.to_text())
        return files

    def write_sample(
        self,
        sample_id: str | int,
        files: SensorFiles,
        boxes: np.ndarray,
        classes: Sequence[str],
        prompt: str,
        meta: SampleMeta | None = None,
        calib: Calibration | None = None,
    ) -> str:
        """Write one sample (:func:`sample_text`, then :meth:`write_sample_text`); returns its
        5-digit id. The 2D boxes of ``label_2`` are clipped to the frame's image size
        (:meth:`SensorFiles.label_image_size`); ``calib`` defaults to ``files.lidar_calib``'s.
        """
        sid = format_id(sample_id)
        if not prompt or not prompt.strip():
            raise ValueError(f"sample {sid}: the prompt is empty")
        calib = calib if calib is not None else read_calib(files.lidar_calib)
        text = sample_text(boxes, classes, prompt, calib, files.label_image_size(), meta)
        return self.write_sample_text(sid, files, text)

    def write_sample_text(self, sample_id: str | int, files: SensorFiles, text: SampleText) -> str:
        """Write one sample: sensor links, camera image link, then the text files
        (:meth:`text_files`); returns its 5-digit id.

        The label file is written last among the tree files so that a sample whose label exists is
        complete; the id becomes visible to readers only through :meth:`write_image_sets`.
        """
        sid = format_id(sample_id)
        lidar_tree, radar_tree = self.trees
        link_or_copy(files.lidar_bin, sample_file(lidar_tree, VELODYNE, sid))
        link_or_copy(files.lidar_calib, sample_file(lidar_tree, CALIB, sid))
        link_or_copy(files.radar_bin, sample_file(radar_tree, VELODYNE, sid))
        link_or_copy(files.radar_calib, sample_file(radar_tree, CALIB, sid))
        if files.image is not None:
            for tree in self.trees:
                link_or_copy(files.image, sample_file(tree, IMAGE, sid, files.image.suffix))
        for path, content in self.text_files(sid, text):
            atomic_write_text(path, content)
        return sid

    def text_files(self, sample_id: str, text: SampleText) -> list[tuple[Path, str]]:
        """``(path, content)`` of a sample's text files in write order: the sidecar (if any), the
        prompt of each tree, the ``label_2`` of each tree (last: a sample whose label exists is
        complete)."""
        files = [] if text.meta is None else [(meta_file(self.root, sample_id), text.meta)]
        files += [(sample_file(tree, PROMPT, sample_id), text.prompt) for tree in self.trees]
        files += [(sample_file(tree, LABEL, sample_id), text.label) for tree in self.trees]
        return files

    def write_image_sets(self, splits: Mapping[str, Sequence[str | int]]) -> None:
        """Write ``ImageSets/<split>.txt`` in both trees (atomically, replacing old lists)."""
        for split, ids in splits.items():
            text = "".join(format_id(i) + "\n" for i in ids)
            for tree in self.trees:
                atomic_write_text(split_file(tree, split), text)
