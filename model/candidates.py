"""Object candidates of the referent stage and their explicit, text-free evidence.

A candidate is one box ``x, y, z, l, w, h, yaw`` (LiDAR frame, z at the geometric centre) with a
class and a detection score; at inference the candidates are the text-agnostic C3D-RECHead's
decoded detections, in training the frame's actors (slightly jittered) plus the detector's own
false positives. For each candidate this module computes, as pure numpy functions:

- :func:`geometry_features` ``(K, GEOMETRY_FEATURES)``: class one-hot, detection score, centre,
  size, heading, nearest-edge depth (``min x`` of the BEV corners, the depth the prompts speak of),
  bearing, range, lateral offset;
- :func:`lidar_evidence` ``(K, LIDAR_EVIDENCE)``: LiDAR points inside the box (count, intensity,
  height spread);
- :func:`radar_evidence` ``(K, RADAR_EVIDENCE)``: radar points inside the box footprint grown by
  :data:`RADAR_MARGIN` (count, radial and ego-compensated radial velocity, RCS) and the box's motion
  read off the accumulated scans' ``time`` field: the least-squares slope of the points' x and y
  over the scan index, i.e. the displacement per scan, which sees crossing motion that Doppler
  cannot.

:func:`pool_bev` samples a BEV feature map at metric positions (bilinear, differentiable), for the
learned part of each candidate's description.

Scales: every feature is brought to roughly unit range by the constants below, so that the
referent stage can compare them with the numbers of a prompt (see :mod:`model.numerals`) through
plain linear layers.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from model.grid import BevGrid
from scenes.actors import CLASSES
from scenes.boxes import bev_corners

GEOMETRY_FEATURES = 17
LIDAR_EVIDENCE = 4
RADAR_EVIDENCE = 10
RADAR_MARGIN = 0.5
"""Metres added on every side of a box's footprint when gathering its radar points (radar points
scatter around an object's surface by more than LiDAR points do)."""
LIDAR_MARGIN = 0.2
DEPTH_SCALE = 50.0
LATERAL_SCALE = 25.0
SPEED_SCALE = 10.0


def _boxes(boxes: np.ndarray) -> np.ndarray:
    return np.asarray(boxes, dtype=np.float64).reshape(-1, 7)


def nearest_depth(boxes: np.ndarray) -> np.ndarray:
    """Forward distance ``(K,)`` of each box's nearest point: ``min x`` over its BEV corners."""
    b = _boxes(boxes)
    if len(b) == 0:
        return np.zeros(0)
    return bev_corners(b)[:, :, 0].min(axis=1)


