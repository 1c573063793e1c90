"""Training targets of the C3D-RECHead (paper section III-E/III-F; CenterPoint's target scheme).

For every ground-truth box (LiDAR frame, ``x, y, z, l, w, h, yaw``) of a metric class:

1. the *anchor point* is chosen by ``HeadConfig.anchor`` (see :mod:`model.head.detector`): the BEV corner
   nearest the LiDAR origin (default), the midpoint of the nearest edge (eq. 17), or the centre;
2. the *anchor cell* is the head-grid cell ``(iy, ix)`` containing the anchor point; boxes whose
   anchor lies outside the grid get ``mask = False`` and draw nothing;
3. a Gaussian with peak exactly 1 at the anchor cell is drawn (element-wise max) into the class's
   heatmap channel. Its radius is CenterPoint's ``gaussian_radius`` of the box's length and width
   in cells with ``min_overlap = HeadConfig.gaussian_overlap``, truncated to an integer and at least
   ``HeadConfig.min_radius``; ``sigma = (2 r + 1) / 6``. (The radius formula is CornerNet's, with
   its well-known division by 2 rather than by ``2a``, kept as in CenterNet/CenterPoint so that the
   radii match theirs.);
4. the regression target is ``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)`` with
   ``(dx, dy) = centre_xy - anchor_cell_centre_xy`` in metres. Decoding (:mod:`model.head.decode`)
   adds the same offset to the same cell centre, so it is the exact inverse.

The flat cell index of the anchor cell is ``iy * W + ix`` (row-major over the ``(H, W)`` canvas),
which is what :func:`model.head.losses.grounding_loss` gathers the regression map with.

Box classes outside the model's class set (``ModelConfig.class_set``) are ignored: they stay in the arrays (so index
``k`` still means input box ``k``) with ``label = -1`` and ``mask = False``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from model.config import HeadConfig
from model.core.anchors import anchor_points, cell_centres
from model.core.grid import BevGrid
from model.head.detector import REGRESSION_CHANNELS


@dataclass(frozen=True)
class Targets:
    """Targets of one sample on the head grid ``(H, W)``.

    Attributes:
        heatmap: ``(C, H, W)`` float32 (``C`` classes) Gaussian heatmaps, peak 1 at each anchor cell.
        indices: ``(K,)`` int64 flat anchor-cell index ``iy * W + ix`` (0 where ``mask`` is False).
        anchor_offsets: ``(K, 2)`` float32 anchor point minus anchor-cell centre, metres
            (in ``[-cell/2, cell/2)``; zero where ``mask`` is False).
        regression: ``(K, 8)`` float32 ``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)``
            (zero where ``mask`` is False).
        mask: ``(K,)`` bool, True for metric-class boxes whose anchor lies in the grid.
        labels: ``(K,)`` int64 class index into the class set, -1 for ignored classes.
        anchors: ``(K, 2)`` float64 anchor points ``(x, y)``, LiDAR frame, metres.
    """

    heatmap: np.ndarray
    indices: np.ndarray
    anchor_offsets: np.ndarray
    regression: np.ndarray
    mask: np.ndarray
    labels: np.ndarray
    anchors: np.ndarray


@dataclass(frozen=True)
class BatchTargets:
    """Targets of a batch, padded to the largest box count ``Kmax`` (padding has ``mask`` False).

    Attributes:
        heatmap: ``(B, C, H, W)`` float32.
        indices: ``(B, Kmax)`` int64 flat anchor-cell indices.
        anchor_offsets: ``(B, Kmax, 2)`` float32, metres.
        regression: ``(B, Kmax, 8)`` float32.
        mask: ``(B, Kmax)`` bool.
        labels: ``(B, Kmax)`` int64 (-1 for ignored classes and padding).
        ignore: ``(B, 1, H, W)`` bool, True where the labels are incomplete (outside the camera
            view VoD annotates): no negative heatmap loss there. None: labels complete.
    """

    heatmap: Tensor
    indices: Tensor
    anchor_offsets: Tensor
    regression: Tensor
    mask: Tensor
    labels: Tensor
    ignore: Tensor | None = None

    def to(self, device: torch.device | str) -> BatchTargets:
        """A copy with every tensor on ``device``."""
        return BatchTargets(
            heatmap=self.heatmap.to(device),
            indices=self.indices.to(device),
            anchor_offsets=self.anchor_offsets.to(device),
            regression=self.regression.to(device),
            mask=self.mask.to(device),
            labels=self.labels.to(device),
            ignore=None if self.ignore is None else self.ignore.to(device),
        )


def gaussian_radius(length: float, width: float, min_overlap: float) -> float:
    """CenterPoint's Gaussian radius (in cells) for a box of ``length x width`` cells.

    The smallest of the three CornerNet cases (both corners shifted inwards, outwards, one of each)
    for which a box displaced by the radius keeps IoU ``>= min_overlap`` with the original.
    """
    lw = length * width
    s = length + width
    r1 = (s + math.sqrt(max(s * s - 4.0 * lw * (1.0 - min_overlap) / (1.0 + min_overlap), 0.0))) / 2
    r2 = (2.0 * s + math.sqrt(max(4.0 * s * s - 16.0 * (1.0 - min_overlap) * lw, 0.0))) / 2
    b3 = -2.0 * min_overlap * s
    r3 = (b3 + math.sqrt(max(b3 * b3 - 16.0 * min_overlap * (min_overlap - 1.0) * lw, 0.0))) / 2
    return min(r1, r2, r3)


def gaussian_kernel(radius: int) -> np.ndarray:
    """``(2r+1, 2r+1)`` float32 Gaussian with ``sigma = (2r+1)/6`` and exactly 1 at the centre."""
    sigma = (2 * radius + 1) / 6.0
    offsets = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-(offsets[:, None] ** 2 + offsets[None, :] ** 2) / (2.0 * sigma * sigma))
    g[g < np.finfo(np.float64).eps * g.max()] = 0.0
    return g.astype(np.float32)


def draw_gaussian(heatmap: np.ndarray, row: int, col: int, radius: int) -> None:
    """Draw (element-wise max, in place) a Gaussian of ``radius`` cells peaked at ``(row, col)``.

    Args:
        heatmap: ``(H, W)`` float32 channel, modified in place.
        row, col: Peak cell (``iy``, ``ix``), inside the canvas.
        radius: Radius in cells (>= 0).
    """
    H, W = heatmap.shape
    kernel = gaussian_kernel(radius)
    top, bottom = min(row, radius), min(H - row, radius + 1)
    left, right = min(col, radius), min(W - col, radius + 1)
    window = heatmap[row - top : row + bottom, col - left : col + right]
    patch = kernel[radius - top : radius + bottom, radius - left : radius + right]
    np.maximum(window, patch, out=window)


def _check_boxes(boxes: np.ndarray, classes: Sequence[str]) -> np.ndarray:
    boxes = np.asarray(boxes, dtype=np.float64)
    if boxes.size == 0:
        boxes = boxes.reshape(0, 7)
    if boxes.ndim != 2 or boxes.shape[1] != 7:
        raise ValueError(f"draw_targets: boxes must have shape (K, 7), got {boxes.shape}")
    if len(classes) != len(boxes):
        raise ValueError(
            f"draw_targets: {len(boxes)} boxes but {len(classes)} class names; they must match"
        )
    for k, box in enumerate(boxes):
        if not np.all(np.isfinite(box)):
            raise ValueError(f"draw_targets: box {k} has non-finite values {box.tolist()}")
        if np.any(box[3:6] <= 0):
            raise ValueError(f"draw_targets: box {k} has non-positive size (l, w, h) = {box[3:6]}")
    return boxes


def draw_targets(
    boxes: np.ndarray, classes: Sequence[str], grid: BevGrid, cfg: HeadConfig
) -> Targets:
    """Heatmap and regression targets of one sample.

    Args:
        boxes: ``(K, 7)`` ``x, y, z, l, w, h, yaw``, LiDAR frame, z at the geometric centre.
        classes: ``K`` class names; names outside ``cfg.class_set`` are ignored.
        grid: The head's BEV grid (the grid of the feature map the head runs on).
        cfg: Head configuration (anchor kind, Gaussian radius parameters, the class set: heatmap
            channel ``k`` is its class ``k``; a class without heading,
            :attr:`scenes.geometry.classes.ObjectClass.heading`, gets the yaw target 0).

    Returns:
        :class:`Targets` on ``grid.shape``.

    Raises:
        ValueError: Wrong shapes, non-finite boxes, or a size ``<= 0`` (naming the box index).
    """
    boxes = _check_boxes(boxes, classes)
    K = len(boxes)
    H, W = grid.shape
    class_set = cfg.class_set
    heatmap = np.zeros((len(class_set), H, W), dtype=np.float32)
    indices = np.zeros(K, dtype=np.int64)
    anchor_offsets = np.zeros((K, 2), dtype=np.float32)
    regression = np.zeros((K, REGRESSION_CHANNELS), dtype=np.float32)
    mask = np.zeros(K, dtype=bool)
    labels = np.array(
        [class_set.index(c) if c in class_set else -1 for c in classes], dtype=np.int64
    )
    headless = np.array([not c.heading for c in class_set.classes] + [False])
    if K == 0:
        return Targets(heatmap, indices, anchor_offsets, regression, mask, labels, np.zeros((0, 2)))

    anchors = anchor_points(boxes, cfg.anchor)
    colrow = np.floor(grid.xy_to_cell(anchors))
    cols = np.clip(colrow[:, 0], 0, W - 1).astype(np.int64)
    rows = np.clip(colrow[:, 1], 0, H - 1).astype(np.int64)
    mask = (labels >= 0) & grid.contains(anchors)
    centres = cell_centres(grid, cols, rows)

    for k in np.flatnonzero(mask):
        l_cells, w_cells = boxes[k, 3] / grid.cell, boxes[k, 4] / grid.cell
        radius = max(cfg.min_radius, int(gaussian_radius(l_cells, w_cells, cfg.gaussian_overlap)))
        draw_gaussian(heatmap[labels[k]], int(rows[k]), int(cols[k]), radius)
        indices[k] = rows[k] * W + cols[k]
        anchor_offsets[k] = anchors[k] - centres[k]
        x, y, z, l, w, h, yaw = boxes[k]
        if headless[labels[k]]:
            yaw = 0.0
        regression[k] = (
            x - centres[k, 0],
            y - centres[k, 1],
            z,
            math.log(l),
            math.log(w),
            math.log(h),
            math.sin(yaw),
            math.cos(yaw),
        )
    return Targets(heatmap, indices, anchor_offsets, regression, mask, labels, anchors)


def collate_targets(targets: Sequence[Targets]) -> BatchTargets:
    """Stack per-sample :class:`Targets` into padded torch tensors (:class:`BatchTargets`).

    Raises:
        ValueError: An empty batch, or samples whose heatmaps differ in shape.
    """
    if len(targets) == 0:
        raise ValueError("collate_targets: empty batch")
    shape = targets[0].heatmap.shape
    for b, t in enumerate(targets):
        if t.heatmap.shape != shape:
            raise ValueError(
                f"collate_targets: sample {b} heatmap shape {t.heatmap.shape} != {shape}"
            )
    B = len(targets)
    k_max = max(len(t.mask) for t in targets)
    indices = np.zeros((B, k_max), dtype=np.int64)
    anchor_offsets = np.zeros((B, k_max, 2), dtype=np.float32)
    regression = np.zeros((B, k_max, REGRESSION_CHANNELS), dtype=np.float32)
    mask = np.zeros((B, k_max), dtype=bool)
    labels = np.full((B, k_max), -1, dtype=np.int64)
    for b, t in enumerate(targets):
        k = len(t.mask)
        indices[b, :k] = t.indices
        anchor_offsets[b, :k] = t.anchor_offsets
        regression[b, :k] = t.regression
        mask[b, :k] = t.mask
        labels[b, :k] = t.labels
    return BatchTargets(
        heatmap=torch.from_numpy(np.stack([t.heatmap for t in targets])),
        indices=torch.from_numpy(indices),
        anchor_offsets=torch.from_numpy(anchor_offsets),
        regression=torch.from_numpy(regression),
        mask=torch.from_numpy(mask),
        labels=torch.from_numpy(labels),
    )
