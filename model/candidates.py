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


def _near_boxes(points: np.ndarray, boxes: np.ndarray, margin: float) -> np.ndarray:
    """Indices (ascending) of the ``points (N, >=2)`` that may lie in a box grown by ``margin``.

    A superset of every box's points: each box marks the cells of a 1 m grid under its bounding
    square (half-width ``hypot(l/2 + margin, w/2 + margin)`` plus 1 mm, which contains the grown
    footprint at any yaw), and a point is kept when its cell is marked (cells are found by
    truncation, which may keep a few more points, never fewer). One pass over the points and no
    sort, so that the exact per-box tests of :func:`_in_footprints` see only the points near a
    box instead of the whole cloud.
    """
    half = np.hypot(boxes[:, 3] / 2 + margin, boxes[:, 4] / 2 + margin) + 1e-3
    x0 = float((boxes[:, 0] - half).min())
    y0 = float((boxes[:, 1] - half).min())
    c0 = np.floor(boxes[:, 0] - half - x0).astype(np.int64) + 1
    c1 = np.floor(boxes[:, 0] + half - x0).astype(np.int64) + 1
    r0 = np.floor(boxes[:, 1] - half - y0).astype(np.int64) + 1
    r1 = np.floor(boxes[:, 1] + half - y0).astype(np.int64) + 1
    # Cell i + 1 holds [x0 + i, x0 + i + 1); row/column 0 and the last one stay empty (outside).
    occupied = np.zeros((int(c1.max()) + 2, int(r1.max()) + 2), dtype=bool)
    for a, b, c, d in zip(c0.tolist(), c1.tolist(), r0.tolist(), r1.tolist(), strict=True):
        occupied[a : b + 1, c : d + 1] = True
    col = np.clip(points[:, 0] - (x0 - 1.0), 0.0, occupied.shape[0] - 1).astype(np.intp)
    row = np.clip(points[:, 1] - (y0 - 1.0), 0.0, occupied.shape[1] - 1).astype(np.intp)
    return np.flatnonzero(occupied[col, row])


def _in_footprints(points: np.ndarray, boxes: np.ndarray, margin: float, use_z: bool) -> list:
    """Indices of ``points (N, >=3)`` inside each box grown by ``margin`` (list of K arrays).

    Each box tests the points within its bounding circle's x range (``box x -/+ r``, ``r`` =
    half the box diagonal + ``margin``) against the grown box, and returns them in the order of
    a stable sort of the points by x. Only the points near some box (:func:`_near_boxes`, a
    superset of every box's points) are sorted, and all (box, point) pairs of the x ranges are
    tested at once, so the cost is one pass over the cloud plus ``M log M + sum of range sizes``
    for the ``M`` points near a box.
    """
    if len(boxes) == 0:
        return []
    if len(points) == 0:
        return [np.zeros(0, dtype=np.int64) for _ in boxes]
    near = _near_boxes(points, boxes, margin)
    order = near[np.argsort(points[near, 0], kind="stable")]
    sub = points[order]
    r = 0.5 * np.hypot(boxes[:, 3], boxes[:, 4]) + margin
    lo = np.searchsorted(sub[:, 0], boxes[:, 0] - r)
    hi = np.searchsorted(sub[:, 0], boxes[:, 0] + r)
    sizes = np.maximum(hi - lo, 0)
    # Pair j belongs to box which[j] and is point pos[j] of the sorted near set.
    which = np.repeat(np.arange(len(boxes)), sizes)
    starts = np.cumsum(sizes) - sizes
    pos = np.arange(len(which)) - np.repeat(starts - lo, sizes)
    box, p = boxes[which], sub[pos]
    dx, dy = p[:, 0] - box[:, 0], p[:, 1] - box[:, 1]
    c, s = np.cos(box[:, 6]), np.sin(box[:, 6])
    lx, ly = dx * c + dy * s, -dx * s + dy * c
    keep = (np.abs(lx) <= box[:, 3] / 2 + margin) & (np.abs(ly) <= box[:, 4] / 2 + margin)
    if use_z:
        keep &= np.abs(p[:, 2] - box[:, 2]) <= box[:, 5] / 2 + margin
    counts = np.bincount(which[keep], minlength=len(boxes))
    return np.split(order[pos[keep]], np.cumsum(counts)[:-1])


def _mean(values: np.ndarray) -> float:
    """``values.mean()`` of a non-empty 1-D float64 array, without its Python overhead (the same
    pairwise sum divided by the count, so bit-identical)."""
    return np.add.reduce(values) / len(values)


def lidar_evidence(boxes: np.ndarray, lidar: np.ndarray) -> np.ndarray:
    """LiDAR evidence ``(K, LIDAR_EVIDENCE)``: log(1 + points in the box grown by
    :data:`LIDAR_MARGIN`), mean intensity / 255, height spread of those points (m), whether any."""
    b = _boxes(boxes)
    pts = np.asarray(lidar, dtype=np.float64).reshape(-1, 4)
    out = np.zeros((len(b), LIDAR_EVIDENCE), dtype=np.float32)
    for i, idx in enumerate(_in_footprints(pts, b, LIDAR_MARGIN, use_z=True)):
        if len(idx):
            p = pts[idx]
            z = p[:, 2]
            out[i] = (np.log1p(len(idx)), _mean(p[:, 3]) / 255.0, z.max() - z.min(), 1.0)
    return out


def _scan_slope(values: np.ndarray, t: np.ndarray, denom: float) -> float:
    """Least-squares slope of ``values`` over times centred as ``t`` (``denom`` = sum of
    ``t * t``; 0 when it is below 1e-9, i.e. fewer than two distinct times)."""
    if denom < 1e-9:
        return 0.0
    return float(np.add.reduce(t * (values - _mean(values))) / denom)


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
        vc, times = p[:, 5], p[:, 6]
        vc_mean = _mean(vc)
        spread = vc - vc_mean
        t = times - _mean(times)
        denom = float(np.add.reduce(t * t))
        out[i] = (
            np.log1p(len(idx)),
            np.log1p(np.count_nonzero(times == 0)),
            _mean(p[:, 4]) / SPEED_SCALE,
            vc_mean / SPEED_SCALE,
            np.median(vc) / SPEED_SCALE,
            np.sqrt(np.add.reduce(spread * spread) / len(vc)) / SPEED_SCALE,
            _mean(p[:, 3]) / 10.0,
            _scan_slope(p[:, 0], t, denom),
            _scan_slope(p[:, 1], t, denom),
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
