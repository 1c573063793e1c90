"""Decoding C3D-RECHead outputs into 3D boxes (the inverse of :mod:`model.targets`).

Per batch item (CenterPoint's decoder, spec section 3.7, with the anchor of section III-E):

1. ``sigmoid`` of the heatmap logits ``(3, H, W)``;
2. peaks: cells equal to the maximum of their 3x3 neighbourhood (max-pool NMS);
3. the ``HeadConfig.top_k`` highest peaks over all classes, then ``score >= score_threshold``;
4. box centre = anchor cell centre + ``(dx, dy)`` (metres, LiDAR frame; computed in float64 so the
   round trip through :func:`model.targets.draw_targets` is exact up to float32 storage of the
   small offset), ``z`` as regressed, ``(l, w, h) = exp(log size)``,
   ``yaw = atan2(sin, cos)`` wrapped to ``[-pi, pi)``;
5. rotated NMS per class with the exact BEV IoU of :func:`scenes.boxes.bev_iou`
   (``HeadConfig.nms_iou``), then the ``HeadConfig.max_detections`` best boxes by score.

Decoded centres are not filtered by the grid range: a box whose near corner is inside the grid may
have its centre just outside it, and it is still a valid detection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from model.grid import BevGrid
from model.head import NUM_CLASSES, REGRESSION_CHANNELS, HeadConfig, HeadOutput
from model.targets import cell_centres
from scenes.actors import CLASSES
from scenes.boxes import bev_iou, wrap_yaw


@dataclass(frozen=True)
class Detections:
    """Decoded boxes of one sample, sorted by descending score.

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame, z at the geometric centre.
        scores: ``(K,)`` float64 sigmoid scores.
        labels: ``(K,)`` int64 class indices into ``CLASSES``.
        classes: ``K`` class names (``CLASSES[label]``).
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
    order = np.argsort(-scores, kind="stable")
    # Bounding circles rule out most pairs before the exact polygon IoU.
    radius = 0.5 * np.hypot(boxes[:, 3], boxes[:, 4])
    suppressed = np.zeros(len(boxes), dtype=bool)
    keep: list[int] = []
    for pos, i in enumerate(order):
        if suppressed[i]:
            continue
        keep.append(int(i))
        if max_keep is not None and len(keep) >= max_keep:
            break
        rest = order[pos + 1 :]
        rest = rest[~suppressed[rest]]
        if len(rest) == 0:
            continue
        dist = np.hypot(boxes[rest, 0] - boxes[i, 0], boxes[rest, 1] - boxes[i, 1])
        rest = rest[dist < radius[rest] + radius[i]]
        if len(rest) == 0:
            continue
        iou = np.asarray(bev_iou(boxes[i : i + 1], boxes[rest]))[0]
        suppressed[rest[iou > iou_threshold]] = True
    return np.asarray(keep, dtype=np.int64)


def _decode_one(
    heatmap: torch.Tensor,
    regression: torch.Tensor,
    grid: BevGrid,
    cfg: HeadConfig,
    threshold: float,
) -> Detections:
    """Decode one item: ``heatmap (3, H, W)`` logits and ``regression (8, H, W)``."""
    _, H, W = heatmap.shape
    scores = torch.sigmoid(heatmap.float())
    pooled = F.max_pool2d(scores[None], kernel_size=3, stride=1, padding=1)[0]
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
    boxes = np.concatenate([centres, reg[:, 2:3], np.exp(reg[:, 3:6]), yaw[:, None]], axis=1)
    scores_np = top_scores.detach().cpu().numpy().astype(np.float64)

    kept: list[np.ndarray] = []
    for c in range(NUM_CLASSES):
        idx = np.flatnonzero(labels == c)
        if len(idx):
            kept.append(
                idx[rotated_nms(boxes[idx], scores_np[idx], cfg.nms_iou, cfg.max_detections)]
            )
    sel = np.concatenate(kept)
    sel = sel[np.argsort(-scores_np[sel], kind="stable")][: cfg.max_detections]
    return Detections(
        boxes=boxes[sel],
        scores=scores_np[sel],
        labels=labels[sel],
        classes=tuple(CLASSES[i] for i in labels[sel]),
    )


@torch.no_grad()
def decode(
    out: HeadOutput, grid: BevGrid, cfg: HeadConfig, score_threshold: float | None = None
) -> list[Detections]:
    """Decode a batch of head outputs into boxes.

    Args:
        out: ``heatmap (B, 3, H, W)`` logits and ``regression (B, 8, H, W)`` on ``grid``.
        grid: The head's BEV grid; ``grid.shape`` must equal ``(H, W)``.
        cfg: Head configuration (top-K, threshold, NMS IoU, cap).
        score_threshold: Overrides ``cfg.score_threshold`` when given.

    Returns:
        One :class:`Detections` per batch item (LiDAR frame boxes).
    """
    hm, reg = out.heatmap, out.regression
    if hm.dim() != 4 or hm.shape[1] != NUM_CLASSES:
        raise ValueError(f"decode: heatmap must be (B, {NUM_CLASSES}, H, W), got {tuple(hm.shape)}")
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
    return [_decode_one(hm[b], reg[b], grid, cfg, threshold) for b in range(hm.shape[0])]
