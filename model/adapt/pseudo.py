"""Pseudo-labels: per-class selection, the memory across rounds, and the triplet partition
(ST3D, CVPR 2021, section 3.2: "memory ensemble and voting" and "triplet box partition").

Each round the current detector is run on every frame (eval mode, no augmentation) and its boxes
scoring at least the round's *negative* threshold of their class are kept (:func:`select`). The
frame's memory (:class:`FrameMemory`, the pseudo-labels of the rounds before) is then merged with
them (:func:`ensemble`):

- a new box and a remembered one whose BEV IoU exceeds ``memory_iou`` are one object (greedy,
  the highest IoU first); of the pair the box with the higher score is kept (ST3D's
  consistency ensemble by maximum confidence), its miss count reset to 0;
- a remembered box that no new box matches is kept with its miss count raised by one, and
  dropped once that count exceeds ``max_miss`` (ST3D's memory voting);
- a new box that matches nothing is added.

:func:`partition` splits the memory into the round's training targets: a **pseudo-label** is a
box seen this round (miss 0) whose score reaches its class's positive threshold and whose centre
lies within the round's range; every other remembered box (below the positive threshold, beyond
the range, or unseen this round) is **ignored**: no target, and no negative on its footprint.
Everything else is background.

With ``--seat-on-ground`` (default) each new box is first moved in z to rest on the ground the
new sensor sees around it (:func:`seat_on_ground`): a detector trained on one mounting height
places boxes too high or too low on another (0.1 m too high on the nuScenes-like set-up, 0.14 m
higher than VoD's), and pseudo-labels would teach that error back to it. Boxes are ``(K, 7)`` ``x, y, z, l, w, h, yaw`` in the LiDAR frame;
labels index the checkpoint's class set (heatmap-channel order, :attr:`RoundPlan.classes`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from model.adapt.config import RoundPlan
from scenes.geometry.boxes import bev_iou
from scenes.geometry.ground import ground_under_boxes


@dataclass(frozen=True)
class FrameMemory:
    """A frame's remembered boxes.

    Attributes:
        boxes: ``(K, 7)`` float64, LiDAR frame.
        labels: ``(K,)`` int64 into the checkpoint's classes.
        scores: ``(K,)`` float64 detector scores (the kept box's).
        misses: ``(K,)`` int64 rounds in a row the box went undetected.
    """

    boxes: np.ndarray
    labels: np.ndarray
    scores: np.ndarray
    misses: np.ndarray

    @staticmethod
    def empty() -> FrameMemory:
        return FrameMemory(
            np.zeros((0, 7)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
        )

    def __len__(self) -> int:
        return len(self.boxes)

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {
            "boxes": self.boxes,
            "labels": self.labels,
            "scores": self.scores,
            "misses": self.misses,
        }

    @staticmethod
    def from_arrays(data: Mapping[str, np.ndarray]) -> FrameMemory:
        return FrameMemory(
            np.asarray(data["boxes"], np.float64).reshape(-1, 7),
            np.asarray(data["labels"], np.int64),
            np.asarray(data["scores"], np.float64),
            np.asarray(data["misses"], np.int64),
        )


def select(
    labels: np.ndarray,
    scores: np.ndarray,
    threshold: Mapping[str, float],
    classes: Sequence[str],
) -> np.ndarray:
    """``(K,)`` bool: the boxes whose score reaches their class's entry of ``threshold``
    (``{class name: threshold}``; a class without an entry is never selected); ``labels`` index
    ``classes``."""
    limits = np.array([threshold.get(c, np.inf) for c in classes])
    labels = np.asarray(labels, np.int64)
    return np.asarray(scores, np.float64) >= limits[labels] if len(labels) else np.zeros(0, bool)


@dataclass(frozen=True)
class EnsembleStats:
    """What one frame's merge did: new boxes matched to the memory, added, remembered boxes
    missed (kept, ignored) and dropped."""

    matched: int
    added: int
    missed: int
    dropped: int


def ensemble(
    memory: FrameMemory,
    boxes: np.ndarray,
    labels: np.ndarray,
    scores: np.ndarray,
    memory_iou: float,
    max_miss: int,
) -> tuple[FrameMemory, EnsembleStats]:
    """The frame's memory merged with this round's selected boxes (module docstring)."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 7)
    labels, scores = np.asarray(labels, np.int64), np.asarray(scores, np.float64)
    m, n = len(memory), len(boxes)
    match_new = np.full(n, -1)
    match_old = np.full(m, -1)
    if m and n:
        iou = bev_iou(memory.boxes, boxes)
        for flat in np.argsort(-iou, axis=None, kind="stable"):
            i, j = divmod(int(flat), n)
            if iou[i, j] <= memory_iou:
                break
            if match_old[i] < 0 and match_new[j] < 0:
                match_old[i], match_new[j] = j, i
    out_boxes, out_labels, out_scores, out_misses = [], [], [], []
    dropped = missed = 0
    for i in range(m):
        j = match_old[i]
        if j >= 0:
            newer = scores[j] > memory.scores[i]
            out_boxes.append(boxes[j] if newer else memory.boxes[i])
            out_labels.append(labels[j] if newer else memory.labels[i])
            out_scores.append(max(scores[j], memory.scores[i]))
            out_misses.append(0)
        elif memory.misses[i] + 1 > max_miss:
            dropped += 1
        else:
            missed += 1
            out_boxes.append(memory.boxes[i])
            out_labels.append(memory.labels[i])
            out_scores.append(memory.scores[i])
            out_misses.append(memory.misses[i] + 1)
    fresh = np.flatnonzero(match_new < 0)
    for j in fresh:
        out_boxes.append(boxes[j])
        out_labels.append(labels[j])
        out_scores.append(scores[j])
        out_misses.append(0)
    merged = FrameMemory(
        np.array(out_boxes, np.float64).reshape(-1, 7),
        np.array(out_labels, np.int64),
        np.array(out_scores, np.float64),
        np.array(out_misses, np.int64),
    )
    return merged, EnsembleStats(int((match_new >= 0).sum()), len(fresh), missed, dropped)


@dataclass(frozen=True)
class FrameTargets:
    """A frame's training targets of one round.

    Attributes:
        boxes: ``(P, 7)`` pseudo-labels, LiDAR frame.
        labels: ``(P,)`` int64 into the checkpoint's classes.
        ignore: ``(J, 7)`` boxes ignored: no target, no negative on their footprint.
    """

    boxes: np.ndarray
    labels: np.ndarray
    ignore: np.ndarray


def positive_mask(memory: FrameMemory, plan: RoundPlan) -> np.ndarray:
    """``(K,)`` bool: the remembered boxes that are pseudo-labels at ``plan``: seen this round,
    confident for their class, within the round's range (module docstring)."""
    near = np.hypot(memory.boxes[:, 0], memory.boxes[:, 1]) <= plan.max_range
    confident = select(memory.labels, memory.scores, plan.positive, plan.classes)
    return confident & near & (memory.misses == 0)


def partition(memory: FrameMemory, plan: RoundPlan) -> FrameTargets:
    """The memory split into pseudo-labels and ignored boxes at ``plan`` (module docstring)."""
    positive = positive_mask(memory, plan)
    return FrameTargets(memory.boxes[positive], memory.labels[positive], memory.boxes[~positive])


__all__ = [
    "EnsembleStats",
    "FrameMemory",
    "FrameTargets",
    "ensemble",
    "ground_heights",
    "partition",
    "positive_mask",
    "seat_on_ground",
    "select",
]


MAX_SEAT_SHIFT = 0.3
"""Metres a box may move in z to rest on the ground; a larger move (a ring without road points:
a sidewalk, an occluded ground) leaves it where it was."""


def ground_heights(boxes: np.ndarray, lidar: np.ndarray) -> np.ndarray:
    """``(K,)`` the ground height under each box ``(K, 7)`` (LiDAR frame) from the LiDAR points
    ``(N, >=3)`` in a ring around its footprint (:func:`scenes.geometry.ground.ground_under_boxes`:
    the object inside is left out); NaN where the ring holds too few points."""
    return ground_under_boxes(lidar, boxes)


def seat_on_ground(boxes: np.ndarray, lidar: np.ndarray) -> np.ndarray:
    """``(K, 7)`` copies of ``boxes`` whose bottom rests on the ground under them
    (:func:`ground_heights`; ``z = ground + h / 2``), where the ground could be told and the move
    is at most :data:`MAX_SEAT_SHIFT`; the others as they were. The detector's heights carry its training sensor's mounting (a LiDAR mounted
    higher makes every box float); the ground seen by the new sensor does not."""
    out = np.array(boxes, np.float64).reshape(-1, 7)
    seated = ground_heights(out, lidar) + out[:, 5] / 2
    known = np.isfinite(seated) & (np.abs(seated - out[:, 2]) <= MAX_SEAT_SHIFT)
    out[known, 2] = seated[known]
    return out
