"""Counting the answers of class prompts against full labels (:mod:`model.evaluation.class_prompts`' core).

Pure functions on ``(K, 7)`` float boxes ``x, y, z, l, w, h, yaw`` in the LiDAR frame (x forward,
y left, z up, metres; z at the geometric centre, yaw counter-clockwise about +z). See
:mod:`model.evaluation.class_prompts` for what "target", "found" and "false box" mean.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from model.evaluation.metrics import MIN_OVERLAPS
from scenes.frame.kitti import ObjectLabel
from scenes.geometry.boxes import bev_iou, iou3d
from scenes.geometry.calib import (
    Calibration,
    CameraBoxes,
    boxes_camera_to_lidar,
)
from scenes.geometry.classes import VOD, ClassSet, object_class

if TYPE_CHECKING:
    from model.core.features import SceneFeatures
    from model.tpcnet import TPCNet


def class_prompts(classes: ClassSet = VOD) -> dict[str, str]:
    """The prompt asked for each class of ``classes`` ("the " and its plural), in the order they
    are asked: the set's channel order reversed (``vod``: the cyclists, the pedestrians, the
    cars, as this evaluation has always asked them)."""
    return {c.name: f"the {c.plural}" for c in reversed(classes.classes)}


CLASS_PROMPTS: dict[str, str] = class_prompts(VOD)
"""The ``vod`` class set's :func:`class_prompts` (the shipped checkpoint's)."""

TARGET_RECALL = 70.0
"""Issue 14: share (percent) of the cyclists, pedestrians and cars within 30 m to find."""

TARGET_FALSE_PER_PROMPT = 3.0
"""Issue 14: at most this many false boxes per prompt."""

OTHER_OBJECT_BEV_IOU = 0.1
"""A false box whose BEV IoU with a non-metric labelled object (a parked bicycle, a rider, a
moped...) exceeds this is counted as a box *on* that object (:attr:`PromptCount.false_on_other`)."""


RULES = ("iou", "centre")
"""Matching rules: official 3D IoU, loose BEV centre distance."""


def bev_range(boxes: np.ndarray) -> np.ndarray:
    """BEV distance ``(K,)`` of the centres of LiDAR-frame boxes ``(K, 7)`` from the origin."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    return np.hypot(b[:, 0], b[:, 1])


def other_label_boxes(
    labels: Sequence[ObjectLabel], calib: Calibration, classes: ClassSet = VOD
) -> np.ndarray:
    """LiDAR-frame boxes ``(K, 7)`` of the labels outside ``classes`` (with ``vod``:
    ``bicycle``, ``rider``, ``moped_scooter``, ...; mapped as ``labels_to_boxes`` maps them)."""
    other = [lab for lab in labels if classes.label_class(lab.name) is None]
    if not other:
        return np.zeros((0, 7))
    cam = CameraBoxes(
        location=np.array([lab.location for lab in other], dtype=np.float64),
        dimensions_hwl=np.array([lab.dimensions_hwl for lab in other], dtype=np.float64),
        rotation_y=np.array([lab.rotation_y for lab in other], dtype=np.float64),
    )
    return boxes_camera_to_lidar(cam, calib)


