"""The official View-of-Delft (VoD) evaluation, re-implemented in pure NumPy.

This is the metric the Talk2Radar paper reports (spec ``talk2radar-format-and-eval.md`` §2.3): 3D and
BEV average precision and average orientation similarity (AOS) per class, over the entire annotated
area and over the driving corridor, computed from KITTI-format labels in the camera frame.

Protocol, step by step (every number below is the devkit's):

- Classes ``Car``, ``Pedestrian``, ``Cyclist``; names compare case-insensitively. ``Van`` is a
  neighbour of ``Car`` and ``Person_sitting`` of ``Pedestrian`` (their ground truth is "ignored",
  not "missed"); VoD has neither. Every other name counts for no class; a name that is not one of
  KITTI's or VoD's known classes either (a typo such as ``Cyclst``) is counted and reported
  (:attr:`VodResult.unknown_gt_classes`, the last line of :meth:`VodResult.format_table`).
- Minimum overlaps (the devkit's second table, the only one it reports): 2D image box 0.7 / 0.5 /
  0.5, BEV and 3D 0.5 / 0.25 / 0.25 for Car / Pedestrian / Cyclist. A match needs an overlap
  strictly greater than the minimum.
- Per frame and class, every object gets a state: 0 (counts), 1 (ignored: may absorb a match but
  is neither TP, FN nor FP) or -1 (another class, never matched).
  Ground truth: the class matches and it is not ignored -> 0; ignored when ``occluded > 4`` or the
  2D height ``bottom - top <= 40`` px, or, in the driving corridor only, when the camera-frame
  bottom centre has ``x < -4``, ``x > 4`` or ``z > 25`` m. Ignored ground truth of the class and
  neighbour-class ground truth -> 1; anything else -> -1.
  Detections, in this order: 2D height ``|bottom - top| < 40`` px -> 1 (whatever the class);
  outside the corridor in corridor mode -> 1 (whatever the class); class matches -> 0; else -1.
- Overlaps, detections x ground truth, in the camera frame (x right, y down, z forward): 2D IoU
  of ``left, top, right, bottom`` (no +1); BEV IoU of the rectangles centred at ``(x, z)`` with
  length ``l`` along ``(cos ry, -sin ry)`` and width ``w`` across it; 3D IoU = BEV intersection area
  x vertical overlap of ``[y - h, y]`` over the union of volumes. The BEV and 3D overlaps are exact
  (:mod:`scenes.boxes`), so identical boxes have IoU 1, which the devkit gets wrong.
- Score thresholds: in every frame, each ground truth with state != -1 takes the highest-scoring
  free detection with state != -1 above the minimum overlap; the scores of the pairs with both
  states 0 are pooled over all frames, sorted in descending order and thinned to at most 41
  thresholds spaced about 1/40 apart in recall (:func:`score_thresholds`).
- At each threshold (detections scoring below it drop out), each ground truth with state != -1
  takes the free detection of state 0 with the largest overlap above the minimum, else the first
  free detection of state 1 that overlaps enough. Unmatched ground truth of state 0 is a false
  negative; a match involving a state-1 object is consumed silently; the rest are true positives,
  each adding ``(1 + cos(alpha_gt - alpha_dt)) / 2`` to the orientation similarity. Free detections
  of state 0 are false positives (in the 2D pass, minus those lying on a ``DontCare`` box).
- precision = TP / (TP + FP), recall = TP / (TP + FN), aos = similarity / (TP + FP); each curve is
  replaced by the maximum over its tail; unused slots of the 41 stay 0.
- AP R11 = mean of precision at slots 0, 4, ..., 40 (recall 0 included) x 100: the headline.
  AP R40 = mean of slots 1..40 x 100, reported beside it. AOS is always computed, and, as in the
  devkit, from the 2D image-box pass (its thresholds and matches), so it depends on the predicted
  2D boxes and alphas, not on the 3D boxes.
- mAP = mean over the three classes. A class without valid ground truth scores 0 (as the devkit).

The devkit's offsets, and where this file departs from the devkit (``vod-tudelft`` 1.0.3):

- Before computing overlaps the devkit adds 0.01 rad to every detection's ``rotation_y`` and
  0.01 px to every detection's 2D box (a workaround for its polygon routine). That small rotation
  flips matches whose IoU lies near a threshold, and with few objects one flipped match moves an
  11-point AP by a whole slot (measured: up to 6 AP on random 80-frame sets). Since published
  numbers include it, it is reproduced by default (``devkit_offsets=True``); ``False`` scores the
  boxes exactly as written.
- The devkit's rotated IoU is float32 polygon clipping that fails for identical or nearly identical
  boxes (IoU 0 or 0.33 instead of 1). Here the overlaps are exact and float64, so identical boxes
  have IoU 1; the devkit's numbers are wrong there and these are not.
- If every detection at some threshold is absorbed by ignored ground truth (TP + FP = 0), the devkit
  divides by zero (NaN); here precision and aos are 0 there.

Evaluating a subset (one prompt type, one depth bin) is :func:`evaluate_frames` on a filtered dict.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from scenes.actors import CLASSES
from scenes.boxes import bev_iou, iou3d
from scenes.kitti import ObjectLabel

NUM_SAMPLE_POINTS = 41
"""Slots of the precision / recall / aos curves (recall 0, 1/40, ..., 1)."""

MIN_HEIGHT_PX = 40.0
"""2D-height filter in pixels: ground truth with height <= 40 and detections with height < 40 are
ignored."""

MAX_OCCLUSION = 4
"""Ground truth with a larger ``occluded`` value is ignored (never the case in VoD)."""

CORRIDOR_HALF_WIDTH = 4.0
"""Driving corridor: ``-4 <= x <= 4`` m in the camera frame (x to the right)..."""

CORRIDOR_MAX_DEPTH = 25.0
"""...and ``z <= 25`` m (z forward); there is no lower bound on z."""

DEVKIT_OFFSET = 0.01
"""The devkit adds this to every detection's ``rotation_y`` (rad) and 2D box (px) before computing
overlaps; reproduced by default (``devkit_offsets=True``)."""

DONT_CARE = "DontCare"
"""Ground-truth name of KITTI's don't-care regions (compared case-sensitively; VoD has none)."""

_NEIGHBOURS = {"car": "van", "pedestrian": "person_sitting"}

KNOWN_OTHER_CLASSES: frozenset[str] = frozenset(
    {
        # KITTI
        "van",
        "truck",
        "person_sitting",
        "tram",
        "misc",
        "dontcare",
        # View-of-Delft (spec §1.4)
        "rider",
        "bicycle",
        "bicycle_rack",
        "human_depiction",
        "moped_scooter",
        "motor",
        "ride_other",
        "ride_uncertain",
        "vehicle_other",
    }
)
"""Class names (lower case) that are known but not scored: as the protocol says they never count,
silently. Any other name outside the three classes (a typo such as ``Cyclst``) is also kept out of
the metric, but counted in :attr:`VodResult.unknown_gt_classes` / ``unknown_dt_classes`` and
reported, so that it cannot silently change a score."""


def unknown_class_counts(frames: Mapping[str, Sequence[ObjectLabel]]) -> dict[str, int]:
    """Class names of ``frames`` (frame id -> labels) that are neither metric classes nor
    :data:`KNOWN_OTHER_CLASSES` (case-insensitive), with their number of objects, by name."""
    metric = {c.lower() for c in CLASSES}
    counts: dict[str, int] = {}
    for labels in frames.values():
        for lab in labels:
            low = lab.name.lower()
            if low not in metric and low not in KNOWN_OTHER_CLASSES:
                counts[lab.name] = counts.get(lab.name, 0) + 1
    return dict(sorted(counts.items()))


class Metric(enum.Enum):
    """The overlap a match is judged on."""

    IMAGE = 0
    BEV = 1
    BOX3D = 2


@dataclass(frozen=True)
class MinOverlaps:
    """Minimum overlaps of one class (a match needs strictly more)."""

    image: float
    bev: float
    box3d: float

    def of(self, metric: Metric) -> float:
        return {Metric.IMAGE: self.image, Metric.BEV: self.bev, Metric.BOX3D: self.box3d}[metric]


MIN_OVERLAPS: dict[str, MinOverlaps] = {
    "Car": MinOverlaps(image=0.7, bev=0.5, box3d=0.5),
    "Pedestrian": MinOverlaps(image=0.5, bev=0.25, box3d=0.25),
    "Cyclist": MinOverlaps(image=0.5, bev=0.25, box3d=0.25),
}
"""The devkit's reported (second) overlap table."""

