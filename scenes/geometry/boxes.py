"""Box geometry in the LiDAR frame: corners, points in boxes, exact rotated IoU, anchor points.

Boxes are ``(K, 7)`` arrays ``x, y, z, l, w, h, yaw`` in the LiDAR frame (x forward, y left, z up),
``z`` at the geometric centre, ``l`` along the heading, ``yaw`` counter-clockwise about +z from +x.

The rotated IoU is exact: the intersection of two convex quadrilaterals is the convex polygon whose
vertices are (a) the corners of each box inside or on the other and (b) the crossings of their
edges; its area follows from the shoelace formula once the vertices are sorted by angle about their
mean. Duplicated vertices (identical or touching boxes) add zero area, so identical boxes have IoU 1
and boxes that only touch have IoU 0, the two cases where the official devkit's polygon clipping
is known to fail.
"""

from __future__ import annotations

import numpy as np

_EPS = 1e-9


def wrap_yaw(yaw: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles (radians) into ``[-pi, pi)``."""
    wrapped = np.mod(np.asarray(yaw, dtype=np.float64) + np.pi, 2.0 * np.pi) - np.pi
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def _as_boxes(boxes: np.ndarray) -> np.ndarray:
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 7:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 7:
        raise ValueError(f"boxes must have shape (K, 7), got {arr.shape}")
    return arr


def bev_corners(boxes: np.ndarray) -> np.ndarray:
    """BEV corners ``(K, 4, 2)`` in counter-clockwise order.

    Order: front-left, rear-left, rear-right, front-right (front = +heading, left = +90 degrees).
    """
    b = _as_boxes(boxes)
    half_l, half_w = b[:, 3] / 2.0, b[:, 4] / 2.0
    local = np.stack(
        [
            np.stack([half_l, half_w], -1),
            np.stack([-half_l, half_w], -1),
            np.stack([-half_l, -half_w], -1),
            np.stack([half_l, -half_w], -1),
        ],
        axis=1,
    )  # (K, 4, 2)
    cos, sin = np.cos(b[:, 6]), np.sin(b[:, 6])
    rot = np.stack([np.stack([cos, -sin], -1), np.stack([sin, cos], -1)], axis=1)  # (K, 2, 2)
    return np.einsum("kij,kcj->kci", rot, local) + b[:, None, :2]


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """3D corners ``(K, 8, 3)``: the four bottom corners, then the four top ones (BEV order as
    :func:`bev_corners`)."""
    b = _as_boxes(boxes)
    bev = bev_corners(b)
    bottom = (b[:, 2] - b[:, 5] / 2.0)[:, None, None].repeat(4, axis=1)
    top = (b[:, 2] + b[:, 5] / 2.0)[:, None, None].repeat(4, axis=1)
    return np.concatenate(
        [np.concatenate([bev, bottom], -1), np.concatenate([bev, top], -1)], axis=1
    )


def points_in_boxes(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Which points lie inside which boxes (boundary included).

    Args:
        points: ``(N, >=3)``; only x, y, z are used. LiDAR frame.
        boxes: ``(K, 7)``.

    Returns:
        ``(N, K)`` bool.
    """
    pts = np.asarray(points, dtype=np.float64)[:, :3]
    b = _as_boxes(boxes)
    if len(pts) == 0 or len(b) == 0:
        return np.zeros((len(pts), len(b)), dtype=bool)
    d = pts[:, None, :] - b[None, :, :3]  # (N, K, 3)
    cos, sin = np.cos(b[:, 6]), np.sin(b[:, 6])
    local_x = d[..., 0] * cos + d[..., 1] * sin
    local_y = -d[..., 0] * sin + d[..., 1] * cos
    tol = 1e-6
    return (
        (np.abs(local_x) <= b[:, 3] / 2.0 + tol)
        & (np.abs(local_y) <= b[:, 4] / 2.0 + tol)
        & (np.abs(d[..., 2]) <= b[:, 5] / 2.0 + tol)
    )


def points_in_footprints(xy: np.ndarray, boxes: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Which ground positions lie inside which boxes' bird's-eye footprints, each grown by
    ``margin`` metres on every side (boundary included; z is not looked at).

    Args:
        xy: ``(N, >=2)``; only x, y are used. LiDAR frame.
        boxes: ``(K, 7)``.

    Returns:
        ``(N, K)`` bool.
    """
    pts = np.asarray(xy, dtype=np.float64)[:, :2]
    b = _as_boxes(boxes)
    d = pts[:, None, :] - b[None, :, :2]  # (N, K, 2)
    cos, sin = np.cos(b[:, 6]), np.sin(b[:, 6])
    along = d[..., 0] * cos + d[..., 1] * sin
    across = -d[..., 0] * sin + d[..., 1] * cos
    return (np.abs(along) <= b[:, 3] / 2 + margin) & (np.abs(across) <= b[:, 4] / 2 + margin)


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of (a - o) x (b - o) for broadcastable ``(..., 2)`` arrays."""
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (
        b[..., 0] - o[..., 0]
    )


def _inside_convex(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """``points (P, M, 2)`` inside or on counter-clockwise quadrilaterals ``poly (P, 4, 2)`` -> (P, M)."""
    start = poly[:, None, :, :]  # (P, 1, 4, 2)
    end = np.roll(poly, -1, axis=1)[:, None, :, :]
    scale = np.maximum(np.abs(poly).max(axis=(1, 2)), 1.0)[:, None, None]
    side = _cross(start, end, points[:, :, None, :])  # (P, M, 4)
    return np.all(side >= -1e-9 * scale * scale, axis=-1)


def _edge_crossings(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Crossings of every edge of ``a (P, 4, 2)`` with every edge of ``b (P, 4, 2)``.

    Returns points ``(P, 16, 2)`` and a validity mask ``(P, 16)``; parallel edges give no crossing
    (their shared stretch, if any, is bounded by corners that the inside test already collects).
    """
    p = a[:, :, None, :]  # (P, 4, 1, 2)
    r = (np.roll(a, -1, axis=1) - a)[:, :, None, :]
    q = b[:, None, :, :]  # (P, 1, 4, 2)
    s = (np.roll(b, -1, axis=1) - b)[:, None, :, :]
    denom = r[..., 0] * s[..., 1] - r[..., 1] * s[..., 0]  # (P, 4, 4)
    qp = q - p
    parallel = np.abs(denom) < _EPS
    safe = np.where(parallel, 1.0, denom)
    t = (qp[..., 0] * s[..., 1] - qp[..., 1] * s[..., 0]) / safe
    u = (qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / safe
    tol = 1e-9
    valid = (~parallel) & (t >= -tol) & (t <= 1 + tol) & (u >= -tol) & (u <= 1 + tol)
    pts = p + t[..., None] * r
    return pts.reshape(len(a), 16, 2), valid.reshape(len(a), 16)


def _intersection_area(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact intersection areas ``(P,)`` of counter-clockwise quadrilateral pairs ``(P, 4, 2)``."""
    if len(a) == 0:
        return np.zeros(0)
    crossings, crossing_ok = _edge_crossings(a, b)
    candidates = np.concatenate([a, b, crossings], axis=1)  # (P, 24, 2)
    valid = np.concatenate([_inside_convex(a, b), _inside_convex(b, a), crossing_ok], axis=1)
    count = valid.sum(axis=1)
    weights = valid[..., None].astype(np.float64)
    centre = (candidates * weights).sum(axis=1) / np.maximum(count, 1)[:, None]
    rel = candidates - centre[:, None, :]
    angle = np.where(valid, np.arctan2(rel[..., 1], rel[..., 0]), np.inf)
    order = np.argsort(angle, axis=1, kind="stable")
    sorted_pts = np.take_along_axis(candidates, order[..., None], axis=1)
    sorted_valid = np.take_along_axis(valid, order, axis=1)
    # Replace the invalid tail with the last valid vertex: repeated vertices add zero area.
    last_idx = np.maximum(count - 1, 0)
    last = sorted_pts[np.arange(len(a)), last_idx]
    sorted_pts = np.where(sorted_valid[..., None], sorted_pts, last[:, None, :])
    x, y = sorted_pts[..., 0], sorted_pts[..., 1]
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1))
    return np.where(count >= 3, area, 0.0)


def _pairwise(a: np.ndarray, b: np.ndarray, with_height: bool, chunk: int = 65536) -> np.ndarray:
    a, b = _as_boxes(a), _as_boxes(b)
    out = np.zeros((len(a), len(b)))
    if len(a) == 0 or len(b) == 0:
        return out
    # Only pairs whose circumscribed circles overlap can intersect.
    radius_a = 0.5 * np.hypot(a[:, 3], a[:, 4])
    radius_b = 0.5 * np.hypot(b[:, 3], b[:, 4])
    dist = np.linalg.norm(a[:, None, :2] - b[None, :, :2], axis=-1)
    ia, ib = np.nonzero(dist <= radius_a[:, None] + radius_b[None, :] + 1e-9)
    corners_a, corners_b = bev_corners(a), bev_corners(b)
    for start in range(0, len(ia), chunk):
        sa, sb = ia[start : start + chunk], ib[start : start + chunk]
        out[sa, sb] = _paired(a[sa], b[sb], corners_a[sa], corners_b[sb], with_height)
    return np.clip(out, 0.0, 1.0)


def _paired(
    a: np.ndarray, b: np.ndarray, corners_a: np.ndarray, corners_b: np.ndarray, with_height: bool
) -> np.ndarray:
    """IoU ``(P,)`` of the box pairs ``a[i]``, ``b[i]`` (BEV corners given), before clipping."""
    inter = _intersection_area(corners_a, corners_b)
    area_a = a[:, 3] * a[:, 4]
    area_b = b[:, 3] * b[:, 4]
    if with_height:
        top = np.minimum(a[:, 2] + a[:, 5] / 2, b[:, 2] + b[:, 5] / 2)
        bottom = np.maximum(a[:, 2] - a[:, 5] / 2, b[:, 2] - b[:, 5] / 2)
        inter = inter * np.clip(top - bottom, 0.0, None)
        area_a = area_a * a[:, 5]
        area_b = area_b * b[:, 5]
    union = area_a + area_b - inter
    return np.where(union > 0, inter / np.maximum(union, _EPS), 0.0)


def paired_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact rotated BEV IoU ``(P,)`` of the pairs ``a[i]``, ``b[i]`` (``a``, ``b``: ``(P, 7)``):
    the values :func:`bev_iou` gives for those pairs, without the rest of the matrix."""
    a, b = _as_boxes(a), _as_boxes(b)
    if len(a) != len(b):
        raise ValueError(f"paired_bev_iou: {len(a)} boxes against {len(b)}")
    if len(a) == 0:
        return np.zeros(0)
    return np.clip(_paired(a, b, bev_corners(a), bev_corners(b), False), 0.0, 1.0)


def bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact rotated BEV IoU ``(K1, K2)`` between boxes ``a (K1, 7)`` and ``b (K2, 7)``."""
    return _pairwise(a, b, with_height=False)


def iou3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact 3D IoU ``(K1, K2)``: BEV intersection area times vertical overlap over the union."""
    return _pairwise(a, b, with_height=True)


def match_by_centre(
    boxes: np.ndarray,
    labels: np.ndarray,
    targets: np.ndarray,
    target_labels: np.ndarray,
    max_distance: np.ndarray,
) -> np.ndarray:
    """Greedy one-to-one matching of boxes to targets of the same class by BEV centre distance.

    Boxes are taken in the given order (e.g. by detection score); each takes the nearest free
    target of its class within ``max_distance[label]`` metres.

    Args:
        boxes: ``(K, 7)`` LiDAR frame; labels: ``(K,)`` class indices.
        targets: ``(T, 7)`` LiDAR frame; target_labels: ``(T,)`` class indices.
        max_distance: ``(C,)`` largest centre distance (m) per class index.

    Returns:
        ``(K,)`` int64: the index of each box's target, ``-1`` for none.
    """
    b = _as_boxes(boxes)
    t = _as_boxes(targets)
    out = np.full(len(b), -1, dtype=np.int64)
    if len(b) == 0 or len(t) == 0:
        return out
    labels = np.asarray(labels, dtype=np.int64).reshape(-1)
    target_labels = np.asarray(target_labels, dtype=np.int64).reshape(-1)
    limit = np.asarray(max_distance, dtype=np.float64)
    dist = np.hypot(*(b[:, None, :2] - t[None, :, :2]).transpose(2, 0, 1))
    dist[labels[:, None] != target_labels[None, :]] = np.inf
    free = np.ones(len(t), dtype=bool)
    for i in range(len(b)):
        row = np.where(free, dist[i], np.inf)
        j = int(np.argmin(row))
        if row[j] <= limit[labels[i]]:
            out[i] = j
            free[j] = False
    return out


def nearest_bev_corner(boxes: np.ndarray, origin: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The BEV corner of each box nearest to ``origin`` (the ego sensor): ``(K, 2)``.

    Ties (two corners at the same distance) go to the first in :func:`bev_corners` order.
    """
    corners = bev_corners(boxes)
    dist = np.linalg.norm(corners - np.asarray(origin, dtype=np.float64), axis=-1)
    return corners[np.arange(len(corners)), np.argmin(dist, axis=1)]


def nearest_edge_midpoint(
    boxes: np.ndarray, origin: tuple[float, float] = (0.0, 0.0)
) -> np.ndarray:
    """Midpoint ``(K, 2)`` of the BEV edge nearest to ``origin`` (TPCNet eq. 17).

    The distance from the origin to an edge is the Euclidean distance to the closest point of the
    segment. Ties go to the first edge in :func:`bev_corners` order (edge i joins corners i, i+1).
    """
    corners = bev_corners(boxes)
    start, end = corners, np.roll(corners, -1, axis=1)
    o = np.asarray(origin, dtype=np.float64)
    seg = end - start
    t = np.clip(
        np.sum((o - start) * seg, axis=-1) / np.maximum(np.sum(seg * seg, axis=-1), _EPS), 0, 1
    )
    closest = start + t[..., None] * seg
    dist = np.linalg.norm(closest - o, axis=-1)
    k = np.argmin(dist, axis=1)
    idx = np.arange(len(corners))
    return 0.5 * (start[idx, k] + end[idx, k])
