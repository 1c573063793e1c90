"""The Talk2Car metrics, as pure functions of boxes (no model, no files).

Table II of the paper reports, per command of a split (one referred object each):

- **BEV AP and 3D AP at MSSG's AP_A and AP_B** (MSSG: W. Cheng, J. Yin, W. Li, R. Yang, J. Shen,
  "Language-Guided 3D Object Detection in Point Cloud for Autonomous Driving", arXiv 2305.15765).
  The stored copies of the paper reachable here (ar5iv 2305.15765) showed only its abstract, so
  the two threshold sets could not be read from it (searched again for issue 40 in every corpus
  of the project's search tool, docs, pages, code and issues, with "MSSG Talk2Car 3D AP_A AP_B",
  the paper's title with "AP IoU 0.5 0.25", "Talk2Car-3D evaluation": the abstract, TPCNet's
  abstract and unrelated KITTI tables only); :data:`MSSG_THRESHOLDS` holds the two sets of
  the KITTI protocol MSSG evaluates with (AP_A: IoU 0.7 for a car, 0.5 for a pedestrian or
  cyclist, KITTI's official "moderate" overlaps; AP_B: 0.5 and 0.25, KITTI's loose ones), one
  place to change should the paper's text say otherwise (the classes' ``talk2car_overlaps``,
  :mod:`scenes.geometry.classes`). AP is KITTI's 40-recall-point
  interpolated AP over every command's ranked boxes pooled by score (:func:`grounding_ap`): a box
  is a true positive when its overlap with its command's referent is **strictly greater** than
  the referent class's threshold and no higher-scored box of that command already was; every
  other box is a false positive; each command is one ground truth.
- **Talk2Car's own AP50** (:func:`talk2car_ap`): the share of commands whose best box, projected
  into the CAM_FRONT image, overlaps the command's ``2d_box`` with IoU strictly above 0.5, exactly
  as the release's ``eval.py`` computes it (``int(iou > thresh)`` averaged over commands); a
  command without a box scores 0.
- **Top-1** (:func:`top1_hits`): the best box's bird's-eye centre within
  :data:`TOP1_DISTANCE` of the referent (1.0 m for a car, 0.5 m for a pedestrian or cyclist).

Both tables name the three View-of-Delft classes, as MSSG and the paper score Talk2Car; a
referent of another class (a model of nuScenes' ten classes) is scored as the class its
:attr:`~scenes.geometry.classes.ObjectClass.scored_as` names: a truck, bus, trailer or
construction vehicle as a car, a motorcycle or bicycle as a cyclist, a traffic cone or barrier as
a pedestrian (the evaluator's minimum overlaps make the same choice).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from scenes.geometry.boxes import bev_iou, iou3d
from scenes.geometry.classes import ALL_CLASSES, VOD, object_class

MSSG_THRESHOLDS: dict[str, dict[str, float]] = {
    name: {c.name: c.talk2car_overlaps[k] for c in VOD.classes if c.talk2car_overlaps}
    for k, name in enumerate(("AP_A", "AP_B"))
}
"""IoU thresholds per referent class of MSSG's two AP definitions (module docstring): the
classes' :attr:`~scenes.geometry.classes.ObjectClass.talk2car_overlaps` (AP_A: Car 0.7,
Pedestrian and Cyclist 0.5; AP_B: 0.5 and 0.25)."""

TOP1_DISTANCE: dict[str, float] = {
    c.name: c.top1_distance for c in VOD.classes if c.top1_distance is not None
}
"""Top-1: largest bird's-eye centre distance (m) from the referent, per referent class: the
classes' :attr:`~scenes.geometry.classes.ObjectClass.top1_distance` (Car 1.0, Pedestrian and
Cyclist 0.5)."""

RECALL_POINTS = 40
"""KITTI's R40: precision interpolated at recall 1/40, 2/40, ..., 1."""

AP50_THRESHOLD = 0.5
"""Talk2Car's AP50: 2D IoU strictly above this counts."""

Overlap = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(K, 7), (1, 7) -> (K, 1)`` overlaps of LiDAR-frame boxes (:func:`bev_iou`, :func:`iou3d`)."""


@dataclass(frozen=True)
class CommandBoxes:
    """One command's answer and its referent (model frame).

    Attributes:
        boxes: ``(K, 7)`` float64 answer boxes, best first.
        scores: ``(K,)`` their scores (descending).
        referent: ``(7,)`` the referred box.
        referent_class: Its class (any class of a preset; scored as its ``scored_as``).
        classes: The answer boxes' classes (empty where not known; the metrics do not read them).
    """

    boxes: np.ndarray
    scores: np.ndarray
    referent: np.ndarray
    referent_class: str
    classes: tuple[str, ...] = ()

    @staticmethod
    def make(
        boxes: np.ndarray,
        scores: Sequence[float] | np.ndarray,
        referent: np.ndarray,
        cls: str,
        classes: Sequence[str] = (),
    ) -> CommandBoxes:
        """Checked and shaped (errors name the field)."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
        s = np.asarray(scores, dtype=np.float64).reshape(-1)
        if len(s) != len(b):
            raise ValueError(f"CommandBoxes: {len(s)} scores for {len(b)} boxes")
        r = np.asarray(referent, dtype=np.float64).reshape(7)
        if cls not in ALL_CLASSES:
            raise ValueError(f"CommandBoxes: referent class {cls!r} is not one of {ALL_CLASSES}")
        if classes and len(classes) != len(b):
            raise ValueError(f"CommandBoxes: {len(classes)} classes for {len(b)} boxes")
        return CommandBoxes(b, s, r, cls, tuple(classes))

    @property
    def scored_as(self) -> str:
        """The View-of-Delft class whose thresholds score this command (module docstring)."""
        return object_class(self.referent_class).scored_as