def geometry_features(boxes: np.ndarray, labels: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Explicit geometry of ``K`` candidates.

    Args:
        boxes: ``(K, 7)`` LiDAR frame.
        labels: ``(K,)`` class indices into :data:`scenes.actors.CLASSES`.
        scores: ``(K,)`` detection scores in ``[0, 1]``.

    Returns:
        ``(K, GEOMETRY_FEATURES)`` float32: one-hot class (3), score, x, y, z, log l, log w, log h,
        sin yaw, cos yaw, nearest-edge depth, bearing (rad), range, ``|y|``, nearest-edge depth
        minus centre x (how deep the box reaches).
    """
    b = _boxes(boxes)
    k = len(b)
    out = np.zeros((k, GEOMETRY_FEATURES), dtype=np.float32)
    if k == 0:
        return out
    labels = np.asarray(labels, dtype=np.int64).reshape(k)
    out[np.arange(k), labels] = 1.0
    depth = nearest_depth(b)
    rng = np.hypot(b[:, 0], b[:, 1])
    out[:, 3] = np.asarray(scores, dtype=np.float64).reshape(k)
    out[:, 4] = b[:, 0] / DEPTH_SCALE
    out[:, 5] = b[:, 1] / LATERAL_SCALE
    out[:, 6] = b[:, 2] / 2.0
    out[:, 7:10] = np.log(np.maximum(b[:, 3:6], 1e-3))
    out[:, 10] = np.sin(b[:, 6])
    out[:, 11] = np.cos(b[:, 6])
    out[:, 12] = depth / DEPTH_SCALE
    out[:, 13] = np.arctan2(b[:, 1], b[:, 0])
    out[:, 14] = rng / DEPTH_SCALE
    out[:, 15] = np.abs(b[:, 1]) / LATERAL_SCALE
    out[:, 16] = (b[:, 0] - depth) / 2.0
    return out


def _in_footprints(points: np.ndarray, boxes: np.ndarray, margin: float, use_z: bool) -> list:
    """Indices of ``points (N, >=3)`` inside each box grown by ``margin`` (list of K arrays).

    Points are sorted by x once; each box only tests the slice within its bounding circle's x
    range, so the cost is about ``N log N + sum of slice sizes`` rather than ``N * K``.
    """
    if len(boxes) == 0:
        return []
    if len(points) == 0:
        return [np.zeros(0, dtype=np.int64) for _ in boxes]
    order = np.argsort(points[:, 0], kind="stable")
    xs = points[order, 0]
    out = []
    for box in boxes:
        r = 0.5 * float(np.hypot(box[3], box[4])) + margin
        lo, hi = np.searchsorted(xs, [box[0] - r, box[0] + r])
        idx = order[lo:hi]
        p = points[idx]
        dx, dy = p[:, 0] - box[0], p[:, 1] - box[1]
        c, s = np.cos(box[6]), np.sin(box[6])
        lx, ly = dx * c + dy * s, -dx * s + dy * c
        keep = (np.abs(lx) <= box[3] / 2 + margin) & (np.abs(ly) <= box[4] / 2 + margin)
        if use_z:
            keep &= np.abs(p[:, 2] - box[2]) <= box[5] / 2 + margin
        out.append(idx[keep])
    return out


def lidar_evidence(boxes: np.ndarray, lidar: np.ndarray) -> np.ndarray:
    """LiDAR evidence ``(K, LIDAR_EVIDENCE)``: log(1 + points in the box grown by
    :data:`LIDAR_MARGIN`), mean intensity / 255, height spread of those points (m), whether any."""
    b = _boxes(boxes)
    pts = np.asarray(lidar, dtype=np.float64).reshape(-1, 4)
    out = np.zeros((len(b), LIDAR_EVIDENCE), dtype=np.float32)
    for i, idx in enumerate(_in_footprints(pts, b, LIDAR_MARGIN, use_z=True)):
        if len(idx):
            p = pts[idx]
            out[i] = (np.log1p(len(idx)), p[:, 3].mean() / 255.0, np.ptp(p[:, 2]), 1.0)
    return out


def _scan_slope(values: np.ndarray, times: np.ndarray) -> float:
    """Least-squares slope of ``values`` over ``times`` (0 when fewer than two distinct times)."""
    t = times - times.mean()
    denom = float(np.sum(t * t))
    if denom < 1e-9:
        return 0.0
    return float(np.sum(t * (values - values.mean())) / denom)


def radar_evidence(boxes: np.ndarray, radar: np.ndarray) -> np.ndarray:
    """Radar evidence ``(K, RADAR_EVIDENCE)`` from points ``(M, 7)`` (x, y, z, rcs, v_r,
    v_r_compensated, time; LiDAR frame) in each box's footprint grown by :data:`RADAR_MARGIN`.

    Columns: log(1 + count), log(1 + count of the newest scan), mean v_r, mean v_r_compensated,
    median v_r_compensated, spread (std) of v_r_compensated, mean RCS / 10, displacement per scan
    along x and along y (slope over the ``time`` field, m / scan), whether any point; velocities in
    units of :data:`SPEED_SCALE` m/s.
    """
    b = _boxes(boxes)
    pts = np.asarray(radar, dtype=np.float64).reshape(-1, 7)
    out = np.zeros((len(b), RADAR_EVIDENCE), dtype=np.float32)
    for i, idx in enumerate(_in_footprints(pts, b, RADAR_MARGIN, use_z=False)):
        if not len(idx):
            continue
        p = pts[idx]
        vc = p[:, 5]
        out[i] = (
            np.log1p(len(idx)),
            np.log1p(int(np.sum(p[:, 6] == 0))),
            p[:, 4].mean() / SPEED_SCALE,
            vc.mean() / SPEED_SCALE,
            np.median(vc) / SPEED_SCALE,
            vc.std() / SPEED_SCALE,
            p[:, 3].mean() / 10.0,
            _scan_slope(p[:, 0], p[:, 6]),
            _scan_slope(p[:, 1], p[:, 6]),
            1.0,
        )
    return out


def pool_bev(feature_map: Tensor, grid: BevGrid, xy: Tensor) -> Tensor:
    """Bilinear samples of a BEV map at metric positions.

    Args:
        feature_map: ``(C, H, W)`` on ``grid`` (``[c, iy, ix]``, see :mod:`model.grid`).
        grid: The map's grid.
        xy: ``(K, 2)`` positions in the LiDAR frame (metres), on the map's device.

    Returns:
        ``(K, C)``; positions outside the grid sample zeros. Differentiable in ``feature_map``.
    """
    if xy.shape[0] == 0:
        return feature_map.new_zeros((0, feature_map.shape[0]))
    gx = (xy[:, 0] - grid.x_min) / (grid.x_max - grid.x_min) * 2.0 - 1.0
    gy = (xy[:, 1] - grid.y_min) / (grid.y_max - grid.y_min) * 2.0 - 1.0
    g = torch.stack([gx, gy], dim=-1).to(feature_map.dtype)[None, None]  # (1, 1, K, 2)
    out = F.grid_sample(
        feature_map[None], g, mode="bilinear", padding_mode="zeros", align_corners=False
    )
    return out[0, :, 0].T


def class_indices(names: tuple[str, ...] | list[str]) -> np.ndarray:
    """Class indices ``(K,)`` of class names (each must be one of ``CLASSES``)."""
    return np.array([CLASSES.index(n) for n in names], dtype=np.int64)


__all__ = [
    "GEOMETRY_FEATURES",
    "LIDAR_EVIDENCE",
    "RADAR_EVIDENCE",
    "class_indices",
    "geometry_features",
    "lidar_evidence",
    "nearest_depth",
    "pool_bev",
    "radar_evidence",
]
