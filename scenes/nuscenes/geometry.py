"""nuScenes poses and frames: quaternions (``w, x, y, z``, as the tables store them), rigid
transforms ``(4, 4)`` float64, and the turn between LIDAR_TOP and the model frame.

Frames: a sensor frame (LIDAR_TOP: x right, y forward, z up; a radar: x forward of that radar;
CAM_FRONT: x right, y down, z forward), the ego frame (x forward, y left, z up) at one
sample_data's own timestamp (its ``ego_pose``), and the global frame. A point goes sensor ->
ego(t) through the sensor's ``calibrated_sensor`` and ego(t) -> global through that
sample_data's ``ego_pose``; the reverse chain brings it into another sample_data's sensor frame
(the devkit's ``from_file_multisweep`` chain). The model frame is the key frame's LIDAR_TOP
turned by 90 degrees about z (:data:`LIDAR_TO_MODEL`): x forward, y left, z up, origin at the
LiDAR (``../shared/ARCHITECTURE.md``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from scenes.geometry.boxes import wrap_yaw

__all__ = [
    "LIDAR_TO_MODEL",
    "MODEL_TO_LIDAR",
    "boxes_from_poses",
    "pose_matrix",
    "quaternion_from_matrix",
    "quaternion_from_yaw",
    "quaternion_matrix",
    "transform",
]


def quaternion_matrix(q: Sequence[float]) -> np.ndarray:
    """The ``(3, 3)`` rotation of a quaternion ``(w, x, y, z)`` (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(np.asarray(q, dtype=np.float64))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_matrix(m: np.ndarray) -> np.ndarray:
    """The quaternion ``(4,)`` ``(w, x, y, z)`` with ``w >= 0`` of a ``(3, 3)`` rotation."""
    m = np.asarray(m, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.asarray(q)
    out /= np.linalg.norm(out)
    return -out if out[0] < 0 else out


def quaternion_from_yaw(yaw: float) -> np.ndarray:
    """The quaternion ``(w, x, y, z)`` of a turn by ``yaw`` radians about +z."""
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def pose_matrix(translation: Sequence[float], rotation: Sequence[float]) -> np.ndarray:
    """The ``(4, 4)`` transform child -> parent of a pose record (``translation`` (3,) metres,
    ``rotation`` (4,) ``w, x, y, z``): a calibrated_sensor (sensor -> ego) or an ego_pose
    (ego -> global)."""
    out = np.eye(4)
    out[:3, :3] = quaternion_matrix(rotation)
    out[:3, 3] = np.asarray(translation, dtype=np.float64)
    return out


def transform(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """``points (N, 3)`` moved by a ``(4, 4)`` transform, float64."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return pts @ matrix[:3, :3].T + matrix[:3, 3]


LIDAR_TO_MODEL = np.array(
    [[0.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
"""``(4, 4)`` LIDAR_TOP (x right, y forward) -> model frame (x forward, y left): a turn by -90
degrees about z, origin kept (model x = LiDAR y, model y = -LiDAR x)."""
MODEL_TO_LIDAR = LIDAR_TO_MODEL.T.copy()
"""``(4, 4)`` the inverse of :data:`LIDAR_TO_MODEL`."""


def boxes_from_poses(
    translations: np.ndarray, sizes_wlh: np.ndarray, rotations: np.ndarray, to_frame: np.ndarray
) -> np.ndarray:
    """nuScenes boxes moved into a frame whose z is up (the model frame), as ``(K, 7)`` float64
    ``x, y, z, l, w, h, yaw`` (z the geometric centre, yaw about +z from +x, wrapped).

    Args:
        translations: ``(K, 3)`` box centres in the source frame (global for sample_annotation).
        sizes_wlh: ``(K, 3)`` nuScenes sizes ``w, l, h``.
        rotations: ``(K, 4)`` quaternions ``w, x, y, z`` in the source frame.
        to_frame: ``(4, 4)`` source -> target transform.

    The heading is the box's x axis (its length) as the target frame sees it, projected on the
    ground plane; a box tilted out of that plane keeps only its yaw.
    """
    translations = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
    sizes_wlh = np.asarray(sizes_wlh, dtype=np.float64).reshape(-1, 3)
    rotations = np.asarray(rotations, dtype=np.float64).reshape(-1, 4)
    out = np.zeros((len(translations), 7))
    if not len(out):
        return out
    out[:, :3] = transform(translations, to_frame)
    out[:, 3] = sizes_wlh[:, 1]
    out[:, 4] = sizes_wlh[:, 0]
    out[:, 5] = sizes_wlh[:, 2]
    for i, q in enumerate(rotations):
        heading = to_frame[:3, :3] @ quaternion_matrix(q)[:, 0]
        out[i, 6] = np.arctan2(heading[1], heading[0])
    out[:, 6] = wrap_yaw(out[:, 6])
    return out
