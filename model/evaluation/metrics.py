"""The official View-of-Delft (VoD) evaluation, re-implemented in pure NumPy: the entry point.

:func:`evaluate_frames` scores detections against ground truth with the protocol of
:mod:`model.evaluation.protocol` (overlaps: :mod:`model.evaluation.overlaps`; matching and curves:
:mod:`model.evaluation.matching`; results and tables: :mod:`model.evaluation.results`), whose names
it re-exports. Evaluating a subset (one prompt type, one depth bin) is :func:`evaluate_frames` on a
filtered dict.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache

import numpy as np

from model.evaluation.matching import PreparedFrame, class_curve, prepare_frame, score_thresholds
from model.evaluation.overlaps import camera_bev_iou, camera_iou3d, image_iou
from model.evaluation.protocol import (
    AREAS,
    MIN_HEIGHT_PX,
    MIN_OVERLAPS,
    FrameObjects,
    Metric,
    dt_states,
    gt_states,
    unknown_class_counts,
)
from model.evaluation.results import APValue, AreaResult, ClassResult, VodResult
from scenes.frame.kitti import ObjectLabel
from scenes.geometry.classes import VOD, ClassSet


def evaluate_area(
    frames: Sequence[PreparedFrame], corridor: bool, classes: ClassSet = VOD
) -> AreaResult:
    """Evaluate prepared frames in one area (corridor or not): one row per class of
    ``classes``."""
    results = []
    for cls in classes.names:
        states = [
            (gt_states(f.gt, cls, corridor, classes), dt_states(f.dt, cls, corridor, classes))
            for f in frames
        ]
        # Frames where nothing of this class can count contribute nothing: skip them.
        keep = [i for i, (g, d) in enumerate(states) if np.any(g != -1) or np.any(d == 0)]
        sub_frames = [frames[i] for i in keep]
        sub_states = [states[i] for i in keep]
        mins = MIN_OVERLAPS[cls]
        curves = {m: class_curve(sub_frames, sub_states, m, mins.of(m)) for m in Metric}
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
    classes: ClassSet = VOD,
) -> VodResult:
    """Score detections against ground truth with the official VoD protocol.

    Args:
        gt: Frame id -> ground-truth labels. Its keys are the frames evaluated.
        dt: Frame id -> detections (labels with scores; a missing score counts as 0). A frame of
            ``gt`` missing here has no detections.
        devkit_offsets: Apply the devkit's offsets (detections' ``rotation_y`` + 0.01 rad and 2D
            boxes + 0.01 px, for the overlaps only), so that numbers match the devkit's. False:
            overlaps of the boxes exactly as written.
        classes: The class set scored, one row per class (its label names mapped onto it by
            :meth:`scenes.geometry.classes.ClassSet.label_class`); default ``vod``.

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
    return _evaluate_content(content, devkit_offsets, classes)


@lru_cache(maxsize=64)
def _evaluate_content(
    content: tuple[tuple[str, tuple[ObjectLabel, ...], tuple[ObjectLabel, ...]], ...],
    devkit_offsets: bool,
    classes: ClassSet = VOD,
) -> VodResult:
    """:func:`evaluate_frames` of ``(frame id, ground truth, detections)`` triples. Labels are
    frozen values and the result too, so an evaluation asked for again (a report rescored from
    the files it wrote) is not computed again, nor a frame prepared again (the per-prompt-type
    tables score subsets of the same frames)."""
    frames = [_prepared_frame(g, d, devkit_offsets) for _, g, d in content]
    gt = {f: g for f, g, _ in content}
    dt = {f: d for f, _, d in content if d}
    return VodResult(
        entire_area=evaluate_area(frames, corridor=False, classes=classes),
        roi=evaluate_area(frames, corridor=True, classes=classes),
        num_frames=len(frames),
        unknown_gt_classes=unknown_class_counts(gt, classes),
        unknown_dt_classes=unknown_class_counts(dt, classes),
    )


@lru_cache(maxsize=8192)
def _prepared_frame(
    gt: tuple[ObjectLabel, ...], dt: tuple[ObjectLabel, ...], devkit_offsets: bool
) -> PreparedFrame:
    """One frame's objects and overlaps (read only afterwards: shared by every evaluation of
    the same labels)."""
    return prepare_frame(FrameObjects.from_labels(gt), FrameObjects.from_labels(dt), devkit_offsets)


__all__ = [
    "AREAS",
    "MIN_HEIGHT_PX",
    "MIN_OVERLAPS",
    "VodResult",
    "camera_bev_iou",
    "camera_iou3d",
    "evaluate_area",
    "evaluate_frames",
    "image_iou",
    "score_thresholds",
]
