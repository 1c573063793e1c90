"""The ground under a LiDAR, estimated from its cloud, and heights made relative to it.

A sensor mounted at another height or pitched sees the ground elsewhere in its own frame than
the rig a detector was trained on (issue 38: the HDL-64 0.3 m lower and pitched 2 degrees). With
the ground plane ``z = a x + b y + c`` estimated from the cloud (:func:`estimate_ground`), every
point's height can be expressed above that plane and put back at a reference height
(:func:`level_points`: the plane becomes ``z = -height``), and boxes found in that levelled frame
moved back (:func:`unlevel_boxes`). A shear, not a rotation: at a few degrees of pitch the
horizontal positions move by well under a centimetre within 30 m.

Estimate: the lowest point of each 1 m BEV cell 3 to 30 m ahead within 15 m either side, a least
squares plane through the lower half of them, then twice again through those within 0.15 m of it
(kerbs, cars' undersides and walls' feet fall away), and last through every point within 0.15 m
(a cell's lowest point lies below the ground by the range noise). Fewer than 20 cells: the level
plane at the reference height (no estimate).

The one home of ground estimation: every module that needs the ground's height asks here.

- The global plane (:func:`estimate_ground`): what the model's input is levelled on.
- The ground's height under the sensor (:func:`sensor_ground_height`): the plane's ``c``, one
  number a flat display stands on (the app's range rings, ego marker, heatmap; the default bottom
  of a box placed by a ground click).
- The local ground under a box (:func:`ground_under_boxes`) or around a point
  (:func:`ground_around`): the :data:`LOCAL_PERCENTILE` percentile of the point heights near it,
  where a kerb, a slope or a pitched sensor moves the ground away from the global plane (a fitted
  box's bottom, a pseudo-label seated on the ground). Measured on the synthetic world
  (``python -m scenes.synth`` settings, seeds 7 and 38, ten frames each, the labelled boxes
  within 45 m; estimate minus the box's bottom): the 5th percentile of a 2 m ring around the
  footprint has a mean absolute error of 0.029 / 0.111 m, the median of the lowest third of a
  1.5 m ring (the pseudo-labels' former estimate) 0.074 / 0.188 m, and the 5th percentile over
  the footprint grown by 2 m (the box fit's, kept for a rough region) 0.033 / 0.114 m. For the
  height under the sensor the plane's ``c`` has a mean error of -0.027 / -0.018 m and a 90th
  percentile absolute error of 0.12 / 0.10 m; the 10th percentile of the points 3 to 30 m away
  (the app's former estimate) -0.052 / -0.057 m and 0.14 / 0.15 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CELL = 1.0
"""BEV cell (m) of the lowest-point candidates."""
AREA = (3.0, 30.0, 15.0)
"""Candidates from ``x`` in ``[3, 30)`` m and ``|y| < 15`` m (LiDAR frame)."""
INLIER = 0.15
"""Metres from the plane a candidate may lie to count in the refits."""
MIN_CELLS = 20
"""Fewer candidate cells: no estimate."""
LOCAL_RING = 2.0
"""Metres around a footprint whose points tell the local ground (:func:`ground_under_boxes`)."""
LOCAL_PERCENTILE = 5.0
"""Percentile of the nearby point heights taken as the local ground (the ground around an object
is almost always seen; objects stand above it; the lowest few per cent are range noise)."""
LOCAL_MIN_POINTS = 8
"""Fewer nearby points than this: no local estimate (NaN)."""
SENSOR_GROUND_RANGE = (-4.0, 0.5)
"""Bounds (m, LiDAR frame) of :func:`sensor_ground_height` (a sensor mounted 4 m up at most)."""


@dataclass(frozen=True)
class GroundPlane:
    """``z = a x + b y + c`` in the LiDAR frame (m).

    Attributes:
        a, b: Slopes along x and y.
        c: Height of the ground under the sensor (negative: the sensor is above it).
        cells: Candidate cells the fit used (0: not estimated, the reference plane).
    """

    a: float
    b: float
    c: float
    cells: int

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """``(N,)`` ground height under ``xy (N, >=2)``."""
        xy = np.asarray(xy, dtype=np.float64)
        return self.a * xy[:, 0] + self.b * xy[:, 1] + self.c


def estimate_ground(points: np.ndarray, reference_height: float) -> GroundPlane:
    """The ground plane of a LiDAR cloud ``(N, >=3)`` (module docstring); the level plane
    ``z = -reference_height`` when too few cells hold points."""
    level = GroundPlane(0.0, 0.0, -float(reference_height), 0)
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 3 or len(p) == 0:
        return level
    p = p[:, :3]
    x0, x1, half = AREA
    p = p[(p[:, 0] >= x0) & (p[:, 0] < x1) & (np.abs(p[:, 1]) < half) & np.isfinite(p).all(1)]
    if len(p) == 0:
        return level
    ix = np.floor((p[:, 0] - x0) / CELL).astype(np.int64)
    iy = np.floor((p[:, 1] + half) / CELL).astype(np.int64)
    key = ix * int(2 * half / CELL + 1) + iy
    order = np.lexsort((p[:, 2], key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    low = p[order][first]  # the lowest point of each cell
    if len(low) < MIN_CELLS:
        return level
    # First fit on the lower half of the cells (objects' cells lie above the ground).
    keep = low[:, 2] <= np.median(low[:, 2])
    coef = np.zeros(3)
    for _ in range(3):
        if keep.sum() < MIN_CELLS // 2:
            return level
        coef = _fit(low[keep])
        keep = np.abs(low[:, 2] - (low[:, :2] @ coef[:2] + coef[2])) < INLIER
    cells = int(keep.sum())
    # The cells' lowest points lie below the ground by the range noise: the last fit is through
    # every point near the plane.
    for _ in range(2):
        near = np.abs(p[:, 2] - (p[:, :2] @ coef[:2] + coef[2])) < INLIER
        if near.sum() < MIN_CELLS:
            break
        coef = _fit(p[near])
    return GroundPlane(float(coef[0]), float(coef[1]), float(coef[2]), cells)


def _fit(points: np.ndarray) -> np.ndarray:
    """Least squares ``(a, b, c)`` of ``z = a x + b y + c`` through ``points (N, 3)``."""
    design = np.c_[points[:, :2], np.ones(len(points))]
    coef, *_ = np.linalg.lstsq(design, points[:, 2], rcond=None)
    return coef


def level_points(points: np.ndarray, plane: GroundPlane, reference_height: float) -> np.ndarray:
    """A copy of ``points (N, >=3)`` with ``z`` measured from ``plane`` and the plane put at
    ``z = -reference_height`` (other columns, dtype kept)."""
    out = np.array(points, copy=True)
    if len(out):
        out[:, 2] = out[:, 2] - plane.height_at(out[:, :2]) - reference_height
    return out


def level_clouds(
    lidar: np.ndarray, radar: np.ndarray | None, reference_height: float
) -> tuple[GroundPlane, np.ndarray, np.ndarray | None]:
    """The ground estimated from ``lidar (N, >=3)`` (:func:`estimate_ground`) and both clouds
    levelled on it (:func:`level_points`): what a model whose heights are above the estimated
    ground sees, at inference and in training alike. ``radar`` None stays None."""
    plane = estimate_ground(lidar, reference_height)
    levelled = None if radar is None else level_points(radar, plane, reference_height)
    return plane, level_points(lidar, plane, reference_height), levelled


def unlevel_boxes(boxes: np.ndarray, plane: GroundPlane, reference_height: float) -> np.ndarray:
    """``(K, 7)`` boxes found in the levelled frame of :func:`level_points`, back in the sensor's
    (their centres' ``z`` moved by the plane under them; sizes and yaw kept)."""
    out = np.array(boxes, dtype=np.float64, copy=True).reshape(-1, 7)
    if len(out):
        out[:, 2] = out[:, 2] + plane.height_at(out[:, :2]) + reference_height
    return out


def sensor_ground_height(points: np.ndarray, reference_height: float) -> float:
    """The ground's height under the sensor (m, LiDAR frame): ``c`` of :func:`estimate_ground`
    of ``points (N, >=3)``, clipped to :data:`SENSOR_GROUND_RANGE`; ``-reference_height`` where
    the cloud tells no plane. One number for a flat display (module docstring)."""
    plane = estimate_ground(points, reference_height)
    if not plane.cells:
        return float(-reference_height)
    low, high = SENSOR_GROUND_RANGE
    return float(np.clip(plane.c, low, high))


def _local_height(z: np.ndarray, min_points: int) -> float:
    """:data:`LOCAL_PERCENTILE` percentile of the heights ``z (n,)``; NaN under ``min_points``."""
    if len(z) < max(1, min_points):
        return float("nan")
    return float(np.percentile(z, LOCAL_PERCENTILE))


def _finite_xyz(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.size == 0:
        return np.zeros((0, 3))
    if p.ndim != 2 or p.shape[1] < 3:
        raise ValueError(f"points must have shape (N, >=3), got {p.shape}")
    p = p[:, :3]
    return p[np.isfinite(p).all(1)]


def ground_under_boxes(
    points: np.ndarray,
    boxes: np.ndarray,
    ring: float = LOCAL_RING,
    *,
    with_footprint: bool = False,
    min_points: int = LOCAL_MIN_POINTS,
) -> np.ndarray:
    """``(K,)`` float64: the local ground height (m, LiDAR frame) under each box ``(K, 7)``
    (``x, y, z, l, w, h, yaw``, LiDAR frame; ``z`` and ``h`` unread) from the LiDAR points
    ``(N, >=3)``: the :data:`LOCAL_PERCENTILE` percentile of the heights of the points whose BEV
    position lies in the footprint grown by ``ring`` metres per side and not in the footprint
    itself (an accurate box: what is inside is the object, and the ground under it is hidden);
    ``with_footprint``: the footprint's points count too (a rough box, which the object may
    overhang). NaN where fewer than ``min_points`` such points exist."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 7)
    out = np.full(len(boxes), np.nan)
    xyz = _finite_xyz(points)
    if not len(boxes) or not len(xyz):
        return out
    for k, box in enumerate(boxes):
        d = xyz[:, :2] - box[:2]
        reach = np.hypot(box[3], box[4]) / 2 + ring
        near = np.flatnonzero((np.abs(d[:, 0]) <= reach) & (np.abs(d[:, 1]) <= reach))
        c, s = np.cos(box[6]), np.sin(box[6])
        along = np.abs(d[near, 0] * c + d[near, 1] * s)
        across = np.abs(-d[near, 0] * s + d[near, 1] * c)
        half_l, half_w = box[3] / 2, box[4] / 2
        keep = (along <= half_l + ring) & (across <= half_w + ring)
        if not with_footprint:
            keep &= (along > half_l) | (across > half_w)
        out[k] = _local_height(xyz[near[keep], 2], min_points)
    return out


def ground_around(
    points: np.ndarray, centre: np.ndarray, radius: float, *, min_points: int = LOCAL_MIN_POINTS
) -> float:
    """The local ground height (m, LiDAR frame) around the BEV point ``centre (2,)`` (LiDAR
    frame): the :data:`LOCAL_PERCENTILE` percentile of the heights of the points ``(N, >=3)``
    within ``radius`` metres of it (BEV); NaN where fewer than ``min_points`` are."""
    xyz = _finite_xyz(points)
    d = xyz[:, :2] - np.asarray(centre, np.float64).reshape(2)
    return _local_height(xyz[np.hypot(d[:, 0], d[:, 1]) <= radius, 2], min_points)
