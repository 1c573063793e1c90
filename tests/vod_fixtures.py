"""Small View-of-Delft-layout roots the tests write themselves (the ``write_vod_root`` fixture of
``conftest.py``). Not a test module.

The layout is the release's, as a researcher downloads it (written by
:class:`scenes.talk2radar.vod_writer.VodWriter`): ``lidar/`` and one radar tree (``radar`` by default: a
single scan) with ``ImageSets/`` and ``training/{velodyne,calib,label_2,image_2}``, the camera
image a 1936 x 1216 JPEG (VoD's size and intrinsics), the radar points stored in the radar's own
frame (2.51 m ahead of and 1.15 m below the LiDAR), label_2 listing *every* object given (the
metric classes and VoD's others, one of them beyond the annotated range), and no ``prompt/`` or
``meta/`` folder.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from scenes.frame.kitti import boxes_to_labels
from scenes.geometry.calib import IMAGE_SIZE, vod_lidar_calibration, vod_radar_calibration
from scenes.geometry.projection import project_box_edges
from scenes.talk2radar.vod_writer import VodWriter

GROUND_Z = -1.7
"""The flat ground of every fixture frame (LiDAR frame)."""


def vod_objects(index: int) -> tuple[np.ndarray, list[str]]:
    """The labelled objects of fixture frame ``index``: boxes ``(6, 7)`` (LiDAR frame) and their
    VoD class names. A car 15 m ahead (shifted 2 m per frame), a pedestrian, a cyclist, VoD's
    ``bicycle`` and ``rider`` (not metric classes) and a car 60 m ahead (beyond the annotated
    range, but in the camera's view)."""

    def on_ground(x: float, y: float, length: float, width: float, height: float, yaw: float):
        return [x, y, GROUND_Z + height / 2.0, length, width, height, yaw]

    boxes = np.array(
        [
            on_ground(15.0 + 2.0 * index, 2.0, 4.2, 1.8, 1.5, 0.1),
            on_ground(10.0, -3.0, 0.6, 0.6, 1.8, 0.0),
            on_ground(20.0, -5.0, 1.9, 0.7, 1.7, np.pi / 2),
            on_ground(12.0, 5.0, 1.7, 0.5, 1.0, 0.0),
            on_ground(25.0, 5.0, 0.8, 0.6, 1.7, 0.0),
            on_ground(60.0, 0.0, 4.4, 1.9, 1.6, 0.0),
        ]
    )
    return boxes, ["Car", "Pedestrian", "Cyclist", "bicycle", "rider", "Car"]


def _points(rng: np.random.Generator, boxes: np.ndarray) -> np.ndarray:
    """A flat ground and a cluster of points filling each object's box, ``(N, 4)`` float32."""
    ground = np.c_[
        rng.uniform([1.0, -20.0], [62.0, 20.0], size=(5000, 2)),
        rng.normal(GROUND_Z, 0.01, 5000),
        rng.uniform(0, 60, 5000),
    ]
    parts = [ground]
    for box in boxes:
        half = box[3:6] / 2.0
        local = rng.uniform(-half, half, size=(300, 3))
        c, s = np.cos(box[6]), np.sin(box[6])
        xy = local[:, :2] @ np.array([[c, s], [-s, c]]) + box[:2]
        parts.append(np.c_[xy, local[:, 2] + box[2], rng.uniform(100, 255, 300)])
    return np.concatenate(parts).astype(np.float32)


def _radar(rng: np.random.Generator, boxes: np.ndarray) -> np.ndarray:
    """Sparse radar ``(M, 7)`` in the LiDAR frame: clutter, and the first car receding at 4 m/s."""
    clutter = np.c_[
        rng.uniform([2.0, -15.0, -1.5], [45.0, 15.0, 0.5], size=(60, 3)),
        rng.normal(5, 5, 60),
        np.zeros((60, 2)),
        np.zeros(60),
    ]
    car = boxes[0]
    on_car = np.c_[
        rng.uniform(car[:3] - car[3:6] / 3, car[:3] + car[3:6] / 3, size=(8, 3)),
        np.full(8, 10.0),
        np.full((8, 2), 4.0),
        np.zeros(8),
    ]
    return np.r_[clutter, on_car].astype(np.float32)


def _image(boxes: np.ndarray, classes: Sequence[str]) -> np.ndarray:
    """A 1936 x 1216 picture: sky over road, each object a filled patch where it projects."""
    width, height = IMAGE_SIZE
    calib = vod_lidar_calibration()
    rows = np.linspace(0.0, 1.0, height)[:, None, None]
    sky, road = np.array([150, 185, 225]), np.array([95, 95, 100])
    horizon = float(calib.P2[1, 2]) / height
    picture = np.where(rows < horizon, sky * (0.7 + 0.3 * rows / horizon), road)
    pil = Image.fromarray(np.broadcast_to(picture, (height, width, 3)).astype(np.uint8))
    draw = ImageDraw.Draw(pil)
    fills = {"Car": (200, 60, 40), "Pedestrian": (60, 60, 160), "Cyclist": (40, 140, 60)}
    segments, drawn = project_box_edges(boxes, calib, IMAGE_SIZE)
    order = np.argsort([-b[0] for b in boxes])  # far first
    for k in order:
        if drawn[k].any():
            ends = segments[k][drawn[k]].reshape(-1, 2)
            rect = [*ends.min(axis=0), *ends.max(axis=0)]
            draw.rectangle(rect, fill=fills.get(classes[k], (120, 120, 60)))
    return np.asarray(pil, dtype=np.uint8)


def write_vod_root(
    path: Path,
    frames: int = 3,
    seed: int = 0,
    radar_folder: str = "radar",
    images: bool = True,
    splits: Mapping[str, Sequence[int]] | None = None,
) -> Path:
    """Write a VoD-layout root (see the module docstring) with ``frames`` frames, ids
    ``00000..``, through the one writer of the layout (:class:`scenes.talk2radar.vod_writer.VodWriter`);
    ``splits`` maps ImageSets names to frame indices (default ``val``: all of them, ``train``:
    the first; ``{}``: no ImageSets folder, as the devkit's example set). Returns ``path``."""
    rng = np.random.default_rng(seed)
    lidar_calib, radar_calib = vod_lidar_calibration(), vod_radar_calibration()
    writer = VodWriter(path, (radar_folder,))
    for index in range(frames):
        boxes, classes = vod_objects(index)
        writer.write_sensors(
            index,
            _points(rng, boxes),
            {radar_folder: _radar(rng, boxes)},
            lidar_calib,
            radar_calib,
            image=_image(boxes, classes) if images else None,
        )
        writer.write_labels(index, boxes_to_labels(boxes, classes, lidar_calib))
    chosen = splits if splits is not None else {"val": range(frames), "train": [0]}
    writer.write_image_sets(chosen)
    return path
