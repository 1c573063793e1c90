"""Object candidates of the referent stage and their explicit, text-free evidence.

A candidate is one box ``x, y, z, l, w, h, yaw`` (LiDAR frame, z at the geometric centre) with a
class and a detection score; at inference the candidates are the text-agnostic C3D-RECHead's
decoded detections, in training the frame's actors (slightly jittered) plus the detector's own
false positives. For each candidate this module computes, as pure numpy functions:

- :func:`geometry_features` ``(K, geometry_feature_width(C))``: class one-hot over the model's
  ``C`` classes, detection score, centre, size, heading, nearest-edge depth (``min x`` of the BEV
  corners, the depth the prompts speak of), bearing, range, lateral offset. The one-hot's first
  three columns are columns 0 to 2 and a fourth and further class's come after the explicit
  geometry (columns 17, 18, ...: :func:`class_columns`), so that every other column has one index
  whatever the class set, and a three-class (``vod``) model reads the layout its checkpoints were
  trained on;
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
referent stage can compare them with the numbers of a prompt (see :mod:`model.nets.numerals`) through
plain linear layers.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from model.core.grid import BevGrid
from model.referent.point_pairs import box_point_pairs
from scenes.geometry.boxes import bev_corners

GEOMETRY_FEATURES = 17
"""Width of :func:`geometry_features` of a set of at most three classes (``vod``);
:func:`geometry_feature_width` in general."""
FIRST_CLASS_COLUMNS = 3
"""Class one-hot columns before the score column (the first three classes')."""
LIDAR_EVIDENCE = 4
RADAR_EVIDENCE = 10
RADAR_MARGIN = 0.5
"""Metres added on every side of a box's footprint when gathering its radar points (radar points
scatter around an object's surface by more than LiDAR points do)."""
LIDAR_MARGIN = 0.2
DEPTH_SCALE = 50.0
LATERAL_SCALE = 25.0
SPEED_SCALE = 10.0
DEPTH_COLUMN = 12
"""Column of :func:`geometry_features` holding the nearest-edge depth / :data:`DEPTH_SCALE`."""
RADAR_MEDIAN_VC, RADAR_SLOPE_X, RADAR_SLOPE_Y = 4, 7, 8
"""Columns of :func:`radar_evidence`: median ego-compensated radial velocity / :data:`SPEED_SCALE`,
and the points' displacement over the ``time`` field along x and y."""


def class_columns(num_classes: int) -> np.ndarray:
    """``(C,)`` int64: the column of each class's one-hot in :func:`geometry_features` of a set
    of ``num_classes`` classes (module docstring: 0, 1, 2, then 17, 18, ...)."""
    first = np.arange(min(num_classes, FIRST_CLASS_COLUMNS))
    later = GEOMETRY_FEATURES + np.arange(max(0, num_classes - FIRST_CLASS_COLUMNS))
    return np.concatenate([first, later]).astype(np.int64)


def geometry_feature_width(num_classes: int) -> int:
    """Width of :func:`geometry_features` of a set of ``num_classes`` classes (17 up to three)."""
    return GEOMETRY_FEATURES + max(0, num_classes - FIRST_CLASS_COLUMNS)


def _boxes(boxes: np.ndarray) -> np.ndarray:
    return np.asarray(boxes, dtype=np.float64).reshape(-1, 7)


def nearest_depth(boxes: np.ndarray) -> np.ndarray:
    """Forward distance ``(K,)`` of each box's nearest point: ``min x`` over its BEV corners."""
    b = _boxes(boxes)
    if len(b) == 0:
        return np.zeros(0)
    return bev_corners(b)[:, :, 0].min(axis=1)


def geometry_features(
    boxes: np.ndarray, labels: np.ndarray, scores: np.ndarray, num_classes: int = 3
) -> np.ndarray:
    """Explicit geometry of ``K`` candidates.

    Args:
        boxes: ``(K, 7)`` LiDAR frame.
        labels: ``(K,)`` class indices into the model's class set.
        scores: ``(K,)`` detection scores in ``[0, 1]``.
        num_classes: ``C``, the size of the model's class set (3: ``vod``).

    Returns:
        ``(K, geometry_feature_width(C))`` float32: one-hot class (the first three), score, x, y,
        z, log l, log w, log h, sin yaw, cos yaw, nearest-edge depth, bearing (rad), range,
        ``|y|``, nearest-edge depth minus centre x (how deep the box reaches), then the one-hot
        of the classes after the third (:func:`class_columns`).
    """
    b = _boxes(boxes)
    k = len(b)
    out = np.zeros((k, geometry_feature_width(num_classes)), dtype=np.float32)
    if k == 0:
        return out
    labels = np.asarray(labels, dtype=np.int64).reshape(k)
    if labels.min() < 0 or labels.max() >= num_classes:
        raise ValueError(
            f"geometry_features: labels must index {num_classes} classes, got "
            f"{sorted(set(labels.tolist()))}"
        )
    out[np.arange(k), class_columns(num_classes)[labels]] = 1.0
    depth = nearest_depth(b)
    rng = np.hypot(b[:, 0], b[:, 1])
    out[:, 3] = np.asarray(scores, dtype=np.float64).reshape(k)
    out[:, 4] = b[:, 0] / DEPTH_SCALE
    out[:, 5] = b[:, 1] / LATERAL_SCALE
    out[:, 6] = b[:, 2] / 2.0
    out[:, 7:10] = np.log(np.maximum(b[:, 3:6], 1e-3))
    out[:, 10] = np.sin(b[:, 6])
    out[:, 11] = np.cos(b[:, 6])
    out[:, DEPTH_COLUMN] = depth / DEPTH_SCALE
    out[:, 13] = np.arctan2(b[:, 1], b[:, 0])
    out[:, 14] = rng / DEPTH_SCALE
    out[:, 15] = np.abs(b[:, 1]) / LATERAL_SCALE
    out[:, 16] = (b[:, 0] - depth) / 2.0
    return out


def _segments(box: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes that hold points, and where their runs of ``box`` (sorted) start and how long
    they are."""
    counts = np.bincount(box, minlength=k)
    has = np.flatnonzero(counts)
    return has, (np.cumsum(counts) - counts)[has], counts[has]


def _mean(values: np.ndarray) -> float:
    """``values.mean()`` of a non-empty 1-D float64 array, without its Python overhead (the same
    pairwise sum divided by the count, so bit-identical)."""
    return np.add.reduce(values) / len(values)


def _points_by_box(
    boxes: np.ndarray, points: np.ndarray, features: int, margin: float, use_z: bool
) -> tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None]:
    """The number of boxes and, when any point lies in one (grown by ``margin``), the points in
    the boxes ``(P, features)`` float64 grouped box after box, with :func:`_segments`' boxes
    that have points, their first rows and counts; None when no point is in any box."""
    b = _boxes(boxes)
    pts = _points(points, features)
    box, idx = box_point_pairs(pts, b, margin, use_z=use_z)
    if len(idx) == 0:
        return len(b), None
    return len(b), (np.asarray(pts[idx], dtype=np.float64), *_segments(box, len(b)))


def lidar_evidence(boxes: np.ndarray, lidar: np.ndarray) -> np.ndarray:
    """LiDAR evidence ``(K, LIDAR_EVIDENCE)``: log(1 + points in the box grown by
    :data:`LIDAR_MARGIN`), mean intensity / 255, height spread of those points (m), whether any.

    ``lidar``: ``(N, 4)`` (float32 as the model gets it, or float64); all boxes are served by one
    pass over the cloud (:func:`model.referent.point_pairs.box_point_pairs`).
    """
    k, grouped = _points_by_box(boxes, lidar, 4, LIDAR_MARGIN, use_z=True)
    out = np.zeros((k, LIDAR_EVIDENCE), dtype=np.float32)
    if grouped is None:
        return out
    p, has, starts, counts = grouped
    z = p[:, 2]
    spread = np.maximum.reduceat(z, starts) - np.minimum.reduceat(z, starts)
    intensity = [
        _mean(p[s : s + n, 3]) for s, n in zip(starts.tolist(), counts.tolist(), strict=True)
    ]
    out[has, 0] = np.log1p(counts)
    out[has, 1] = np.asarray(intensity) / 255.0
    out[has, 2] = spread
    out[has, 3] = 1.0
    return out


def _points(points: np.ndarray, features: int) -> np.ndarray:
    """``points`` as an ``(N, features)`` float32 or float64 array (not copied when it is one)."""
    arr = np.asarray(points)
    if arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    return arr.reshape(-1, features)


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
    k, grouped = _points_by_box(boxes, radar, 7, RADAR_MARGIN, use_z=False)
    out = np.zeros((k, RADAR_EVIDENCE), dtype=np.float32)
    if grouped is None:
        return out
    all_p, has, starts, counts = grouped
    for i, s, n in zip(has.tolist(), starts.tolist(), counts.tolist(), strict=True):
        p = all_p[s : s + n]
        vc, times = p[:, 5], p[:, 6]
        vc_mean = _mean(vc)
        spread = vc - vc_mean
        t = times - _mean(times)
        denom = float(np.add.reduce(t * t))
        out[i] = (
            np.log1p(n),
            np.log1p(np.count_nonzero(times == 0)),
            _mean(p[:, 4]) / SPEED_SCALE,
            vc_mean / SPEED_SCALE,
            np.median(vc) / SPEED_SCALE,
            np.sqrt(np.add.reduce(spread * spread) / n) / SPEED_SCALE,
            _mean(p[:, 3]) / 10.0,
            _scan_slope(p[:, 0], t, denom),
            _scan_slope(p[:, 1], t, denom),
            1.0,
        )
    return out


def pool_bev(feature_map: Tensor, grid: BevGrid, xy: Tensor) -> Tensor:
    """Bilinear samples of a BEV map at metric positions.

    Args:
        feature_map: ``(C, H, W)`` on ``grid`` (``[c, iy, ix]``, see :mod:`model.core.grid`).
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


__all__ = [
    "GEOMETRY_FEATURES",
    "LIDAR_EVIDENCE",
    "RADAR_EVIDENCE",
    "class_columns",
    "geometry_feature_width",
    "geometry_features",
    "lidar_evidence",
    "nearest_depth",
    "pool_bev",
    "radar_evidence",
]
