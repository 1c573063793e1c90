"""The figures of a Talk2Radar split (:class:`GroundingReport`): the official VoD result plus the
paper's breakdowns, the grounding metrics and the baselines beside them; the split is grounded and
scored by :mod:`model.evaluation.talk2radar`.

- Overall: :func:`model.evaluation.metrics.evaluate_frames` over every frame of the split.
- Per prompt type (the paper's table III): frames grouped by their prompt's type tags (``depth``,
  ``velocity``, ``motion``, ``position``); a prompt with several tags counts in each. Tags come from
  the sample's sidecar where present, else from :func:`scenes.language.prompts.infer_tags` on the text (so
  real Talk2Radar prompts are grouped by the same keyword rules).
- Per depth bin (table IV): "we partition the predicted objects into six depth intervals, each
  spanning 10 meters". An object's depth is its camera-frame forward distance (the label's
  ``location.z``); ground truth and detections are both restricted to the bin, then scored.

- Grounding per prompt (:mod:`model.evaluation.grounding`): top-box Acc@0.25 / Acc@0.5 and the set
  metrics at the operating threshold (:func:`model.evaluation.predict.operating_threshold`), overall, per
  prompt type and per group; with ``baselines=True`` also for the language-blind oracle and the
  class-noun prompt (:mod:`model.evaluation.baselines`), each with its official mAP. They judge the boxes as
  ``ground`` returns them (LiDAR frame, before the prediction files' image / range filter), against
  the referents of ``label_2``. Referents of classes outside the model's set are counted and named
  (:mod:`model.evaluation.outside_classes`: a prompt with only such referents is reported apart,
  one with some keeps them as referents the model cannot answer).

Thresholds: :mod:`model.evaluation.talk2radar`.

All AP values are the entire-area 3D mAP at 11 recall points unless a table says otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from model.evaluation.grounding import GroundingMetrics, format_grounding_tables
from model.evaluation.metrics import VodResult, evaluate_frames
from model.evaluation.outside_classes import OutsideClasses
from model.evaluation.report_file import (
    BASELINES,
    BASELINES_KEY,
    BY_DEPTH,
    BY_TYPE,
    FRAMES,
    GROUNDING,
    GT_OBJECTS,
    NOTES,
    NUM_FRAMES,
    OUTSIDE,
    SECONDS,
    BaselineName,
)
from scenes.frame.kitti import ObjectLabel
from scenes.geometry.classes import VOD, ClassSet

PROMPT_TYPES: tuple[str, ...] = ("depth", "velocity", "motion", "position")
DEPTH_BINS: tuple[tuple[float, float], ...] = tuple((10.0 * i, 10.0 * (i + 1)) for i in range(6))


ROW_NAMES: dict[str, str] = {"model": "model", "class_noun": "class noun", "oracle": "oracle"}
"""Row labels of the printed grounding tables."""


@dataclass(frozen=True)
class BaselineResult:
    """A baseline scored like the model.

    Attributes:
        result: Official VoD result of its answers (as the prediction files would hold them).
        grounding: Its grounding metrics at the model's operating threshold.
    """

    result: VodResult
    grounding: GroundingMetrics

    def to_dict(self) -> dict:
        return {**self.result.to_dict(), GROUNDING: self.grounding.to_dict()}


@dataclass(frozen=True)
class GroundingReport:
    """The evaluation of a model on a split.

    Attributes:
        result: Official VoD result over all frames.
        by_type: Prompt type -> (number of frames, result on those frames).
        by_depth: ``"0-10"`` ... ``"50-60"`` -> (number of GT objects, result in that bin).
        predictions: Frame id -> prediction labels (what the files hold).
        ground_truth: Frame id -> ground-truth labels.
        seconds: Per-frame ``encode_scene + ground`` wall time (a shared scene's encoding time
            counts in each of its frames).
        grounding: The model's grounding metrics (None when not computed).
        baselines: Name of :data:`BASELINES` -> its result (only those computed).
        notes: Baseline name -> why it was not computed.
        outside: The referents outside the model's class set and the prompts reported apart
            (:mod:`model.evaluation.outside_classes`).
    """

    result: VodResult
    by_type: Mapping[str, tuple[int, VodResult]]
    by_depth: Mapping[str, tuple[int, VodResult]]
    predictions: Mapping[str, list[ObjectLabel]] = field(repr=False)
    ground_truth: Mapping[str, list[ObjectLabel]] = field(repr=False)
    tags: Mapping[str, frozenset[str]] = field(repr=False, default_factory=dict)
    seconds: tuple[float, ...] = field(repr=False, default=())
    grounding: GroundingMetrics | None = None
    baselines: Mapping[BaselineName, BaselineResult] = field(default_factory=dict)
    notes: Mapping[BaselineName, str] = field(default_factory=dict)
    classes: ClassSet = VOD
    outside: OutsideClasses = field(default_factory=OutsideClasses)

    def rescored(self, predictions: Mapping[str, list[ObjectLabel]]) -> GroundingReport:
        """The same report with other predictions for the same frames (e.g. read back from the
        written files, as the official devkit would read them); grounding and baselines kept."""
        fresh = build_report(self.ground_truth, predictions, self.tags, self.seconds, self.classes)
        return replace(
            fresh,
            grounding=self.grounding,
            baselines=self.baselines,
            notes=self.notes,
            outside=self.outside,
        )

    def to_dict(self) -> dict:
        """JSON-ready: the official dict plus ``by_prompt_type``, ``by_depth`` and timing; with
        grounding metrics, ``grounding`` (:meth:`GroundingMetrics.to_dict`), ``baselines`` (name ->
        official dict + ``grounding``), ``baseline_notes`` and ``outside_class_set``
        (:meth:`OutsideClasses.to_dict`)."""
        out = {
            **self.result.to_dict(),
            NUM_FRAMES: self.result.num_frames,
            BY_TYPE: {k: {FRAMES: n, **r.to_dict()} for k, (n, r) in self.by_type.items()},
            BY_DEPTH: {k: {GT_OBJECTS: n, **r.to_dict()} for k, (n, r) in self.by_depth.items()},
            SECONDS: float(np.median(self.seconds)) if self.seconds else None,
        }
        if self.grounding is not None:
            out[GROUNDING] = self.grounding.to_dict()
            out[BASELINES_KEY] = {k: v.to_dict() for k, v in self.baselines.items()}
            out[NOTES] = dict(self.notes)
            out[OUTSIDE] = self.outside.to_dict()
        return out

    def grounding_rows(self) -> dict[str, tuple[GroundingMetrics, float | None]]:
        """Row label -> (grounding metrics, entire-area 3D mAP): the model, then the baselines."""
        if self.grounding is None:
            return {}
        rows = {ROW_NAMES["model"]: (self.grounding, self.result.entire_area.map_3d)}
        for name in BASELINES:
            if name in self.baselines:
                b = self.baselines[name]
                rows[ROW_NAMES[name]] = (b.grounding, b.result.entire_area.map_3d)
        return rows

    def format_tables(self) -> str:
        """The official table, mAP by prompt type and by depth bin (3D, entire area, R11), then the
        grounding tables (model and baselines side by side), the baselines' notes and the line of
        the referents outside the model's class set (:meth:`OutsideClasses.note`)."""
        lines = [self.result.format_table()]
        lines.append("mAP by prompt type (3D, entire area, 11-point / 40-point)")
        for name, (n, res) in self.by_type.items():
            area = res.entire_area
            lines.append(f"  {name:<10}{n:>6} frames  {area.map_3d:6.2f} / {area.map_3d_r40:6.2f}")
        lines.append("mAP by depth (3D, entire area, 11-point / 40-point)")
        for name, (n, res) in self.by_depth.items():
            area = res.entire_area
            lines.append(f"  {name:<10}{n:>6} objects {area.map_3d:6.2f} / {area.map_3d_r40:6.2f}")
        rows = self.grounding_rows()
        if rows:
            lines.append(format_grounding_tables(rows).rstrip("\n"))
        for name, why in self.notes.items():
            lines.append(f"{ROW_NAMES.get(name, name)} baseline not computed: {why}")
        note = self.outside.note()
        if note is not None:
            lines.append(note)
        return "\n".join(lines) + "\n"