def interpolated_ap(tp: np.ndarray, scores: np.ndarray, positives: int) -> float:
    """KITTI's R40 AP (percent) of detections ``tp`` ``(N,)`` bool with ``scores`` ``(N,)`` over
    ``positives`` ground truths: detections ranked by score (stable), precision made monotone,
    read at each of :data:`RECALL_POINTS` recall levels (0 where not reached). No ground truth: 0."""
    if positives <= 0:
        return 0.0
    order = np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable")
    hits = np.asarray(tp, dtype=bool)[order]
    if not len(hits):
        return 0.0
    cum_tp = np.cumsum(hits)
    precision = cum_tp / np.arange(1, len(hits) + 1)
    recall = cum_tp / positives
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    total = 0.0
    for level in np.arange(1, RECALL_POINTS + 1) / RECALL_POINTS:
        reached = np.nonzero(recall >= level - 1e-12)[0]
        total += float(envelope[reached[0]]) if len(reached) else 0.0
    return 100.0 * total / RECALL_POINTS


def command_hits(command: CommandBoxes, overlap: Overlap, threshold: float) -> np.ndarray:
    """``(K,)`` bool: which of a command's boxes is its true positive (the first, by score, whose
    overlap with the referent is strictly above ``threshold``; at most one)."""
    hits = np.zeros(len(command.boxes), dtype=bool)
    if not len(command.boxes):
        return hits
    ious = np.asarray(overlap(command.boxes, command.referent[None])).reshape(-1)
    above = np.nonzero(ious > threshold)[0]
    if len(above):
        hits[above[0]] = True
    return hits


def grounding_ap(
    commands: Sequence[CommandBoxes], overlap: Overlap, thresholds: dict[str, float]
) -> float:
    """AP (percent) over ``commands`` (module docstring) at the referent class's threshold of
    ``thresholds``; no command: 0."""
    tp, scores = [], []
    for command in commands:
        tp.append(command_hits(command, overlap, thresholds[command.scored_as]))
        scores.append(command.scores)
    if not commands:
        return 0.0
    return interpolated_ap(np.concatenate(tp), np.concatenate(scores), len(commands))


def table_ii(commands: Sequence[CommandBoxes]) -> dict[str, float]:
    """``{"BEV AP_A", "3D AP_A", "BEV AP_B", "3D AP_B"} -> percent`` of ``commands``."""
    out = {}
    for name, thresholds in MSSG_THRESHOLDS.items():
        out[f"BEV {name}"] = grounding_ap(commands, bev_iou, thresholds)
        out[f"3D {name}"] = grounding_ap(commands, iou3d, thresholds)
    return out


def top1_distance(cls: str) -> float:
    """The top-1 distance (m) of a referent of class ``cls``: :data:`TOP1_DISTANCE` of the class
    it is scored as (module docstring)."""
    return TOP1_DISTANCE[object_class(cls).scored_as]


def top1_hits(commands: Sequence[CommandBoxes]) -> np.ndarray:
    """``(C,)`` bool: the best box's bird's-eye centre lies within :data:`TOP1_DISTANCE` of the
    referent (a command without a box: False)."""
    out = np.zeros(len(commands), dtype=bool)
    for i, command in enumerate(commands):
        if len(command.boxes):
            best = command.boxes[int(np.argmax(command.scores))]
            gap = float(np.hypot(*(best[:2] - command.referent[:2])))
            out[i] = gap <= top1_distance(command.referent_class)
    return out


def iou_2d(a: Sequence[float], b: Sequence[float]) -> float:
    """IoU of two image boxes given as Talk2Car writes them, ``[x, y, w, h]`` in pixels."""
    ax0, ay0, aw, ah = (float(v) for v in a)
    bx0, by0, bw, bh = (float(v) for v in b)
    iw = max(0.0, min(ax0 + aw, bx0 + bw) - max(ax0, bx0))
    ih = max(0.0, min(ay0 + ah, by0 + bh) - max(ay0, by0))
    inter = iw * ih
    union = max(aw, 0.0) * max(ah, 0.0) + max(bw, 0.0) * max(bh, 0.0) - inter
    return inter / max(union, 1e-7)


def talk2car_ap(
    predicted: Sequence[Sequence[float] | None], truth: Sequence[Sequence[float]]
) -> float:
    """Talk2Car's AP50 (percent): the share of commands whose predicted 2D box (``[x, y, w, h]``,
    None: no box) has IoU strictly above :data:`AP50_THRESHOLD` with the truth; no command: 0."""
    if len(predicted) != len(truth):
        raise ValueError(f"talk2car_ap: {len(predicted)} predictions for {len(truth)} commands")
    if not truth:
        return 0.0
    hits = [
        p is not None and iou_2d(p, t) > AP50_THRESHOLD
        for p, t in zip(predicted, truth, strict=True)
    ]
    return 100.0 * float(np.mean(hits))


__all__ = [
    "AP50_THRESHOLD",
    "MSSG_THRESHOLDS",
    "RECALL_POINTS",
    "TOP1_DISTANCE",
    "CommandBoxes",
    "command_hits",
    "grounding_ap",
    "interpolated_ap",
    "iou_2d",
    "table_ii",
    "talk2car_ap",
    "top1_distance",
    "top1_hits",
]
