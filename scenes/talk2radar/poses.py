"""Ego poses of a frame, as View-of-Delft writes them: ``<tree>/training/pose/<id>.json``.

A VoD pose file holds three JSON lines, one object each, with a 4 x 4 row-major matrix of 16
numbers: ``{"odomToCamera": [...]}``, ``{"mapToCamera": [...]}``, ``{"UTMToCamera": [...]}``
(specs/talk2radar-format-and-eval.md §2.6; the LiDAR and radar trees hold identical copies). Read
the ROS tf way, ``odomToCamera`` is the camera's pose in the odometry frame: the matrix that maps
camera coordinates into odometry coordinates (``T_odom_camera``), and so on for the map and UTM
frames. :class:`Pose` keeps the three; :func:`lidar_motion` turns two poses and the LiDAR
calibration into the motion of the LiDAR frame between two frames.

What a reader of a sequence needs: :func:`lidar_motion` (points of one frame in the next frame's
LiDAR frame) and :func:`consecutive` (whether two frames can be consecutive 10 Hz frames of one
drive: their cameras at most :data:`MAX_STEP` metres apart in UTM; another drive, or another
synthetic world, is far away).

Nothing here reads a sidecar; reading fails with :class:`~scenes.frame.RootError` naming the file
and line.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.geometry.calib import Calibration
from scenes.talk2radar.layout import POSE, format_id, sample_file
from scenes.utils.durable import atomic_write_text
from scenes.utils.errors import RootError
from scenes.utils.textfile import read_text_file

FRAME_RATE = 10.0
"""View-of-Delft's frame rate (Hz): consecutive frames are ``1 / FRAME_RATE`` s apart."""

MAX_STEP = 5.0
"""Largest camera displacement (m, UTM) between two consecutive frames (50 m/s at 10 Hz)."""

KEYS = ("odomToCamera", "mapToCamera", "UTMToCamera")
"""The keys of a pose file's three lines, in file order."""


@dataclass(frozen=True)
class Pose:
    """The camera's pose in the odometry, map and UTM frames (each ``(4, 4)`` float64, mapping
    camera coordinates into that frame)."""

    odom: np.ndarray
    map: np.ndarray
    utm: np.ndarray

    def __post_init__(self) -> None:
        for name in ("odom", "map", "utm"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (4, 4) or not np.all(np.isfinite(value)):
                raise ValueError(f"pose {name}: expected a finite 4 x 4 matrix")
            object.__setattr__(self, name, value)

    def to_text(self) -> str:
        """The file's text: three JSON lines, row-major matrices (as VoD)."""
        return "".join(
            json.dumps({key: [float(v) for v in m.reshape(-1)]}) + "\n"
            for key, m in zip(KEYS, (self.odom, self.map, self.utm), strict=True)
        )


def parse_pose(text: str, where: str = "pose") -> Pose:
    """A :class:`Pose` from a pose file's text; :class:`RootError` naming ``where`` and the line
    for anything else (a missing key, not 16 numbers)."""
    found: dict[str, np.ndarray] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            item = json.loads(line)
        except json.JSONDecodeError as exc:
            raise RootError(f"{where}:{lineno}: not JSON ({exc.msg})") from exc
        if not isinstance(item, dict) or len(item) != 1:
            raise RootError(f"{where}:{lineno}: expected one object with one of {list(KEYS)}")
        ((key, values),) = item.items()
        if key not in KEYS:
            raise RootError(f"{where}:{lineno}: unknown key {key!r}; expected one of {list(KEYS)}")
        try:
            matrix = np.array(values, dtype=np.float64).reshape(4, 4)
        except (TypeError, ValueError) as exc:
            raise RootError(f"{where}:{lineno}: {key} must hold 16 numbers") from exc
        if not np.all(np.isfinite(matrix)):
            raise RootError(f"{where}:{lineno}: {key} holds a value that is not finite")
        found[key] = matrix
    missing = [k for k in KEYS if k not in found]
    if missing:
        raise RootError(f"{where}: no {', '.join(missing)} line")
    return Pose(found["odomToCamera"], found["mapToCamera"], found["UTMToCamera"])


def pose_path(tree: Path, sample_id: str | int) -> Path:
    """``<tree>/training/pose/<id>.json``."""
    return sample_file(tree, POSE, format_id(sample_id))


def read_pose(tree: Path, sample_id: str | int) -> Pose | None:
    """The pose of a sample of ``tree`` (a root's LiDAR tree), or None when it has no pose file."""
    path = pose_path(tree, sample_id)
    if not path.exists() and not path.is_symlink():
        return None
    return parse_pose(read_text_file(path, "pose file", RootError), str(path))


def write_pose(tree: Path, sample_id: str | int, pose: Pose) -> Path:
    """Write a sample's pose file (atomically); returns its path."""
    path = pose_path(tree, sample_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, pose.to_text())
    return path


def lidar_motion(before: Pose, after: Pose, calib: Calibration) -> np.ndarray:
    """``(4, 4)``: a point's LiDAR-frame coordinates in frame ``before`` -> in frame ``after``
    (the inverse of the LiDAR's motion), through the odometry frame.

    ``calib.velo_to_cam`` (LiDAR -> camera, the same in both frames) links the LiDAR to the
    camera whose poses the files hold.
    """
    cam = calib.velo_to_cam
    return np.linalg.inv(after.odom @ cam) @ (before.odom @ cam)


def consecutive(before: Pose, after: Pose, max_step: float = MAX_STEP) -> bool:
    """Whether two poses can be consecutive frames of one drive: the camera moved at most
    ``max_step`` metres in UTM."""
    step = after.utm[:3, 3] - before.utm[:3, 3]
    return bool(math.hypot(*step) <= max_step)


def synthetic_pose(ego_x: float, calib: Calibration, utm_origin: tuple[float, float]) -> Pose:
    """The pose a synthetic drive writes: the ego ``ego_x`` m along the +x axis of its first
    frame's LiDAR frame, which is the odometry and map frame; UTM is that frame placed at
    ``utm_origin`` (easting, northing; x east, y north)."""
    lidar_in_odom = np.eye(4)
    lidar_in_odom[0, 3] = float(ego_x)
    camera_in_odom = lidar_in_odom @ np.linalg.inv(calib.velo_to_cam)
    to_utm = np.eye(4)
    to_utm[:2, 3] = utm_origin
    return Pose(camera_in_odom, camera_in_odom.copy(), to_utm @ camera_in_odom)