def _depth(label: ObjectLabel) -> float:
    return float(label.location[2])


def breakdown_by_type(
    gt: Mapping[str, list[ObjectLabel]],
    dt: Mapping[str, list[ObjectLabel]],
    tags: Mapping[str, frozenset[str]],
    classes: ClassSet = VOD,
) -> dict[str, tuple[int, VodResult]]:
    """Score the frames of each prompt type separately (types with no frame are left out)."""
    out = {}
    for kind in PROMPT_TYPES:
        frames = [f for f in gt if kind in tags.get(f, frozenset())]
        if frames:
            out[kind] = (
                len(frames),
                evaluate_frames(
                    {f: gt[f] for f in frames},
                    {f: dt.get(f, []) for f in frames},
                    classes=classes,
                ),
            )
    return out


def breakdown_by_depth(
    gt: Mapping[str, list[ObjectLabel]],
    dt: Mapping[str, list[ObjectLabel]],
    bins: Sequence[tuple[float, float]] = DEPTH_BINS,
    classes: ClassSet = VOD,
) -> dict[str, tuple[int, VodResult]]:
    """Score ground truth and detections restricted to each depth bin ``[lo, hi)``."""
    out = {}
    for lo, hi in bins:
        gt_bin = {f: [g for g in labs if lo <= _depth(g) < hi] for f, labs in gt.items()}
        dt_bin = {f: [d for d in labs if lo <= _depth(d) < hi] for f, labs in dt.items()}
        count = sum(len(v) for v in gt_bin.values())
        out[f"{lo:g}-{hi:g}"] = (count, evaluate_frames(gt_bin, dt_bin, classes=classes))
    return out


def build_report(
    gt: Mapping[str, list[ObjectLabel]],
    dt: Mapping[str, list[ObjectLabel]],
    tags: Mapping[str, frozenset[str]],
    seconds: Sequence[float] = (),
    classes: ClassSet = VOD,
) -> GroundingReport:
    """Score ``dt`` against ``gt`` overall, per prompt type and per depth bin, one row per
    class of ``classes`` (the model's class set)."""
    return GroundingReport(
        result=evaluate_frames(gt, dt, classes=classes),
        by_type=breakdown_by_type(gt, dt, tags, classes),
        by_depth=breakdown_by_depth(gt, dt, classes=classes),
        predictions=dict(dt),
        ground_truth=dict(gt),
        tags=dict(tags),
        seconds=tuple(seconds),
        classes=classes,
    )
