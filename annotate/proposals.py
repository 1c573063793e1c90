"""The model's predicted boxes as proposals for a draft ("Use predictions").

A prediction becomes a proposal when its class is one of the allowed classes (the served model's
class set; ``vod``'s ``Car``, ``Pedestrian``, ``Cyclist`` by default), its size is
positive, and it does not repeat a box the draft already holds or an earlier proposal (bird's eye
view IoU below :data:`DUPLICATE_IOU`); at most :data:`MAX_PROPOSALS`, best score first.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from scenes.geometry.boxes import bev_iou
from scenes.geometry.classes import VOD

MAX_PROPOSALS = 20
"""*Use predictions* adds at most this many boxes (the best scores)."""

DUPLICATE_IOU = 0.5
"""A predicted box overlapping a draft box at least this much (BEV IoU) is not added again."""


def proposals(
    boxes: np.ndarray,
    classes: Sequence[str],
    existing: np.ndarray,
    limit: int = MAX_PROPOSALS,
    duplicate_iou: float = DUPLICATE_IOU,
    allowed: Sequence[str] = VOD.names,
) -> tuple[np.ndarray, tuple[str, ...], int]:
    """The predicted boxes to add to a draft.

    Args:
        boxes: ``(K, 7)`` predicted boxes, LiDAR frame, best score first.
        classes: Their ``K`` classes.
        existing: ``(E, 7)`` boxes already in the draft.
        limit: Most boxes returned.
        duplicate_iou: A box overlapping an existing (or an earlier returned) box at least this
            much in bird's eye view is a duplicate and left out.
        allowed: The classes a proposal may have (the served model's class set).

    Returns:
        ``(boxes (P, 7), classes, duplicates)``: the boxes to add, in score order, their classes
        (allowed classes only), and how many were left out as duplicates.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    kept = np.asarray(existing, dtype=np.float64).reshape(-1, 7)
    out: list[int] = []
    duplicates = 0
    for k in range(len(b)):
        if len(out) >= limit:
            break
        if classes[k] not in allowed or np.any(b[k, 3:6] <= 0):
            continue
        if len(kept) and float(bev_iou(b[k : k + 1], kept).max()) >= duplicate_iou:
            duplicates += 1
            continue
        out.append(k)
        kept = np.concatenate([kept, b[k : k + 1]])
    return b[out], tuple(str(classes[k]) for k in out), duplicates


__all__ = ["DUPLICATE_IOU", "MAX_PROPOSALS", "proposals"]
