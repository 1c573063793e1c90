"""The official View-of-Delft (VoD) evaluation, re-implemented in pure NumPy: the protocol
(its constants, the objects of a frame and their states); :mod:`model.evaluation.overlaps`
computes the overlaps, :mod:`model.evaluation.matching` the matches and curves,
:mod:`model.evaluation.results` holds the results and :mod:`model.evaluation.metrics` is the entry
point (:func:`~model.evaluation.metrics.evaluate_frames`).

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
  (:mod:`scenes.geometry.boxes`), so identical boxes have IoU 1, which the devkit gets wrong.
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
from dataclasses import dataclass

import numpy as np

from scenes.frame.kitti import ObjectLabel
from scenes.geometry.classes import PRESETS, VOD, ClassSet

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


def unknown_class_counts(
    frames: Mapping[str, Sequence[ObjectLabel]], classes: ClassSet = VOD
) -> dict[str, int]:
    """Class names of ``frames`` (frame id -> labels) that map onto no class of ``classes``
    (:meth:`scenes.geometry.classes.ClassSet.label_class`) and are not
    :data:`KNOWN_OTHER_CLASSES` (case-insensitive), with their number of objects, by name."""
    counts: dict[str, int] = {}
    for labels in frames.values():
        for lab in labels:
            low = lab.name.lower()
            if classes.label_class(lab.name) is None and low not in KNOWN_OTHER_CLASSES:
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
    c.name: MinOverlaps(*c.min_overlaps) for s in PRESETS.values() for c in s.classes
}
"""The devkit's reported (second) overlap table (Car 0.7 / 0.5 / 0.5, Pedestrian and Cyclist
0.5 / 0.25 / 0.25), by class name over every class set: each class's
:attr:`scenes.geometry.classes.ObjectClass.min_overlaps` (the other classes are scored like the
VoD class they resemble: large vehicles as Car, two-wheelers as Cyclist, cones and barriers as
Pedestrian)."""

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


def _in_corridor(boxes: np.ndarray) -> np.ndarray:
    x, z = boxes[:, 0], boxes[:, 2]
    return (x >= -CORRIDOR_HALF_WIDTH) & (x <= CORRIDOR_HALF_WIDTH) & (z <= CORRIDOR_MAX_DEPTH)


def _lower(names: np.ndarray) -> np.ndarray:
    return np.array([str(n).lower() for n in names], dtype=object)


def _of_class(names: Sequence[str], cls: str, classes: ClassSet) -> np.ndarray:
    """``(N,)`` bool: the label names that map onto class ``cls`` of ``classes`` (for ``vod``
    the class name itself, case-insensitive, as the devkit compares)."""
    return np.array([classes.label_class(str(n)) == cls for n in names], dtype=bool)


def gt_states(gt: FrameObjects, cls: str, corridor: bool, classes: ClassSet = VOD) -> np.ndarray:
    """Ground-truth states ``(G,)`` int: 0 counts, 1 ignored, -1 another class (``cls`` a class
    of ``classes``; KITTI's neighbour class, :attr:`scenes.geometry.classes.ObjectClass.
    neighbour`, a van for a car, is ignored rather than missed)."""
    if len(gt) == 0:
        return np.zeros(0, dtype=np.int64)
    names = _lower(gt.names)
    valid = _of_class(gt.names, cls, classes)
    neighbour = names == (classes.get(cls).neighbour or "\0")
    height = gt.bbox[:, 3] - gt.bbox[:, 1]
    ignore = (gt.occluded > MAX_OCCLUSION) | (height <= MIN_HEIGHT_PX)
    if corridor:
        ignore |= ~_in_corridor(gt.boxes)
    states = np.full(len(gt), -1, dtype=np.int64)
    states[neighbour | (valid & ignore)] = 1
    states[valid & ~ignore] = 0
    return states


def dt_states(dt: FrameObjects, cls: str, corridor: bool, classes: ClassSet = VOD) -> np.ndarray:
    """Detection states ``(D,)`` int: 0 counts, 1 ignored (too small or outside the corridor,
    whatever the class), -1 another class."""
    if len(dt) == 0:
        return np.zeros(0, dtype=np.int64)
    ignored = np.abs(dt.bbox[:, 3] - dt.bbox[:, 1]) < MIN_HEIGHT_PX
    if corridor:
        ignored |= ~_in_corridor(dt.boxes)
    states = np.where(_of_class(dt.names, cls, classes), 0, -1).astype(np.int64)
    states[ignored] = 1
    return states