AREAS: tuple[str, ...] = ("entire_area", "roi")
"""Result names of the two areas: the entire annotated area and the driving corridor."""


# ---------------------------------------------------------------------------------------------
# Per-frame arrays and overlaps


@dataclass(frozen=True)
class FrameObjects:
    """The objects of one frame as arrays (camera frame, KITTI conventions).

    Attributes:
        names: ``(K,)`` class names as written.
        occluded: ``(K,)`` int.
        alpha: ``(K,)`` observation angle, rad.
        bbox: ``(K, 4)`` 2D box ``left, top, right, bottom`` in pixels.
        boxes: ``(K, 7)`` camera boxes ``x, y, z, l, h, w, ry``: bottom centre (x right, y down,
            z forward), length, height, width in metres, ``rotation_y`` in rad.
        scores: ``(K,)`` confidence; 0 where a label has none (the devkit's rule).
    """

    names: np.ndarray
    occluded: np.ndarray
    alpha: np.ndarray
    bbox: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray

    @classmethod
    def from_labels(cls, labels: Sequence[ObjectLabel]) -> FrameObjects:
        k = len(labels)
        if k == 0:
            return cls(
                names=np.zeros(0, dtype=object),
                occluded=np.zeros(0, dtype=np.int64),
                alpha=np.zeros(0),
                bbox=np.zeros((0, 4)),
                boxes=np.zeros((0, 7)),
                scores=np.zeros(0),
            )
        hwl = np.array([lab.dimensions_hwl for lab in labels], dtype=np.float64)
        boxes = np.concatenate(
            [
                np.array([lab.location for lab in labels], dtype=np.float64),
                hwl[:, [2, 0, 1]],
                np.array([[lab.rotation_y] for lab in labels], dtype=np.float64),
            ],
            axis=1,
        )
        return cls(
            names=np.array([lab.name for lab in labels], dtype=object),
            occluded=np.array([lab.occluded for lab in labels], dtype=np.int64),
            alpha=np.array([lab.alpha for lab in labels], dtype=np.float64),
            bbox=np.array([lab.bbox for lab in labels], dtype=np.float64).reshape(k, 4),
            boxes=boxes,
            scores=np.array(
                [0.0 if lab.score is None else lab.score for lab in labels], dtype=np.float64
            ),
        )

    def __len__(self) -> int:
        return len(self.names)


