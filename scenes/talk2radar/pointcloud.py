"""Point-cloud ``.bin`` files: little-endian float32, no header, ``(N, F)`` with F = 4 (LiDAR)
or 7 (radar). Reading is strict: a size that is not a multiple of ``4 * F`` bytes, or a NaN or
infinite value in any channel of any point, is an error naming the file (and the first bad point
and its channel, :data:`LIDAR_FEATURE_NAMES` / :data:`RADAR_FEATURE_NAMES`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenes.utils.durable import atomic_write_bytes
from scenes.utils.textfile import read_file_bytes

LIDAR_FEATURES = 4
RADAR_FEATURES = 7
LIDAR_FEATURE_NAMES: tuple[str, ...] = ("x", "y", "z", "intensity")
"""The channels of a LiDAR point, in file order."""
RADAR_FEATURE_NAMES: tuple[str, ...] = ("x", "y", "z", "rcs", "v_r", "v_r_compensated", "time")
"""The channels of a radar point, in file order."""
_NAMES = {LIDAR_FEATURES: LIDAR_FEATURE_NAMES, RADAR_FEATURES: RADAR_FEATURE_NAMES}


class PointCloudError(ValueError):
    """A point-cloud file is malformed; the message names the file."""


def read_points(path: str | Path, num_features: int) -> np.ndarray:
    """Read ``(N, num_features)`` float32 points."""
    path = Path(path)
    raw = read_file_bytes(path, "point-cloud file", PointCloudError)
    record = 4 * num_features
    if len(raw) % record:
        raise PointCloudError(
            f"{path}: {len(raw)} bytes is not a multiple of {record} "
            f"({num_features} float32 features per point)"
        )
    points = np.frombuffer(raw, dtype="<f4").reshape(-1, num_features).astype(np.float32)
    validate_points(points, num_features, source=str(path))
    return points


def validate_points(points: np.ndarray, num_features: int, source: str = "<points>") -> None:
    """Raise :class:`PointCloudError` for a wrong shape or a NaN or infinite value in any
    channel (the message names the first such point and its channel)."""
    if points.ndim != 2 or points.shape[1] != num_features:
        raise PointCloudError(f"{source}: expected shape (N, {num_features}), got {points.shape}")
    bad = ~np.isfinite(points)
    rows = np.flatnonzero(bad.any(axis=1))
    if len(rows):
        first = int(rows[0])
        column = int(np.argmax(bad[first]))
        names = _NAMES.get(num_features)
        channel = f"{names[column]!r} (channel {column})" if names else f"channel {column}"
        raise PointCloudError(
            f"{source}: point {first} has a NaN or infinite {channel}; bad points: "
            f"{len(rows)} of {len(points)}"
        )


def write_points(path: str | Path, points: np.ndarray) -> None:
    """Write points atomically (:func:`scenes.utils.durable.atomic_write_bytes`) as little-endian
    float32."""
    path = Path(path)
    pts = np.ascontiguousarray(points, dtype="<f4")
    validate_points(pts, pts.shape[1] if pts.ndim == 2 else -1, source=str(path))
    atomic_write_bytes(path, pts.tobytes())