def assign_matches(
    pred_boxes: np.ndarray,
    pred_scores: np.ndarray,
    gt_boxes: np.ndarray,
    cls: str,
    rule: str = "iou",
) -> np.ndarray:
    """One-to-one greedy matching of answer boxes to ground-truth boxes of one class.

    Args:
        pred_boxes: ``(P, 7)`` answer boxes of class ``cls``, LiDAR frame.
        pred_scores: ``(P,)``; boxes are taken in descending score order (stable).
        gt_boxes: ``(G, 7)`` ground-truth boxes of class ``cls``, LiDAR frame.
        rule: ``iou`` (3D IoU strictly above ``MIN_OVERLAPS[cls].box3d``, the largest first) or
            ``centre`` (BEV centre distance ``<=`` the class's
            :attr:`scenes.geometry.classes.ObjectClass.find_radius`, the nearest first).

    Returns:
        ``(P,)`` int: the matched ground-truth index of each answer box, ``-1`` for none.
    """
    p = np.asarray(pred_boxes, dtype=np.float64).reshape(-1, 7)
    g = np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 7)
    out = np.full(len(p), -1, dtype=np.int64)
    if len(p) == 0 or len(g) == 0:
        return out
    if rule == "iou":
        quality = iou3d(p, g)  # (P, G), higher is better
        ok = quality > MIN_OVERLAPS[cls].box3d
    elif rule == "centre":
        dist = np.linalg.norm(p[:, None, :2] - g[None, :, :2], axis=-1)
        quality = -dist
        ok = dist <= object_class(cls).find_radius
    else:
        raise ValueError(f"rule must be one of {RULES}, got {rule!r}")
    free = np.ones(len(g), dtype=bool)
    for i in np.argsort(-np.asarray(pred_scores, dtype=np.float64), kind="stable"):
        cand = ok[i] & free
        if cand.any():
            j = int(np.argmax(np.where(cand, quality[i], -np.inf)))
            free[j] = False
            out[i] = j
    return out


@dataclass(frozen=True)
class PromptCount:
    """The outcome of one class prompt on one frame.

    Attributes:
        cls: The prompt's class.
        targets: Ground-truth objects of ``cls`` in the counted region.
        found: Of those, matched by the 3D-IoU rule.
        false_boxes: Answer boxes in the counted region matching nothing (3D-IoU rule).
        false_wrong_class: Of those, boxes of another class than the prompt's.
        false_on_other: Of those, boxes on a non-metric labelled object (BEV IoU above
            :data:`OTHER_OBJECT_BEV_IOU`).
        found_centre, false_centre: ``found`` and ``false_boxes`` with the BEV-centre rule.
        answered: Answer boxes (at the threshold) in the counted region.
    """

    cls: str
    targets: int
    found: int
    false_boxes: int
    false_wrong_class: int
    false_on_other: int
    found_centre: int
    false_centre: int
    answered: int


def count_prompt(
    cls: str,
    pred_boxes: np.ndarray,
    pred_scores: np.ndarray,
    pred_classes: Sequence[str],
    gt_boxes: np.ndarray,
    gt_classes: Sequence[str],
    pred_counted: np.ndarray,
    gt_counted: np.ndarray,
    other_boxes: np.ndarray | None = None,
) -> PromptCount:
    """Count one prompt's answer (already cut at the operating threshold); see the module doc.

    Args:
        cls: The prompt's class.
        pred_boxes, pred_scores, pred_classes: ``(P, 7)``, ``(P,)``, ``P`` names: the answer.
        gt_boxes, gt_classes: ``(G, 7)`` and ``G`` names: the frame's metric-class objects.
        pred_counted, gt_counted: ``(P,)`` / ``(G,)`` bool: inside the counted region.
        other_boxes: ``(O, 7)`` the frame's non-metric labelled objects (:func:`other_label_boxes`).
    """
    p = np.asarray(pred_boxes, dtype=np.float64).reshape(-1, 7)
    g = np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 7)
    p_same = np.array([c == cls for c in pred_classes], dtype=bool).reshape(-1)
    g_same = np.array([c == cls for c in gt_classes], dtype=bool).reshape(-1)
    p_in = np.asarray(pred_counted, dtype=bool).reshape(-1)
    g_in = np.asarray(gt_counted, dtype=bool).reshape(-1)
    same_idx, gt_idx = np.flatnonzero(p_same), np.flatnonzero(g_same)
    scores = np.asarray(pred_scores, dtype=np.float64).reshape(-1)[same_idx]
    figures = []
    iou_false = np.zeros(len(p), dtype=bool)
    for rule in RULES:
        matched = np.full(len(p), -1, dtype=np.int64)
        sub = assign_matches(p[same_idx], scores, g[gt_idx], cls, rule)
        if len(gt_idx):
            matched[same_idx] = np.where(sub >= 0, gt_idx[np.maximum(sub, 0)], -1)
        found = int(np.count_nonzero(g_in[matched[matched >= 0]]))
        false = p_in & (matched < 0)
        if rule == "iou":
            iou_false = false
        figures.append((found, int(np.count_nonzero(false))))
    others = np.zeros((0, 7)) if other_boxes is None else np.asarray(other_boxes, np.float64)
    on_other = np.zeros(len(p), dtype=bool)
    if len(p) and len(others):
        on_other = (bev_iou(p, others.reshape(-1, 7)) > OTHER_OBJECT_BEV_IOU).any(axis=1)
    return PromptCount(
        cls=cls,
        targets=int(np.count_nonzero(g_same & g_in)),
        found=figures[0][0],
        false_boxes=figures[0][1],
        false_wrong_class=int(np.count_nonzero(iou_false & ~p_same)),
        false_on_other=int(np.count_nonzero(iou_false & on_other)),
        found_centre=figures[1][0],
        false_centre=figures[1][1],
        answered=int(np.count_nonzero(p_in)),
    )