def image_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """2D IoU ``(K1, K2)`` of image boxes ``a (K1, 4)`` and ``b (K2, 4)`` (left, top, right,
    bottom; pixels, no +1)."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    iw = np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    ih = np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.where((iw > 0) & (ih > 0), iw * ih, 0.0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(inter > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _image_intersection_over_first(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over the area of ``a`` ``(K1, K2)`` (the don't-care test)."""
    iw = np.minimum(a[:, None, 2], b[None, :, 2]) - np.maximum(a[:, None, 0], b[None, :, 0])
    ih = np.minimum(a[:, None, 3], b[None, :, 3]) - np.maximum(a[:, None, 1], b[None, :, 1])
    inter = np.where((iw > 0) & (ih > 0), iw * ih, 0.0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    return np.where(inter > 0, inter / np.where(area_a > 0, area_a, 1.0)[:, None], 0.0)


def camera_to_overlap_boxes(boxes: np.ndarray) -> np.ndarray:
    """Camera boxes ``(K, 7)`` ``x, y, z, l, h, w, ry`` -> ``(K, 7)`` boxes for :mod:`scenes.boxes`.

    The result lives in the right-handed frame ``(x_cam, z_cam, -y_cam)`` (right, forward, up) with
    the geometric centre and a counter-clockwise yaw: ``(x, z, -y + h/2, l, w, h, -ry)``. A camera
    box's length axis is ``(cos ry, -sin ry)`` in the ``(x, z)`` plane (KITTI's and the devkit's
    convention), which is the counter-clockwise direction ``-ry`` there; its vertical extent
    ``[y - h, y]`` (y down) becomes ``[-y, -y + h]`` (up). Overlaps of the results are therefore the
    devkit's BEV and 3D overlaps.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    x, y, z, length, h, w, ry = b.T
    return np.stack([x, z, -y + h / 2.0, length, w, h, -ry], axis=1)


def camera_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact BEV IoU ``(K1, K2)`` of camera boxes ``(K, 7)`` ``x, y, z, l, h, w, ry``."""
    return bev_iou(camera_to_overlap_boxes(a), camera_to_overlap_boxes(b))


def camera_iou3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact 3D IoU ``(K1, K2)`` of camera boxes ``(K, 7)`` ``x, y, z, l, h, w, ry``."""
    return iou3d(camera_to_overlap_boxes(a), camera_to_overlap_boxes(b))


def frame_overlaps(dt: FrameObjects, gt: FrameObjects, metric: Metric) -> np.ndarray:
    """Overlaps ``(D, G)`` of a frame's detections with its ground truth."""
    if len(dt) == 0 or len(gt) == 0:
        return np.zeros((len(dt), len(gt)))
    if metric is Metric.IMAGE:
        return image_iou(dt.bbox, gt.bbox)
    if metric is Metric.BEV:
        return camera_bev_iou(dt.boxes, gt.boxes)
    return camera_iou3d(dt.boxes, gt.boxes)


# ---------------------------------------------------------------------------------------------
# States


def _in_corridor(boxes: np.ndarray) -> np.ndarray:
    x, z = boxes[:, 0], boxes[:, 2]
    return (x >= -CORRIDOR_HALF_WIDTH) & (x <= CORRIDOR_HALF_WIDTH) & (z <= CORRIDOR_MAX_DEPTH)


def _lower(names: np.ndarray) -> np.ndarray:
    return np.array([str(n).lower() for n in names], dtype=object)


def gt_states(gt: FrameObjects, cls: str, corridor: bool) -> np.ndarray:
    """Ground-truth states ``(G,)`` int: 0 counts, 1 ignored, -1 another class."""
    if len(gt) == 0:
        return np.zeros(0, dtype=np.int64)
    names = _lower(gt.names)
    wanted = cls.lower()
    valid = names == wanted
    neighbour = names == _NEIGHBOURS.get(wanted, "\0")
    height = gt.bbox[:, 3] - gt.bbox[:, 1]
    ignore = (gt.occluded > MAX_OCCLUSION) | (height <= MIN_HEIGHT_PX)
    if corridor:
        ignore |= ~_in_corridor(gt.boxes)
    states = np.full(len(gt), -1, dtype=np.int64)
    states[neighbour | (valid & ignore)] = 1
    states[valid & ~ignore] = 0
    return states


def dt_states(dt: FrameObjects, cls: str, corridor: bool) -> np.ndarray:
    """Detection states ``(D,)`` int: 0 counts, 1 ignored (too small or outside the corridor,
    whatever the class), -1 another class."""
    if len(dt) == 0:
        return np.zeros(0, dtype=np.int64)
    ignored = np.abs(dt.bbox[:, 3] - dt.bbox[:, 1]) < MIN_HEIGHT_PX
    if corridor:
        ignored |= ~_in_corridor(dt.boxes)
    states = np.where(_lower(dt.names) == cls.lower(), 0, -1).astype(np.int64)
    states[ignored] = 1
    return states


# ---------------------------------------------------------------------------------------------
# Matching


def _tp_scores(
    overlaps: np.ndarray,
    gt_state: np.ndarray,
    dt_state: np.ndarray,
    scores: np.ndarray,
    min_overlap: float,
) -> list[float]:
    """Scores of the true positives of one frame when every ground truth takes the
    highest-scoring free detection (the threshold-collection pass)."""
    out: list[float] = []
    if len(dt_state) == 0:
        return out
    free = dt_state != -1
    for i in np.flatnonzero(gt_state != -1):
        cand = free & (overlaps[:, i] > min_overlap)
        if not cand.any():
            continue
        j = int(np.argmax(np.where(cand, scores, -np.inf)))
        free[j] = False
        if gt_state[i] == 0 and dt_state[j] == 0:
            out.append(float(scores[j]))
    return out


def score_thresholds(
    tp_scores: Sequence[float] | np.ndarray, num_gt: int, num_points: int = NUM_SAMPLE_POINTS
) -> np.ndarray:
    """Pick at most ``num_points`` score thresholds from the true-positive scores.

    Walking the scores in descending order, score ``i`` lies between recalls
    ``l = (i + 1) / num_gt`` and ``r = (i + 2) / num_gt`` (``r = l`` for the last). It is skipped
    when ``r`` is closer than ``l`` to the current recall target and it is not the last score;
    otherwise it is kept and the target grows by ``1 / (num_points - 1)``.
    """
    scores = np.sort(np.asarray(tp_scores, dtype=np.float64))[::-1]
    kept: list[float] = []
    target = 0.0
    step = 1.0 / (num_points - 1.0)
    n = len(scores)
    for i, score in enumerate(scores):
        left = (i + 1) / num_gt
        right = (i + 2) / num_gt if i < n - 1 else left
        if i < n - 1 and (right - target) < (target - left):
            continue
        kept.append(float(score))
        target += step
    return np.asarray(kept, dtype=np.float64)


@dataclass(frozen=True)
class _Counts:
    """Per-threshold sums ``(T,)``: true positives, false positives, false negatives, similarity."""

    tp: np.ndarray
    fp: np.ndarray
    fn: np.ndarray
    similarity: np.ndarray


def _frame_counts(
    overlaps: np.ndarray,
    gt_state: np.ndarray,
    dt_state: np.ndarray,
    scores: np.ndarray,
    gt_alpha: np.ndarray,
    dt_alpha: np.ndarray,
    min_overlap: float,
    thresholds: np.ndarray,
    dont_care: np.ndarray | None,
) -> _Counts:
    """TP / FP / FN / orientation similarity of one frame at every threshold at once.

    ``dont_care``: ``(D, C)`` intersection-over-detection-area of the detections with the frame's
    don't-care boxes (2D pass only), or None.
    """
    t = len(thresholds)
    tp = np.zeros(t)
    fn = np.zeros(t)
    sim = np.zeros(t)
    if len(dt_state) == 0:
        fn += np.count_nonzero(gt_state == 0)
        return _Counts(tp, np.zeros(t), fn, sim)
    active = (scores[None, :] >= thresholds[:, None]) & (dt_state != -1)[None, :]  # (T, D)
    is0 = (dt_state == 0)[None, :]
    is1 = (dt_state == 1)[None, :]
    rows = np.arange(t)
    for i in np.flatnonzero(gt_state != -1):
        ov = overlaps[:, i]
        cand = active & (ov > min_overlap)[None, :]
        cand0 = cand & is0
        cand1 = cand & is1
        has0 = cand0.any(axis=1)
        has1 = cand1.any(axis=1)
        j = np.where(
            has0,
            np.argmax(np.where(cand0, ov[None, :], -np.inf), axis=1),
            np.argmax(cand1, axis=1),
        )
        matched = has0 | has1
        if gt_state[i] == 0:
            fn += ~matched
        active[rows[matched], j[matched]] = False
        if gt_state[i] == 0:
            hit = has0  # a state-0 detection was taken for a state-0 ground truth
            tp += hit
            sim += np.where(hit, (1.0 + np.cos(gt_alpha[i] - dt_alpha[j])) / 2.0, 0.0)
    unmatched0 = active & is0
    if dont_care is not None and dont_care.shape[1] > 0:
        on_dont_care = (dont_care > min_overlap).any(axis=1)  # (D,)
        unmatched0 &= ~on_dont_care[None, :]
    fp = unmatched0.sum(axis=1).astype(np.float64)
    return _Counts(tp, fp, fn, sim)


@dataclass(frozen=True)
class PRCurve:
    """Interpolated curves of one class, area and overlap kind.

    Attributes:
        thresholds: ``(T,)`` score thresholds, ``T <= 41``.
        precision: ``(41,)`` interpolated precision (max over the tail; zeros past ``T``).
        recall: ``(41,)`` interpolated recall.
        orientation: ``(41,)`` interpolated AOS curve.
        num_gt: Number of valid ground-truth objects (state 0).
    """

    thresholds: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    orientation: np.ndarray
    num_gt: int

    @property
    def ap_r11(self) -> float:
        return ap_r11(self.precision)

    @property
    def ap_r40(self) -> float:
        return ap_r40(self.precision)

    @property
    def aos_r11(self) -> float:
        return ap_r11(self.orientation)

    @property
    def aos_r40(self) -> float:
        return ap_r40(self.orientation)


def ap_r11(curve: np.ndarray) -> float:
    """11-point AP: mean of slots 0, 4, ..., 40 of a 41-slot curve, x 100."""
    return float(np.sum(np.asarray(curve)[0:NUM_SAMPLE_POINTS:4]) / 11.0 * 100.0)


def ap_r40(curve: np.ndarray) -> float:
    """40-point AP: mean of slots 1..40 of a 41-slot curve, x 100."""
    return float(np.sum(np.asarray(curve)[1:NUM_SAMPLE_POINTS]) / 40.0 * 100.0)


def _tail_max(values: np.ndarray) -> np.ndarray:
    return np.maximum.accumulate(values[::-1])[::-1]


@dataclass(frozen=True)
class _PreparedFrame:
    gt: FrameObjects
    dt: FrameObjects
    overlaps: dict[Metric, np.ndarray]
    dont_care: np.ndarray  # (D, C) intersection over detection area with DontCare boxes


def _with_devkit_offsets(dt: FrameObjects) -> FrameObjects:
    boxes = dt.boxes.copy()
    boxes[:, 6] += DEVKIT_OFFSET
    return FrameObjects(
        names=dt.names,
        occluded=dt.occluded,
        alpha=dt.alpha,
        bbox=dt.bbox + DEVKIT_OFFSET,
        boxes=boxes,
        scores=dt.scores,
    )


def _prepare(gt: FrameObjects, dt: FrameObjects, devkit_offsets: bool) -> _PreparedFrame:
    shifted = _with_devkit_offsets(dt) if devkit_offsets else dt
    overlaps = {m: frame_overlaps(shifted, gt, m) for m in Metric}
    dc = gt.bbox[np.array([str(n) == DONT_CARE for n in gt.names], dtype=bool)]
    if len(dt) and len(dc):
        dont_care = _image_intersection_over_first(dt.bbox, dc)
    else:
        dont_care = np.zeros((len(dt), 0))
    return _PreparedFrame(gt=gt, dt=dt, overlaps=overlaps, dont_care=dont_care)


def _class_curve(
    frames: Sequence[_PreparedFrame],
    states: Sequence[tuple[np.ndarray, np.ndarray]],
    metric: Metric,
    min_overlap: float,
) -> PRCurve:
    num_gt = int(sum(np.count_nonzero(g == 0) for g, _ in states))
    pooled: list[float] = []
    for frame, (gs, ds) in zip(frames, states, strict=True):
        pooled += _tp_scores(frame.overlaps[metric], gs, ds, frame.dt.scores, min_overlap)
    thresholds = score_thresholds(pooled, num_gt) if num_gt > 0 else np.zeros(0)
    t = len(thresholds)
    sums = np.zeros((4, t))
    if t:
        for frame, (gs, ds) in zip(frames, states, strict=True):
            c = _frame_counts(
                frame.overlaps[metric],
                gs,
                ds,
                frame.dt.scores,
                frame.gt.alpha,
                frame.dt.alpha,
                min_overlap,
                thresholds,
                frame.dont_care if metric is Metric.IMAGE else None,
            )
            sums += np.stack([c.tp, c.fp, c.fn, c.similarity])
    tp, fp, fn, sim = sums
    precision = np.zeros(NUM_SAMPLE_POINTS)
    recall = np.zeros(NUM_SAMPLE_POINTS)
    orientation = np.zeros(NUM_SAMPLE_POINTS)
    with np.errstate(divide="ignore", invalid="ignore"):
        detected = tp + fp
        precision[:t] = np.where(detected > 0, tp / np.where(detected > 0, detected, 1), 0.0)
        orientation[:t] = np.where(detected > 0, sim / np.where(detected > 0, detected, 1), 0.0)
        recall[:t] = np.where(tp + fn > 0, tp / np.maximum(tp + fn, 1), 0.0)
    return PRCurve(
        thresholds=thresholds,
        precision=_tail_max(precision),
        recall=_tail_max(recall),
        orientation=_tail_max(orientation),
        num_gt=num_gt,
    )


# ---------------------------------------------------------------------------------------------
# Results


@dataclass(frozen=True)
class APValue:
    """One AP (or AOS) in percent at 11 and 40 recall points."""

    r11: float
    r40: float


@dataclass(frozen=True)
class ClassResult:
    """One class in one area.

    Attributes:
        name: ``Car``, ``Pedestrian`` or ``Cyclist``.
        num_gt: Valid ground-truth objects (class matches, not ignored).
        ap_3d: 3D AP. ap_bev: BEV AP. aos: AOS (from the 2D pass). ap_2d: 2D image-box AP.
    """

    name: str
    num_gt: int
    ap_3d: APValue
    ap_bev: APValue
    aos: APValue
    ap_2d: APValue


@dataclass(frozen=True)
class AreaResult:
    """All classes in one area (entire annotated area or driving corridor)."""

    classes: tuple[ClassResult, ...]

    def __getitem__(self, name: str) -> ClassResult:
        for c in self.classes:
            if c.name.lower() == name.lower():
                return c
        raise KeyError(name)

    def _mean(self, attr: str, points: str) -> float:
        return float(np.mean([getattr(getattr(c, attr), points) for c in self.classes]))

    @property
    def map_3d(self) -> float:
        """mAP 3D at 11 points (the headline)."""
        return self._mean("ap_3d", "r11")

    @property
    def map_bev(self) -> float:
        return self._mean("ap_bev", "r11")

    @property
    def maos(self) -> float:
        return self._mean("aos", "r11")

    @property
    def map_3d_r40(self) -> float:
        return self._mean("ap_3d", "r40")

    @property
    def map_bev_r40(self) -> float:
        return self._mean("ap_bev", "r40")

    @property
    def maos_r40(self) -> float:
        return self._mean("aos", "r40")

    def to_dict(self) -> dict[str, float]:
        """The devkit's keys (``Car_3d_all``, ``Car_bev_all``, ``Car_aos_all``, ...) at 11 points,
        the same with suffix ``_R40``, and ``mAP_3d``, ``mAP_bev``, ``mAOS`` (also ``_R40``)."""
        out: dict[str, float] = {}
        for c in self.classes:
            out[f"{c.name}_3d_all"] = c.ap_3d.r11
            out[f"{c.name}_bev_all"] = c.ap_bev.r11
            out[f"{c.name}_aos_all"] = c.aos.r11
        for c in self.classes:
            out[f"{c.name}_3d_all_R40"] = c.ap_3d.r40
            out[f"{c.name}_bev_all_R40"] = c.ap_bev.r40
            out[f"{c.name}_aos_all_R40"] = c.aos.r40
        out["mAP_3d"] = self.map_3d
        out["mAP_bev"] = self.map_bev
        out["mAOS"] = self.maos
        out["mAP_3d_R40"] = self.map_3d_r40
        out["mAP_bev_R40"] = self.map_bev_r40
        out["mAOS_R40"] = self.maos_r40
        return out


@dataclass(frozen=True)
class VodResult:
    """The official evaluation of a set of frames.

    Attributes:
        entire_area: Results over the entire annotated area.
        roi: Results in the driving corridor.
        num_frames: Frames evaluated.
        unknown_gt_classes: Ground-truth class names that are neither scored nor known (see
            :data:`KNOWN_OTHER_CLASSES`) -> number of objects; they count for no class.
        unknown_dt_classes: The same for the detections.
    """

    entire_area: AreaResult
    roi: AreaResult
    num_frames: int
    unknown_gt_classes: Mapping[str, int] = field(default_factory=dict)
    unknown_dt_classes: Mapping[str, int] = field(default_factory=dict)

    def area(self, name: str) -> AreaResult:
        """``"entire_area"`` or ``"roi"``."""
        if name not in AREAS:
            raise KeyError(f"unknown area {name!r}; expected one of {AREAS}")
        return self.entire_area if name == "entire_area" else self.roi

    def to_dict(self) -> dict[str, dict[str, float]]:
        """``{"entire_area": {...}, "roi": {...}}`` with :meth:`AreaResult.to_dict` inside."""
        return {"entire_area": self.entire_area.to_dict(), "roi": self.roi.to_dict()}

    def unknown_classes_note(self) -> str | None:
        """One line naming the unknown class names left out of the metric, or None."""
        parts = []
        for what, counts in (
            ("ground-truth", self.unknown_gt_classes),
            ("detection", self.unknown_dt_classes),
        ):
            if counts:
                names = ", ".join(f"{name!r} x{n}" for name, n in counts.items())
                parts.append(f"{sum(counts.values())} {what} object(s) ({names})")
        if not parts:
            return None
        return (
            "Not scored, unknown class name: "
            + "; ".join(parts)
            + f" (the classes are {', '.join(CLASSES)})"
        )

    def format_table(self) -> str:
        """A plain-text summary: class x {3D, BEV, AOS} x {entire area, corridor}, R11 / R40."""
        lines = []
        titles = {"entire_area": "Entire annotated area", "roi": "Driving corridor"}
        header = f"{'':<12}{'#GT':>5}  {'3D R11 / R40':>15}  {'BEV R11 / R40':>15}  {'AOS R11 / R40':>15}"
        for name in AREAS:
            res = self.area(name)
            lines.append(f"{titles[name]} ({self.num_frames} frames)")
            lines.append(header)
            for c in res.classes:
                lines.append(
                    f"{c.name:<12}{c.num_gt:>5}  {_pair(c.ap_3d.r11, c.ap_3d.r40)}  "
                    f"{_pair(c.ap_bev.r11, c.ap_bev.r40)}  {_pair(c.aos.r11, c.aos.r40)}"
                )
            lines.append(
                f"{'mean':<12}{'':>5}  {_pair(res.map_3d, res.map_3d_r40)}  "
                f"{_pair(res.map_bev, res.map_bev_r40)}  {_pair(res.maos, res.maos_r40)}"
            )
            lines.append("")
        note = self.unknown_classes_note()
        if note is not None:
            lines.append(note)
        return "\n".join(lines).rstrip() + "\n"


def _pair(r11: float, r40: float) -> str:
    return f"{r11:6.2f} / {r40:6.2f}"


def evaluate_area(
    frames: Sequence[_PreparedFrame], corridor: bool, classes: Sequence[str] = CLASSES
) -> AreaResult:
    """Evaluate prepared frames in one area (corridor or not)."""
    results = []
    for cls in classes:
        states = [(gt_states(f.gt, cls, corridor), dt_states(f.dt, cls, corridor)) for f in frames]
        # Frames where nothing of this class can count contribute nothing: skip them.
        keep = [i for i, (g, d) in enumerate(states) if np.any(g != -1) or np.any(d == 0)]
        sub_frames = [frames[i] for i in keep]
        sub_states = [states[i] for i in keep]
        mins = MIN_OVERLAPS[cls]
        curves = {m: _class_curve(sub_frames, sub_states, m, mins.of(m)) for m in Metric}
        results.append(
            ClassResult(
                name=cls,
                num_gt=curves[Metric.BOX3D].num_gt,
                ap_3d=APValue(curves[Metric.BOX3D].ap_r11, curves[Metric.BOX3D].ap_r40),
                ap_bev=APValue(curves[Metric.BEV].ap_r11, curves[Metric.BEV].ap_r40),
                aos=APValue(curves[Metric.IMAGE].aos_r11, curves[Metric.IMAGE].aos_r40),
                ap_2d=APValue(curves[Metric.IMAGE].ap_r11, curves[Metric.IMAGE].ap_r40),
            )
        )
    return AreaResult(classes=tuple(results))


def evaluate_frames(
    gt: Mapping[str, Sequence[ObjectLabel]],
    dt: Mapping[str, Sequence[ObjectLabel]],
    devkit_offsets: bool = True,
) -> VodResult:
    """Score detections against ground truth with the official VoD protocol.

    Args:
        gt: Frame id -> ground-truth labels. Its keys are the frames evaluated.
        dt: Frame id -> detections (labels with scores; a missing score counts as 0). A frame of
            ``gt`` missing here has no detections.
        devkit_offsets: Apply the devkit's offsets (detections' ``rotation_y`` + 0.01 rad and 2D
            boxes + 0.01 px, for the overlaps only), so that numbers match the devkit's. False:
            overlaps of the boxes exactly as written.

    Returns:
        :class:`VodResult` for the entire annotated area and the driving corridor.

    Raises:
        ValueError: ``dt`` holds frames that ``gt`` lacks (named in the message).
    """
    extra = sorted(set(dt) - set(gt))
    if extra:
        shown = ", ".join(extra[:5]) + (f" and {len(extra) - 5} more" if len(extra) > 5 else "")
        raise ValueError(f"detections for {len(extra)} frame(s) without ground truth: {shown}")
    content = tuple((f, tuple(gt[f]), tuple(dt.get(f, ()))) for f in sorted(gt))
    return _evaluate_content(content, devkit_offsets)


@lru_cache(maxsize=64)
def _evaluate_content(
    content: tuple[tuple[str, tuple[ObjectLabel, ...], tuple[ObjectLabel, ...]], ...],
    devkit_offsets: bool,
) -> VodResult:
    """:func:`evaluate_frames` of ``(frame id, ground truth, detections)`` triples. Labels are
    frozen values and the result too, so an evaluation asked for again (a report rescored from
    the files it wrote) is not computed again, nor a frame prepared again (the per-prompt-type
    tables score subsets of the same frames)."""
    frames = [_prepared_frame(g, d, devkit_offsets) for _, g, d in content]
    gt = {f: g for f, g, _ in content}
    dt = {f: d for f, _, d in content if d}
    return VodResult(
        entire_area=evaluate_area(frames, corridor=False),
        roi=evaluate_area(frames, corridor=True),
        num_frames=len(frames),
        unknown_gt_classes=unknown_class_counts(gt),
        unknown_dt_classes=unknown_class_counts(dt),
    )


@lru_cache(maxsize=8192)
def _prepared_frame(
    gt: tuple[ObjectLabel, ...], dt: tuple[ObjectLabel, ...], devkit_offsets: bool
) -> _PreparedFrame:
    """One frame's objects and overlaps (read only afterwards: shared by every evaluation of
    the same labels)."""
    return _prepare(FrameObjects.from_labels(gt), FrameObjects.from_labels(dt), devkit_offsets)
