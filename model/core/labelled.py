"""Labelled boxes as the referent stage's candidates, and the detector score of a given box.

Grounding over the frame's labelled boxes (``model.evaluate --candidates labels``, the app's
"candidates: labelled boxes" switch, the Annotate tab's sentence-first flow) makes the referent
stage choose among boxes someone drew instead of the detector's proposals; this measures language
grounding apart from detection and is the fastest way to annotate a labelled frame.

A labelled box is ground truth: its class is its label's and it is certainly an object, so it
enters the candidate description with its label's class one-hot and the detection score
:data:`LABELLED_SCORE` (certain), whatever the detector makes of it. The detector's opinion of
the box never decides its class: on frames unlike our synthetic world (real View-of-Delft frames,
other sensors) the detector misses or mis-scores people the labels name, and reading its score at
the box (as this module did before issue 37) made a labelled pedestrian "not a pedestrian". Only
what labels do not say (motion from the radar points inside the box, point counts) comes from the
sensors. The referent stage is trained on such candidates too (``--freeze-scene``'s labelled
views, with the detector's pooled features at the boxes shifted: see
:mod:`model.training.referent_cache`), so that it trusts the label over the detector.

:func:`anchor_scores` remains what the joint referent step gives an actor's jittered box when it
stands in for a detector proposal (the 3x3 maximum of its class heatmap around its anchor cell).

Nor does a frame's handful of labelled boxes look like the candidate set the referent stage was
trained on (the detector's 40 proposals, street clutter included): its self-attention reads the
other candidates, and alone among a few boxes its probabilities drop (a referent at 0.77 among the
proposals scored 0.19 among eight labelled boxes). So the labelled boxes come first, and the
detector's proposals that overlap none of them fill the set as context (:func:`with_context`);
only the labelled boxes can be the answer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from model.core.anchors import anchor_points
from model.core.grid import BevGrid
from scenes.geometry.boxes import bev_iou
from scenes.geometry.classes import VOD, ClassSet


@dataclass(frozen=True)
class LabelledBoxes:
    """Boxes given as candidates.

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame.
        labels: ``(K,)`` int64 indices into ``classes``.
        classes: The class set the labels index (a model refuses labelled boxes of another set
            than its own).
    """

    boxes: np.ndarray
    labels: np.ndarray
    classes: ClassSet = field(default=VOD)

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 7)
        labels = np.asarray(self.labels, dtype=np.int64).reshape(-1)
        if len(labels) != len(boxes):
            raise ValueError(f"{len(boxes)} labelled boxes but {len(labels)} labels")
        if len(labels) and (labels.min() < 0 or labels.max() >= len(self.classes)):
            raise ValueError(
                f"labels must index {self.classes.names}, got {sorted(set(labels.tolist()))}"
            )
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
    """Detector score ``(K,)`` of each box: the 3x3 maximum of its class heatmap ``heat (C, H, W)``
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


LABELLED_SCORE = 1.0
"""The detection score a labelled box enters the candidate description with: certain."""

CONTEXT_DISTANCE = 1.0
"""A proposal whose BEV centre lies within this many metres of a labelled box (or that overlaps
one) is that object again, not context."""


def with_context(
    labelled: LabelledBoxes,
    proposals: np.ndarray,
    proposal_labels: np.ndarray,
    proposal_scores: np.ndarray,
    max_total: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The labelled boxes (score :data:`LABELLED_SCORE` each) followed by the proposals (in their
    score order) that overlap none of them, at most ``max_total`` in all (the labelled boxes are
    always kept).

    Returns:
        ``boxes (K, 7)``, ``labels (K,)``, ``scores (K,)``; the first ``len(labelled)`` rows are
        the labelled boxes.
    """
    props = np.asarray(proposals, dtype=np.float64).reshape(-1, 7)
    free = np.ones(len(props), dtype=bool)
    if len(labelled) and len(props):
        near = np.hypot(*(props[:, None, :2] - labelled.boxes[None, :, :2]).transpose(2, 0, 1))
        free = ~((near < CONTEXT_DISTANCE) | (bev_iou(props, labelled.boxes) > 0.0)).any(axis=1)
    room = max(0, max_total - len(labelled))
    keep = np.nonzero(free)[0][:room]
    return (
        np.concatenate([labelled.boxes, props[keep]]),
        np.concatenate([labelled.labels, np.asarray(proposal_labels, dtype=np.int64)[keep]]),
        np.concatenate(
            [
                np.full(len(labelled), LABELLED_SCORE),
                np.asarray(proposal_scores, dtype=np.float64)[keep],
            ]
        ),
    )
