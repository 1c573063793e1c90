"""Which points lie in which candidate box: every (box, point) pair of a scene in one compiled
pass over the cloud (the candidates' point evidence, :mod:`model.referent.candidates`).

A full View-of-Delft LiDAR spin has ~190k points and a scene has up to 40 candidates; the array
form of this search (a mask over the cloud, a grid of cells, gathers of every candidate pair, the
exact test, a sort of the pairs) took 2.7 ms of ``encode_scene`` (issue 20). Here, compiled by
numba (a pinned wheel; compiled on first use and cached beside this file):

1. each box marks the cells (:data:`CELL` m) under the axis-aligned bounding rectangle of its
   grown footprint, cut to its x range, plus 1 mm (a point of the footprint is at least 1 mm
   inside it: float rounding of the point's cell cannot lose it);
2. each point in a marked cell gets the exact test against the boxes marking it, in float64 with
   the same operations as the per-box definition (no fused multiply-add: the pairs are the
   same bit for bit);
3. the pairs are ordered by box, then by the point's x, then by the point's index (a stable sort
   by x of each box's points, found in index order), the order each box's sums were defined in.

The box arithmetic that needs libm (``cos``, ``sin``, ``hypot``) is NumPy's, done before the pass,
so that no value depends on which library computed it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

CELL = 0.5
"""Side (m) of the cells that pair points with boxes."""


@njit(nogil=True, cache=True)
def _pairs(  # pragma: no cover - compiled; its Python body is what numba compiles
    points, centre, cos, sin, half_length, half_width, z_centre, half_height, r, ex, ey, use_z,
):  # fmt: skip
    k = centre.shape[0]
    n = points.shape[0]
    x0 = np.inf
    y0 = np.inf
    for b in range(k):
        x0 = min(x0, centre[b, 0] - ex[b])
        y0 = min(y0, centre[b, 1] - ey[b])
    c0 = np.empty(k, np.int64)
    c1 = np.empty(k, np.int64)
    r0 = np.empty(k, np.int64)
    r1 = np.empty(k, np.int64)
    cols = 0
    rows = 0
    for b in range(k):
        c0[b] = int(math.floor((centre[b, 0] - ex[b] - x0) / CELL))
        c1[b] = int(math.floor((centre[b, 0] + ex[b] - x0) / CELL))
        r0[b] = int(math.floor((centre[b, 1] - ey[b] - y0) / CELL))
        r1[b] = int(math.floor((centre[b, 1] + ey[b] - y0) / CELL))
        cols = max(cols, c1[b] + 1)
        rows = max(rows, r1[b] + 1)
    # The boxes marking each cell, as a CSR list (box indices ascending within a cell).
    count = np.zeros(cols * rows + 1, np.int64)
    for b in range(k):
        for c in range(c0[b], c1[b] + 1):
            for q in range(r0[b], r1[b] + 1):
                count[c * rows + q + 1] += 1
    for i in range(cols * rows):
        count[i + 1] += count[i]
    fill = count[:-1].copy()
    marked = np.empty(count[-1], np.int64)
    for b in range(k):
        for c in range(c0[b], c1[b] + 1):
            for q in range(r0[b], r1[b] + 1):
                marked[fill[c * rows + q]] = b
                fill[c * rows + q] += 1
    # The exact test of each point in a marked cell; pairs in point order.
    cap = 1024
    box = np.empty(cap, np.int64)
    point = np.empty(cap, np.int64)
    pairs = 0
    for i in range(n):
        px = np.float64(points[i, 0])
        py = np.float64(points[i, 1])
        fx = (px - x0) / CELL
        fy = (py - y0) / CELL
        if not (fx >= 0.0 and fx < cols and fy >= 0.0 and fy < rows):
            continue
        cell = min(int(fx), cols - 1) * rows + min(int(fy), rows - 1)
        for s in range(count[cell], count[cell + 1]):
            b = marked[s]
            dx = px - centre[b, 0]
            dy = py - centre[b, 1]
            lx = dx * cos[b] + dy * sin[b]
            ly = -dx * sin[b] + dy * cos[b]
            if abs(lx) > half_length[b] or abs(ly) > half_width[b]:
                continue
            if use_z and abs(np.float64(points[i, 2]) - z_centre[b]) > half_height[b]:
                continue
            if not (px >= centre[b, 0] - r[b] and px < centre[b, 0] + r[b]):
                continue
            if pairs == cap:
                cap *= 2
                grown_box = np.empty(cap, np.int64)
                grown_point = np.empty(cap, np.int64)
                grown_box[:pairs] = box[:pairs]
                grown_point[:pairs] = point[:pairs]
                box, point = grown_box, grown_point
            box[pairs] = b
            point[pairs] = i
            pairs += 1
    # By box (a counting sort keeps the point order), then by x within each box (stable).
    start = np.zeros(k + 1, np.int64)
    for p in range(pairs):
        start[box[p] + 1] += 1
    for b in range(k):
        start[b + 1] += start[b]
    place = start[:-1].copy()
    out_box = np.empty(pairs, np.int64)
    out_point = np.empty(pairs, np.int64)
    for p in range(pairs):
        b = box[p]
        out_box[place[b]] = b
        out_point[place[b]] = point[p]
        place[b] += 1
    for b in range(k):
        mine = out_point[start[b] : start[b + 1]]
        xs = np.empty(len(mine), np.float64)
        for j in range(len(mine)):
            xs[j] = points[mine[j], 0]
        out_point[start[b] : start[b + 1]] = mine[np.argsort(xs, kind="mergesort")]
    return out_box, out_point


def box_point_pairs(
    points: np.ndarray, boxes: np.ndarray, margin: float, use_z: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Every (box, point) pair with the point inside the box grown by ``margin`` (BEV footprint,
    and ``|z - box z| <= h / 2 + margin`` with ``use_z``), for all ``K`` boxes at once.

    A point also needs ``box x - r <= x < box x + r`` with ``r`` half the box's diagonal plus
    ``margin`` (the x range each box searched in a cloud sorted by x, which the features were
    defined and the model trained with; it clips the grown box's corners).

    Args:
        points: ``(N, >=3)`` float32 or float64, LiDAR frame.
        boxes: ``(K, 7)`` float64.

    Returns:
        ``(box, point)`` int64 index arrays ``(P,)``, sorted by box, then by the point's x, then
        by the point's index.
    """
    k = len(boxes)
    if k == 0 or len(points) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    cos, sin = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])
    length, width = boxes[:, 3] / 2 + margin, boxes[:, 4] / 2 + margin
    r = 0.5 * np.hypot(boxes[:, 3], boxes[:, 4]) + margin
    ex = np.minimum(np.abs(length * cos) + np.abs(width * sin), r) + 1e-3
    ey = np.abs(length * sin) + np.abs(width * cos) + 1e-3
    return _pairs(
        points, np.ascontiguousarray(boxes[:, :2]), cos, sin, length, width,
        np.ascontiguousarray(boxes[:, 2]), boxes[:, 5] / 2 + margin, r, ex, ey, use_z,
    )  # fmt: skip


__all__ = ["CELL", "box_point_pairs"]
