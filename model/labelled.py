"""Labelled boxes as the referent stage's candidates, and the detector score of a given box.

Grounding over the frame's labelled boxes (``model.evaluate --candidates labels``, the app's
"candidates: labelled boxes" switch, the Annotate tab's sentence-first flow) makes the referent
stage choose among boxes someone drew instead of the detector's proposals; this measures language
grounding apart from detection and is the fastest way to annotate a labelled frame.

A labelled box has no detection score of its own. It gets the one training gives an actor's box
(:func:`anchor_scores`): the 3x3 maximum of its class heatmap around its anchor cell, so that the
candidate description the referent stage reads means the same at training and at inference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.grid import BevGrid
from model.targets import anchor_points
from scenes.actors import CLASSES


@dataclass(frozen=True)
class LabelledBoxes:
    """Boxes given as candidates.

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame.
        labels: ``(K,)`` int64 indices into :data:`scenes.actors.CLASSES`.
    """

    boxes: np.ndarray
    labels: np.ndarray

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 7)
        labels = np.asarray(self.labels, dtype=np.int64).reshape(-1)
        if len(labels) != len(boxes):
            raise ValueError(f"{len(boxes)} labelled boxes but {len(labels)} labels")
        if len(labels) and (labels.min() < 0 or labels.max() >= len(CLASSES)):
            raise ValueError(f"labels must index {CLASSES}, got {sorted(set(labels.tolist()))}")
        if not np.all(np.isfinite(boxes)):
            raise ValueError("labelled boxes must be finite")
        if np.any(boxes[:, 3:6] <= 0):
            raise ValueError("labelled boxes must have positive sizes")
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "labels", labels)

    def __len__(self) -> int:
        return len(self.labels)


def anchor_scores(
    heat: np.ndarray, boxes: np.ndarray, labels: np.ndarray, grid: BevGrid, anchor: str
) -> np.ndarray:
    """Detector score ``(K,)`` of each box: the 3x3 maximum of its class heatmap ``heat (3, H, W)``
    (sigmoid, on ``grid``) around the cell of its anchor point; 0 outside the grid."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return np.zeros(0)
    _, h, w = heat.shape
    cells = np.floor(grid.xy_to_cell(anchor_points(b, anchor))).astype(np.int64)
    out = np.zeros(len(b))
    for i, ((c, r), lab) in enumerate(zip(cells, np.asarray(labels), strict=True)):
        r0, r1, c0, c1 = max(r - 1, 0), min(r + 2, h), max(c - 1, 0), min(c + 2, w)
        if r0 < r1 and c0 < c1:
            out[i] = float(heat[lab, r0:r1, c0:c1].max())
    return out
