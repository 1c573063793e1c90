"""Matching of the VoD protocol (:mod:`model.evaluation.protocol`): score thresholds, per-frame
counts at each threshold, precision / recall / orientation curves and their APs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from model.evaluation.overlaps import frame_overlaps, image_intersection_over_first
from model.evaluation.protocol import (
    DEVKIT_OFFSET,
    DONT_CARE,
    NUM_SAMPLE_POINTS,
    FrameObjects,
    Metric,
)


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
class PreparedFrame:
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


def prepare_frame(gt: FrameObjects, dt: FrameObjects, devkit_offsets: bool) -> PreparedFrame:
    shifted = _with_devkit_offsets(dt) if devkit_offsets else dt
    overlaps = {m: frame_overlaps(shifted, gt, m) for m in Metric}
    dc = gt.bbox[np.array([str(n) == DONT_CARE for n in gt.names], dtype=bool)]
    if len(dt) and len(dc):
        dont_care = image_intersection_over_first(dt.bbox, dc)
    else:
        dont_care = np.zeros((len(dt), 0))
    return PreparedFrame(gt=gt, dt=dt, overlaps=overlaps, dont_care=dont_care)


def class_curve(
    frames: Sequence[PreparedFrame],
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
