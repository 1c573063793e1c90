"""The grounding loss of TPCNet (paper section III-F, eq. 18).

``L_total = L_hm + beta * sum_{r in {x, y, z, l, w, h, theta}} SmoothL1(pred_r, target_r)``

- ``L_hm``: CenterNet's Gaussian focal loss (penalty-reduced pixel-wise logistic regression,
  ``alpha = 2``, ``beta = 4``) on the sigmoid of the heatmap logits, summed over all cells of the
  batch and divided by the number of positive cells (cells whose target is exactly 1, i.e. anchor
  cells; at least 1). The sigmoid is clamped to ``[1e-4, 1 - 1e-4]`` as in CenterPoint so that
  ``log`` stays finite.
- Regression: the 8 channels ``(dx, dy, z, log l, log w, log h, sin yaw, cos yaw)`` of
  :class:`model.head.detector.HeadOutput` are gathered at each box's anchor cell, compared with the targets
  of :func:`model.head.targets.draw_targets` by smooth-L1, summed over the channels (eq. 18's sum over
  ``Lambda``; yaw is represented by its sine and cosine, as in CenterPoint) and averaged over the
  valid boxes of the batch (``mask``; at least 1). Boxes outside the grid, ignored classes and
  padding are masked out, so a batch without boxes gives the heatmap loss only (no NaN).
- The smooth-L1 transition point (the paper does not give it) defaults to ``1/9``, the value of the
  SmoothL1 loss in the Talk2Radar PointPillars configs (spec section 3.7): almost the L1 loss that
  CenterPoint uses, but smooth at zero. ``beta`` (the weight) defaults to the paper's 0.25.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor

from model.head.detector import REGRESSION_CHANNELS, HeadOutput
from model.head.targets import BatchTargets

SIGMOID_CLAMP = 1e-4
"""The predicted heatmap probability is clamped to ``[SIGMOID_CLAMP, 1 - SIGMOID_CLAMP]``."""


@dataclass(frozen=True)
class LossTerms:
    """Scalar loss tensors.

    Attributes:
        total: ``heatmap + beta * regression`` (eq. 18), the one to back-propagate.
        heatmap: The focal heatmap loss ``L_hm``.
        regression: The (unweighted) smooth-L1 regression loss.
    """

    total: Tensor
    heatmap: Tensor
    regression: Tensor


def focal_heatmap_loss(
    logits: Tensor,
    target: Tensor,
    alpha: float = 2.0,
    gamma: float = 4.0,
    ignore: Tensor | None = None,
) -> Tensor:
    """CenterNet's Gaussian focal loss.

    Args:
        logits: ``(B, C, H, W)`` raw heatmap logits.
        target: ``(B, C, H, W)`` Gaussian targets in ``[0, 1]``, exactly 1 at positives.
        alpha: Focusing exponent on ``(1 - p)`` / ``p``.
        gamma: Exponent of the ``(1 - target)`` penalty reduction around positives.
        ignore: Optional ``(B, 1, H, W)`` bool: cells whose negatives count nothing (labels
            incomplete there); positives count wherever they are.

    Returns:
        Scalar: the summed loss over the batch divided by the number of positives (at least 1).
    """
    pred = torch.sigmoid(logits.float()).clamp(SIGMOID_CLAMP, 1.0 - SIGMOID_CLAMP)
    target = target.to(pred.dtype)
    pos = target.eq(1.0)
    pos_loss = torch.log(pred) * (1.0 - pred) ** alpha
    neg_loss = torch.log(1.0 - pred) * pred**alpha * (1.0 - target) ** gamma
    if ignore is not None:
        neg_loss = neg_loss.masked_fill(ignore.to(neg_loss.device), 0.0)
    loss = torch.where(pos, pos_loss, neg_loss).sum()
    num_pos = pos.sum().clamp(min=1).to(pred.dtype)
    return -loss / num_pos


def gather_regression(regression: Tensor, indices: Tensor) -> Tensor:
    """Regression predictions at flat cell indices.

    Args:
        regression: ``(B, 8, H, W)``.
        indices: ``(B, K)`` int64 flat indices ``iy * W + ix``.

    Returns:
        ``(B, K, 8)``.
    """
    B, R, H, W = regression.shape
    flat = regression.reshape(B, R, H * W)
    idx = indices.long().clamp(0, H * W - 1)[:, None, :].expand(B, R, indices.shape[1])
    return flat.gather(2, idx).permute(0, 2, 1)


def grounding_loss(
    out: HeadOutput, targets: BatchTargets, beta: float = 0.25, smooth_l1_beta: float = 1.0 / 9.0
) -> LossTerms:
    """Eq. 18: focal heatmap loss + ``beta`` x smooth-L1 box regression at the anchor cells.

    Args:
        out: Head outputs ``heatmap (B, 3, H, W)``, ``regression (B, 8, H, W)``.
        targets: :class:`model.head.targets.BatchTargets` on the same grid and device.
        beta: Weight of the regression term (the paper's 0.25).
        smooth_l1_beta: Transition point of the smooth-L1 loss.

    Returns:
        :class:`LossTerms` of scalar tensors.
    """
    if out.heatmap.shape != targets.heatmap.shape:
        raise ValueError(
            f"grounding_loss: heatmap {tuple(out.heatmap.shape)} vs targets "
            f"{tuple(targets.heatmap.shape)}"
        )
    if out.regression.shape[1] != REGRESSION_CHANNELS:
        raise ValueError(
            f"grounding_loss: regression must have {REGRESSION_CHANNELS} channels, "
            f"got {out.regression.shape[1]}"
        )
    hm_loss = focal_heatmap_loss(out.heatmap, targets.heatmap, ignore=targets.ignore)
    pred = gather_regression(out.regression, targets.indices).float()  # (B, K, 8)
    mask = targets.mask.to(pred.dtype)[..., None]  # (B, K, 1)
    per_value = F.smooth_l1_loss(
        pred, targets.regression.to(pred.dtype), reduction="none", beta=smooth_l1_beta
    )
    num_boxes = targets.mask.sum().clamp(min=1).to(pred.dtype)
    reg_loss = (per_value * mask).sum() / num_boxes
    return LossTerms(total=hm_loss + beta * reg_loss, heatmap=hm_loss, regression=reg_loss)
