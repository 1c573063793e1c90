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
