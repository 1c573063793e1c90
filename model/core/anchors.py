"""Anchor points of boxes and the metric centres of grid cells: the geometry the detector's
targets (:mod:`model.head.targets`), its decoding (:mod:`model.head.decode`), the labelled boxes'
scores (:mod:`model.core.labelled`), the candidates' pooling and the answer's heatmap share.

Frame: LiDAR (x forward, y left, metres); cells as :class:`model.core.grid.BevGrid` indexes them,
``(col, row)`` = ``(ix, iy)``.
"""

from __future__ import annotations

import numpy as np

from model.core.grid import BevGrid
from scenes.geometry.boxes import nearest_bev_corner, nearest_edge_midpoint


def anchor_points(boxes: np.ndarray, anchor: str) -> np.ndarray:
    """Anchor points ``(K, 2)`` (LiDAR frame, metres) of boxes ``(K, 7)`` for an anchor kind."""
    if anchor == "corner":
        return np.asarray(nearest_bev_corner(boxes, origin=(0.0, 0.0)), dtype=np.float64)
    if anchor == "edge":
        return np.asarray(nearest_edge_midpoint(boxes, origin=(0.0, 0.0)), dtype=np.float64)
    if anchor == "center":
        return np.asarray(boxes[:, :2], dtype=np.float64).copy()
    raise ValueError(f"unknown anchor {anchor!r}")


def grid_cell_centres(grid: BevGrid) -> np.ndarray:
    """Metric centres ``(H * W, 2)`` of every cell of ``grid``, row-major (``[iy, ix]``)."""
    h, w = grid.shape
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    return cell_centres(grid, cols.reshape(-1), rows.reshape(-1))


def cell_centres(grid: BevGrid, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Metric centres ``(..., 2)`` of integer cells ``(cols, rows)``: the reference of ``(dx, dy)``."""
    colrow = np.stack([np.asarray(cols, np.float64) + 0.5, np.asarray(rows, np.float64) + 0.5], -1)
    return grid.cell_to_xy(colrow)
