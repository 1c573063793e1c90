"""Decoding C3D-RECHead outputs into 3D boxes (the inverse of :mod:`model.head.targets`).

Per batch item (CenterPoint's decoder, spec section 3.7, with the anchor of section III-E):

1. ``sigmoid`` of the heatmap logits ``(3, H, W)``;
2. peaks: cells equal to the maximum of their 3x3 neighbourhood (max-pool NMS);
3. the ``HeadConfig.top_k`` highest peaks over all classes, then ``score >= score_threshold``;
4. box centre = anchor cell centre + ``(dx, dy)`` (metres, LiDAR frame; computed in float64 so the
   round trip through :func:`model.head.targets.draw_targets` is exact up to float32 storage of the
   small offset), ``z`` as regressed, ``(l, w, h) = exp(log size)``,
   ``yaw = atan2(sin, cos)`` wrapped to ``[-pi, pi)``;
5. rotated NMS per class with the exact BEV IoU of :func:`scenes.geometry.boxes.paired_bev_iou`
   (``HeadConfig.nms_iou``), then the ``HeadConfig.max_detections`` best boxes by score: one
   greedy pass over all classes in descending score order (:func:`class_nms`), which stops once
   that many boxes are kept and compares only boxes whose bounding circles overlap.

Decoded centres are not filtered by the grid range: a box whose near corner is inside the grid may
have its centre just outside it, and it is still a valid detection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from model.config import HeadConfig
from model.core.anchors import cell_centres
from model.core.grid import BevGrid
from model.head.detector import REGRESSION_CHANNELS, HeadOutput
from scenes.geometry.boxes import paired_bev_iou, wrap_yaw


@dataclass(frozen=True)
class Detections:
    """Decoded boxes of one sample, sorted by descending score.

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame, z at the geometric centre.
        scores: ``(K,)`` float64 sigmoid scores.
        labels: ``(K,)`` int64 class indices into the model's class set.
        classes: ``K`` class names (``class_set.names[label]``).
    """

    boxes: np.ndarray
    scores: np.ndarray
    labels: np.ndarray
    classes: tuple[str, ...]

    @staticmethod
    def empty() -> Detections:
        """No detections."""
        return Detections(np.zeros((0, 7)), np.zeros(0), np.zeros(0, dtype=np.int64), ())


def rotated_nms(
    boxes: np.ndarray, scores: np.ndarray, iou_threshold: float, max_keep: int | None = None
) -> np.ndarray:
    """Greedy non-maximum suppression with the exact rotated BEV IoU.

    Args:
        boxes: ``(K, 7)`` boxes, LiDAR frame.
        scores: ``(K,)`` scores.
        iou_threshold: A box is suppressed when its BEV IoU with a kept, higher-scoring box is
            strictly greater than this.
        max_keep: Stop once this many boxes are kept (the result is the first ``max_keep`` of
            the full run's, since greedy NMS keeps boxes in descending score order).

    Returns:
        ``(M,)`` int64 indices of the kept boxes into ``boxes``, by descending score (ties keep the
        lower index first).
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    if len(boxes) != len(scores):
        raise ValueError(f"rotated_nms: {len(boxes)} boxes but {len(scores)} scores")
    labels = np.zeros(len(boxes), dtype=np.int64)
    return class_nms(boxes, scores, labels, iou_threshold, max_keep)


def class_nms(
    boxes: np.ndarray,
    scores: np.ndarray,
    labels: np.ndarray,
    iou_threshold: float,
    max_keep: int | None = None,
) -> np.ndarray:
    """Greedy rotated NMS within each class, all classes in one pass.

    The result is that of :func:`rotated_nms` run on each class, merged by descending score
    (ties: the lower class, then the lower index) and cut to ``max_keep``. Boxes are visited in
    that order and a box is suppressed by a kept box of its class whose IoU with it exceeds
    ``iou_threshold``; the visit stops once ``max_keep`` boxes are kept, so that only the boxes
    before that point are ever compared. Comparisons are vectorised: per block of the visit
    order, the pairs (earlier kept or in-block box, in-block box) of one class whose bounding
    circles overlap get their exact IoU (:func:`scenes.geometry.boxes.paired_bev_iou`) in one call; the
    first block holds ``4 * max_keep`` boxes (at least 64), which usually suffices.

    Args:
        boxes: ``(K, 7)`` LiDAR frame; scores ``(K,)``; labels ``(K,)`` int class indices.

    Returns:
        ``(M,)`` int64 indices into ``boxes`` of the kept boxes, in the order above.
    """
    n = len(boxes)
    limit = n if max_keep is None else min(int(max_keep), n)
    if n == 0 or limit <= 0:
        return np.zeros(0, dtype=np.int64)
    order = np.lexsort((np.arange(n), labels, -scores))
    b, lab = boxes[order], labels[order]
    radius = 0.5 * np.hypot(b[:, 3], b[:, 4])
    suppressed = np.zeros(n, dtype=bool)
    kept: list[int] = []
    start, size = 0, max(4 * limit, 64)
    while start < n and len(kept) < limit:
        end = min(n, start + size)
        # Earlier boxes only matter where they were kept.
        first = np.concatenate([np.asarray(kept, dtype=np.int64), np.arange(start, end)])
        block = np.arange(start, end)
        pair = (first[:, None] < block[None, :]) & (lab[first][:, None] == lab[block][None, :])
        dist = np.hypot(b[first, 0][:, None] - b[block, 0], b[first, 1][:, None] - b[block, 1])
        pair &= dist < radius[first][:, None] + radius[block][None, :]
        fi, bj = np.nonzero(pair)
        i, j = first[fi], block[bj]
        hit = paired_bev_iou(b[i], b[j]) > iou_threshold
        i, j = i[hit], j[hit]
        # Suppressions by boxes kept before this block; then the block in order.
        before = i < start
        suppressed[j[before]] = True
        later: dict[int, list[int]] = {}
        for a, c in zip(i[~before].tolist(), j[~before].tolist(), strict=True):
            later.setdefault(a, []).append(c)
        for p in range(start, end):
            if suppressed[p]:
                continue
            kept.append(p)
            if len(kept) >= limit:
                break
            for c in later.get(p, ()):
                suppressed[c] = True
        start, size = end, n
    return order[np.asarray(kept, dtype=np.int64)]


def _max3x3(x: torch.Tensor) -> torch.Tensor:
    """``F.max_pool2d(x, 3, stride=1, padding=1)`` of ``(C, H, W)`` as two separable passes of
    element-wise maxima over shifted views (the same values: max is exact; on the CPU a tenth
    of the pooling kernel's time on a head-size map)."""
    padded = F.pad(x, (1, 1, 1, 1), value=float("-inf"))
    rows = torch.maximum(torch.maximum(padded[:, :, :-2], padded[:, :, 1:-1]), padded[:, :, 2:])
    return torch.maximum(torch.maximum(rows[:, :-2], rows[:, 1:-1]), rows[:, 2:])


def _decode_one(
    heatmap: torch.Tensor,
    regression: torch.Tensor,
    grid: BevGrid,
    cfg: HeadConfig,
    threshold: float,
    limit: int,
) -> Detections:
    """Decode one item: ``heatmap (C, H, W)`` logits and ``regression (8, H, W)``; at most
    ``limit`` boxes."""
    _, H, W = heatmap.shape
    scores = torch.sigmoid(heatmap.float())
    pooled = _max3x3(scores)
    # Non-peaks get -1 so that they never pass a threshold (even 0).
    peaks = torch.where(scores == pooled, scores, torch.full_like(scores, -1.0)).reshape(-1)
    k = min(cfg.top_k, peaks.numel())
    top_scores, top_idx = torch.topk(peaks, k)
    keep = top_scores >= threshold
    top_scores, top_idx = top_scores[keep], top_idx[keep]
    if top_idx.numel() == 0:
        return Detections.empty()

    labels = (top_idx // (H * W)).cpu().numpy().astype(np.int64)
    cells = top_idx % (H * W)
    reg = regression.reshape(REGRESSION_CHANNELS, H * W)[:, cells].T
    reg = reg.detach().cpu().numpy().astype(np.float64)
    cells_np = cells.cpu().numpy()
    rows, cols = cells_np // W, cells_np % W
    centres = cell_centres(grid, cols, rows) + reg[:, 0:2]
    yaw = wrap_yaw(np.arctan2(reg[:, 6], reg[:, 7]))
    class_set = cfg.class_set
    headless = np.array([not c.heading for c in class_set.classes])
    if headless.any():  # a symmetric class (a traffic cone) has no heading: yaw 0
        yaw = np.where(headless[labels], 0.0, yaw)
    boxes = np.concatenate([centres, reg[:, 2:3], np.exp(reg[:, 3:6]), yaw[:, None]], axis=1)
    scores_np = top_scores.detach().cpu().numpy().astype(np.float64)

    sel = class_nms(boxes, scores_np, labels, cfg.nms_iou, limit)
    return Detections(
        boxes=boxes[sel],
        scores=scores_np[sel],
        labels=labels[sel],
        classes=tuple(class_set.names[i] for i in labels[sel]),
    )


@torch.no_grad()
def decode(
    out: HeadOutput,
    grid: BevGrid,
    cfg: HeadConfig,
    score_threshold: float | None = None,
    limit: int | None = None,
) -> list[Detections]:
    """Decode a batch of head outputs into boxes.

    Args:
        out: ``heatmap (B, C, H, W)`` logits and ``regression (B, 8, H, W)`` on ``grid``.
        grid: The head's BEV grid; ``grid.shape`` must equal ``(H, W)``.
        cfg: Head configuration (top-K, threshold, NMS IoU, cap; its class set: ``C`` classes,
            channel ``k`` its class ``k``).
        score_threshold: Overrides ``cfg.score_threshold`` when given.
        limit: Keep at most this many boxes (when below ``cfg.max_detections``): the first
            ``limit`` of the full result, found without visiting the boxes after them.

    Returns:
        One :class:`Detections` per batch item (LiDAR frame boxes).
    """
    hm, reg = out.heatmap, out.regression
    class_set = cfg.class_set
    n = len(class_set)
    if hm.dim() != 4 or hm.shape[1] != n:
        raise ValueError(
            f"decode: heatmap must be (B, {n}, H, W) for the {class_set.name!r} class set, "
            f"got {tuple(hm.shape)}"
        )
    if reg.dim() != 4 or reg.shape[1] != REGRESSION_CHANNELS:
        raise ValueError(
            f"decode: regression must be (B, {REGRESSION_CHANNELS}, H, W), got {tuple(reg.shape)}"
        )
    if tuple(hm.shape[2:]) != grid.shape or tuple(reg.shape[2:]) != grid.shape:
        raise ValueError(
            f"decode: output maps {tuple(hm.shape[2:])} / {tuple(reg.shape[2:])} do not match the "
            f"grid shape {grid.shape}"
        )
    if hm.shape[0] != reg.shape[0]:
        raise ValueError(f"decode: batch sizes differ: {hm.shape[0]} vs {reg.shape[0]}")
    threshold = cfg.score_threshold if score_threshold is None else float(score_threshold)
    keep = cfg.max_detections if limit is None else min(cfg.max_detections, int(limit))
    return [_decode_one(hm[b], reg[b], grid, cfg, threshold, keep) for b in range(hm.shape[0])]
