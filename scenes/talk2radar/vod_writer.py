"""Writing a root in the View-of-Delft release layout: :class:`VodWriter`, the one writer of it
(used by ``python -m scenes.export_real``, the tests' VoD fixtures and the benchmarks).

The layout is the release's, as a researcher downloads it (the devkit's ``GETTING_STARTED.md``)::

    <root>/lidar/ImageSets/{train,val,train_val,test}.txt
    <root>/lidar/training/{velodyne,calib,image_2,label_2}/<id>.{bin,txt,jpg,txt}
    <root>/radar/..., <root>/radar_3frames/..., <root>/radar_5frames/...
                                   the same folders in each radar tree written: radar points
                                   (in the radar's own frame) and the radar calibration

``label_2`` lists every annotated object of the frame (:mod:`scenes.synth.vod_labels` says which) and
is the same file in every tree; there is no ``prompt/`` folder and no Talk2PC file (``meta/``,
``sources/``). Paths come from :mod:`scenes.talk2radar.layout`; every file is written or hard-linked through
:mod:`scenes.utils.durable`. The reader is :class:`scenes.talk2radar.root.Talk2RadarRoot` (or
:class:`scenes.talk2radar.scene_labels.SceneLabels` for the labels alone).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from scenes.frame.image import write_jpeg
from scenes.frame.kitti import ObjectLabel, label_file_text
from scenes.geometry.calib import Calibration, sensor_to_lidar, transform_points
from scenes.talk2radar.layout import (
    CALIB,
    IMAGE,
    LABEL,
    LIDAR_FOLDER,
    RADAR_FOLDERS,
    VELODYNE,
    format_id,
    sample_file,
    split_file,
)
from scenes.talk2radar.pointcloud import LIDAR_FEATURES, RADAR_FEATURES, write_points
from scenes.talk2radar.writer import LABEL_DECIMALS, SensorFiles
from scenes.utils.durable import atomic_write_text, link_or_copy

__all__ = ["VodWriter"]


class VodWriter:
    """Writes frames in the View-of-Delft release layout (see the module docstring).

    Args:
        root: The root folder.
        radar_folders: The radar trees to write (``radar``, ``radar_3frames``,
            ``radar_5frames``), each once.

    Raises:
        ValueError: an unknown, repeated or missing radar tree.
    """

    def __init__(self, root: str | Path, radar_folders: Sequence[str] = ("radar",)) -> None:
        folders = tuple(radar_folders)
        unknown = [f for f in folders if f not in RADAR_FOLDERS]
        if unknown or not folders or len(set(folders)) != len(folders):
            raise ValueError(
                f"radar_folders must be distinct names of {RADAR_FOLDERS}, got {list(folders)}"
            )
        self.root = Path(root)
        self.radar_folders = folders
        self.lidar_tree = self.root / LIDAR_FOLDER
        self.trees = (self.lidar_tree, *(self.root / f for f in folders))

    def __repr__(self) -> str:
        return f"VodWriter({str(self.root)!r}, radar_folders={list(self.radar_folders)})"

    def radar_tree(self, folder: str) -> Path:
        """The tree of radar folder ``folder`` (one of :attr:`radar_folders`)."""
        if folder not in self.radar_folders:
            raise ValueError(f"{self}: writes no radar tree {folder!r}")
        return self.root / folder

    def write_sensors(
        self,
        sample_id: str | int,
        lidar: np.ndarray,
        radar: Mapping[str, np.ndarray],
        lidar_calib: Calibration,
        radar_calib: Calibration,
        image: np.ndarray | None = None,
        jpeg_quality: int = 90,
    ) -> None:
        """Write one frame's sensor files from arrays.

        Args:
            lidar: ``(N, 4)`` LiDAR frame.
            radar: Radar folder -> ``(M, 7)`` points in the LiDAR frame, for every radar tree
                written; stored in the radar frame, as VoD.
            image: ``(H, W, 3)`` uint8 camera image (projection ``lidar_calib.P2``), or None.
        """
        sid = format_id(sample_id)
        if set(radar) != set(self.radar_folders):
            raise ValueError(f"{self}: radar points given for {sorted(radar)}")
        write_points(
            sample_file(self.lidar_tree, VELODYNE, sid),
            np.asarray(lidar).reshape(-1, LIDAR_FEATURES),
        )
        atomic_write_text(sample_file(self.lidar_tree, CALIB, sid), lidar_calib.to_text())
        to_radar = np.linalg.inv(sensor_to_lidar(lidar_calib, radar_calib))
        for folder, points in radar.items():
            pts = np.asarray(points, dtype=np.float64).reshape(-1, RADAR_FEATURES)
            self.write_radar(sid, folder, transform_points(pts, to_radar))
            atomic_write_text(
                sample_file(self.radar_tree(folder), CALIB, sid), radar_calib.to_text()
            )
        if image is not None:
            first = sample_file(self.lidar_tree, IMAGE, sid)
            write_jpeg(first, image, jpeg_quality)
            for tree in self.trees[1:]:
                link_or_copy(first, sample_file(tree, IMAGE, sid))

    def write_radar(self, sample_id: str | int, folder: str, points: np.ndarray) -> Path:
        """Write one radar tree's points ``(M, 7)``, already in the radar frame; returns the file."""
        path = sample_file(self.radar_tree(folder), VELODYNE, format_id(sample_id))
        write_points(path, np.asarray(points, dtype=np.float32).reshape(-1, RADAR_FEATURES))
        return path

    def link_sensors(self, sample_id: str | int, files: SensorFiles, folder: str) -> None:
        """Hard-link one frame's sensor files (a copy where links are impossible): the LiDAR
        points and calibration into the LiDAR tree, ``files.radar_bin`` and ``files.radar_calib``
        into radar tree ``folder``, the camera image (if any) into both. Linking a file onto
        itself does nothing (the radar points :meth:`write_radar` wrote)."""
        sid = format_id(sample_id)
        radar_tree = self.radar_tree(folder)
        link_or_copy(files.lidar_bin, sample_file(self.lidar_tree, VELODYNE, sid))
        link_or_copy(files.lidar_calib, sample_file(self.lidar_tree, CALIB, sid))
        link_or_copy(files.radar_bin, sample_file(radar_tree, VELODYNE, sid))
        link_or_copy(files.radar_calib, sample_file(radar_tree, CALIB, sid))
        if files.image is not None:
            for tree in (self.lidar_tree, radar_tree):
                link_or_copy(files.image, sample_file(tree, IMAGE, sid, files.image.suffix))

    def write_labels(self, sample_id: str | int, labels: Sequence[ObjectLabel]) -> None:
        """Write the frame's ``label_2`` (:data:`scenes.talk2radar.writer.LABEL_DECIMALS` decimals) into
        every tree. Written after the sensor files: a frame whose labels exist is complete."""
        text = label_file_text(labels, LABEL_DECIMALS)
        for tree in self.trees:
            atomic_write_text(sample_file(tree, LABEL, format_id(sample_id)), text)

    def label_files(self, sample_id: str | int) -> list[Path]:
        """The frame's ``label_2`` file in every tree."""
        return [sample_file(tree, LABEL, format_id(sample_id)) for tree in self.trees]

    def write_image_sets(self, splits: Mapping[str, Sequence[str | int]]) -> None:
        """Write ``ImageSets/<split>.txt`` in every tree (atomically, replacing old lists)."""
        for split, ids in splits.items():
            text = "".join(format_id(i) + "\n" for i in ids)
            for tree in self.trees:
                atomic_write_text(split_file(tree, split), text)
