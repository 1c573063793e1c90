"""What the sensors say about each box: point counts, radar velocity, distance.

For each box (LiDAR frame): the LiDAR points inside, the radar points inside (the box grown by
``radar_margin`` per side: radar returns scatter around an object's surface, more in height), the
mean ego-motion-compensated radial velocity of those radar points (column 5,
``v_r_compensated``; positive = moving away, VoD's sign) and the motion it indicates, the BEV
distance of the box centre from the ego LiDAR, and the prompt depth (the forward distance of the
box's nearest BEV corner, what "about 15 m ahead" measures, see :mod:`scenes.language.prompts`).

:func:`estimate_velocity` turns a mean radial velocity into a ground velocity for the prompt
suggester. Radar measures only the component along the line of sight; road users move along their
heading, so the speed along the heading is ``v_r / cos(phi)`` with ``phi`` the angle between the
heading and the line of sight. When the heading is nearly perpendicular to the line of sight
(``|cos(phi)| < min_cos``: a crossing object) that division is unreliable, and the radial part alone
is returned, a lower bound of the true speed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from scenes.geometry.actors import MOVING_SPEED
from scenes.geometry.boxes import bev_corners, points_in_boxes

RADAR_VR_COMPENSATED = 5
"""Column of ``v_r_compensated`` in a radar point ``(x, y, z, rcs, v_r, v_r_compensated, time)``."""


class Motion(enum.Enum):
    """Sign of a box's mean compensated radial velocity."""

    APPROACHING = "approaching"
    RECEDING = "receding"
    STATIC = "static"
    UNKNOWN = "unknown"


@dataclass(frozen=True)
class EvidenceConfig:
    """Parameters of :func:`box_evidence`.

    Attributes:
        lidar_margin: Growth (m per side) of each box for counting LiDAR points.
        radar_margin: Growth (m per side) of each box for radar points.
        static_threshold: ``|mean v_r|`` (m/s) at or below which a box counts as static
            (default: the project's moving-speed threshold, 0.5 m/s).
    """

    lidar_margin: float = 0.0
    radar_margin: float = 0.3
    static_threshold: float = MOVING_SPEED

    def __post_init__(self) -> None:
        if self.lidar_margin < 0 or self.radar_margin < 0 or self.static_threshold < 0:
            raise ValueError("EvidenceConfig: margins and static_threshold must be >= 0")


@dataclass(frozen=True)
class BoxEvidence:
    """The evidence for one box.

    Attributes:
        lidar_points: LiDAR points inside.
        radar_points: Radar points inside the grown box.
        mean_radial_velocity: Mean ``v_r_compensated`` of those radar points (m/s), None without.
        motion: Approaching (mean < -threshold), receding (> threshold), static, or unknown (no
            radar point).
        distance: BEV distance from the LiDAR origin to the box centre (m).
        depth: Forward distance of the box's nearest BEV corner, ``min x`` (m).
    """

    lidar_points: int
    radar_points: int
    mean_radial_velocity: float | None
    motion: Motion
    distance: float
    depth: float


def _grow(boxes: np.ndarray, margin: float) -> np.ndarray:
    out = boxes.copy()
    out[:, 3:6] += 2.0 * margin
    return out


def classify_motion(mean_radial_velocity: float | None, threshold: float = MOVING_SPEED) -> Motion:
    """Approaching / receding / static from a mean radial velocity (m/s, + = away)."""
    if mean_radial_velocity is None:
        return Motion.UNKNOWN
    if mean_radial_velocity < -threshold:
        return Motion.APPROACHING
    if mean_radial_velocity > threshold:
        return Motion.RECEDING
    return Motion.STATIC


def box_evidence(
    boxes: np.ndarray,
    lidar: np.ndarray,
    radar: np.ndarray,
    config: EvidenceConfig | None = None,
) -> tuple[BoxEvidence, ...]:
    """Evidence for each box.

    Args:
        boxes: ``(K, 7)`` LiDAR frame.
        lidar: ``(N, >=3)`` LiDAR points, LiDAR frame.
        radar: ``(M, 7)`` radar points in the LiDAR frame (``v_r_compensated`` in column 5).
        config: Margins and threshold (default :class:`EvidenceConfig()`).

    Returns:
        ``K`` :class:`BoxEvidence`, in box order.
    """
    cfg = config if config is not None else EvidenceConfig()
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return ()
    lidar = np.asarray(lidar, dtype=np.float64)
    lidar = np.zeros((0, 4)) if lidar.size == 0 else lidar
    if lidar.ndim != 2 or lidar.shape[1] < 3:
        raise ValueError(f"box_evidence: lidar must have shape (N, >=3), got {lidar.shape}")
    radar = np.asarray(radar, dtype=np.float64)
    radar = np.zeros((0, 7)) if radar.size == 0 else radar
    if radar.ndim != 2 or radar.shape[1] != 7:
        raise ValueError(f"box_evidence: radar must have shape (M, 7), got {radar.shape}")
    in_lidar = points_in_boxes(lidar, _grow(b, cfg.lidar_margin))
    in_radar = points_in_boxes(radar, _grow(b, cfg.radar_margin))
    depth = bev_corners(b)[:, :, 0].min(axis=1)
    out = []
    for k in range(len(b)):
        sel = in_radar[:, k]
        mean = float(radar[sel, RADAR_VR_COMPENSATED].mean()) if sel.any() else None
        out.append(
            BoxEvidence(
                lidar_points=int(in_lidar[:, k].sum()),
                radar_points=int(sel.sum()),
                mean_radial_velocity=mean,
                motion=classify_motion(mean, cfg.static_threshold),
                distance=float(np.hypot(b[k, 0], b[k, 1])),
                depth=float(depth[k]),
            )
        )
    return tuple(out)


def estimate_velocity(
    box: np.ndarray, mean_radial_velocity: float | None, min_cos: float = 0.3
) -> np.ndarray:
    """A ground velocity ``(2,)`` (m/s, LiDAR axes) consistent with a box's radial velocity.

    Args:
        box: ``(7,)`` LiDAR frame; its yaw gives the assumed direction of travel.
        mean_radial_velocity: Mean compensated radial velocity (m/s), or None (-> zero velocity).
        min_cos: Below this ``|cos|`` between heading and line of sight the velocity is taken
            along the line of sight (module docstring).
    """
    b = np.asarray(box, dtype=np.float64).reshape(7)
    if mean_radial_velocity is None or mean_radial_velocity == 0.0:
        return np.zeros(2)
    norm = float(np.hypot(b[0], b[1]))
    if norm < 1e-9:
        return np.zeros(2)
    los = b[:2] / norm
    heading = np.array([np.cos(b[6]), np.sin(b[6])])
    cos_phi = float(heading @ los)
    if abs(cos_phi) < min_cos:
        return float(mean_radial_velocity) * los
    return float(mean_radial_velocity) / cos_phi * heading