_TOTALS = (
    "targets",
    "found",
    "false_boxes",
    "false_wrong_class",
    "false_on_other",
    "found_centre",
    "false_centre",
    "answered",
)


def ask_class_prompts(
    model: TPCNet,
    features: SceneFeatures,
    threshold: float,
    gt_boxes: np.ndarray,
    gt_classes: Sequence[str],
    counted: Callable[[np.ndarray], np.ndarray],
    gt_counted: np.ndarray,
    other_boxes: np.ndarray | None = None,
    classes: ClassSet = VOD,
) -> list[PromptCount]:
    """Each prompt of :func:`class_prompts` of ``classes`` (default the three of
    :data:`CLASS_PROMPTS`) asked over one frame's encoded ``features`` at ``threshold`` and
    counted (:func:`count_prompt`); ``counted`` says which boxes ``(K, 7)`` lie in the counted
    region."""
    out = []
    for cls, text in class_prompts(classes).items():
        pred = model.ground(features, text, score_threshold=threshold)
        boxes = np.asarray(pred.boxes, dtype=np.float64).reshape(-1, 7)
        out.append(
            count_prompt(
                cls,
                boxes,
                np.asarray(pred.scores, dtype=np.float64).reshape(-1),
                list(pred.classes),
                gt_boxes,
                gt_classes,
                counted(boxes),
                gt_counted,
                other_boxes,
            )
        )
    return out


@dataclass(frozen=True)
class ClassSummary:
    """Totals of one prompt (or of the three pooled) over the frames (fields of
    :class:`PromptCount`, summed).

    Attributes:
        prompts: Prompts asked (frames; three per frame when pooled).
        recall, recall_centre: found / targets in percent (0 without targets).
        false_per_prompt, false_centre_per_prompt: false boxes / prompts.
    """

    prompts: int
    targets: int
    found: int
    false_boxes: int
    false_wrong_class: int
    false_on_other: int
    found_centre: int
    false_centre: int
    answered: int
    recall: float
    recall_centre: float
    false_per_prompt: float
    false_centre_per_prompt: float

    @staticmethod
    def of(counts: Sequence[PromptCount]) -> ClassSummary:
        """Sum prompt counts."""
        n = len(counts)
        tot = {k: sum(getattr(c, k) for c in counts) for k in _TOTALS}
        return ClassSummary(
            prompts=n,
            **tot,
            recall=100.0 * tot["found"] / tot["targets"] if tot["targets"] else 0.0,
            recall_centre=100.0 * tot["found_centre"] / tot["targets"] if tot["targets"] else 0.0,
            false_per_prompt=tot["false_boxes"] / n if n else 0.0,
            false_centre_per_prompt=tot["false_centre"] / n if n else 0.0,
        )

    def meets_targets(self) -> bool:
        """Recall >= :data:`TARGET_RECALL` and false boxes per prompt <=
        :data:`TARGET_FALSE_PER_PROMPT` (issue 14)."""
        return self.recall >= TARGET_RECALL and self.false_per_prompt <= TARGET_FALSE_PER_PROMPT
