"""Ground a whole split and score it: the official VoD result plus the paper's breakdowns.

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

Thresholds: the model grounds each prompt once, decoding at ``min(decode, operating)``; the boxes
scoring at least the decode threshold (``score_threshold``, default
:func:`model.evaluation.predict.decode_threshold`, what ``ground`` returns by itself) make the prediction files and the mAP (unchanged by the operating
threshold), the boxes scoring at least the operating threshold make the answer set.

All AP values are the entire-area 3D mAP at 11 recall points unless a table says otherwise.
"""

from __future__ import annotations

import contextlib
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from model.core.labelled import LabelledBoxes
from model.evaluation.baselines import class_noun_prompt, named_class, oracle_boxes, unsensed_ids
from model.evaluation.grounding import (
    CandidateSource,
    GroundingMetrics,
    PromptBoxes,
    PromptOutcome,
    format_grounding_tables,
    grounding_metrics,
    prompt_outcome,
)
from model.evaluation.metrics import VodResult, evaluate_frames
from model.evaluation.outside_classes import OutsideClasses
from model.evaluation.predict import (
    PredictSettings,
    decode_threshold,
    operating_threshold,
    prediction_labels,
)
from model.evaluation.predict_pool import predictions
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
from model.evaluation.worker_watch import DEFAULT_LIVENESS, Liveness
from model.protocol import model_classes
from scenes.geometry.actors import Actor
from scenes.geometry.classes import VOD, ClassSet
from scenes.language.prompts import infer_tags
from scenes.talk2radar.kitti import (
    ObjectLabel,
    format_label_line,
    outside_class_counts,
    parse_label_line,
)
from scenes.talk2radar.root import Sample, Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels

if TYPE_CHECKING:
    from model.tpcnet import TPCNet

PROMPT_TYPES: tuple[str, ...] = ("depth", "velocity", "motion", "position")
DEPTH_BINS: tuple[tuple[float, float], ...] = tuple((10.0 * i, 10.0 * (i + 1)) for i in range(6))


ROW_NAMES: dict[str, str] = {"model": "model", "class_noun": "class noun", "oracle": "oracle"}
"""Row labels of the printed grounding tables."""


@dataclass
class AnswerSet:
    """What one answerer (the model or a baseline) gave on a split, prompt after prompt.

    Attributes:
        outcomes: Its outcome per prompt (:func:`model.evaluation.grounding.prompt_outcome`).
        labels: Frame id -> its answer as prediction labels (baselines: what their files would
            hold, scored with the official metric).
    """

    outcomes: list[PromptOutcome] = field(default_factory=list)
    labels: dict[str, list[ObjectLabel]] = field(default_factory=dict)


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


def _as_written(labels: Sequence[ObjectLabel]) -> list[ObjectLabel]:
    """Labels rounded as a prediction file holds them (4 decimals), so that baselines are scored
    on the same footing as the model's files."""
    return [parse_label_line(format_label_line(lab, decimals=4)) for lab in labels]


def _labels(boxes: PromptBoxes, min_score: float, sample: Sample) -> list[ObjectLabel]:
    kept = boxes.above(min_score)
    return _as_written(prediction_labels(kept.boxes, kept.classes, kept.scores, sample.calib))


def sample_tags(sample: Sample) -> frozenset[str]:
    """The sidecar's prompt type tags, else :func:`scenes.language.prompts.infer_tags` of the prompt."""
    meta = sample.meta
    if meta is not None and meta.tags:
        return frozenset(meta.tags)
    return infer_tags(sample.prompt or "")


def class_noun_of(sample: Sample) -> tuple[str]:
    """The class-noun baseline's prompt for a sample (:func:`model.evaluation.baselines.
    class_noun_prompt` of the class its prompt names): the extra prompt grounded on its scene."""
    return (class_noun_prompt(named_class(sample_tags(sample), sample.classes)),)


@dataclass(frozen=True)
class SceneLabelCandidates:
    """The candidates of ``--candidates labels``: a frame's labelled boxes from the scene labels
    (a picklable callable, for prediction workers)."""

    scene_labels: SceneLabels

    def __call__(self, sample: Sample) -> LabelledBoxes:
        objects = self.scene_labels.load(sample.sample_id)
        return LabelledBoxes(*objects.metric(), objects.classes)


def evaluate_predictions(
    model: TPCNet,
    root: Talk2RadarRoot,
    ids: Sequence[str],
    progress: bool = True,
    score_threshold: float | None = None,
    operating: float | None = None,
    baselines: bool = False,
    scene_labels: SceneLabels | None = None,
    candidates: CandidateSource = "detector",
    workers: int = 1,
    liveness: Liveness = DEFAULT_LIVENESS,
) -> GroundingReport:
    """Ground every sample of ``ids`` and score the answers.

    Args:
        score_threshold: Decode threshold of the prediction files and the mAP (None:
            :func:`model.evaluation.predict.decode_threshold`).
        operating: Operating threshold of the set metrics (None:
            :func:`model.evaluation.predict.operating_threshold`).
        baselines: Also score the class-noun prompt and the language-blind oracle (the oracle
            needs every frame's objects: the scene labels where given, else the sidecar; without
            either it is left out with a note).
        scene_labels: The View-of-Delft root with every frame's full labels. Where given, nothing
            under the root's ``meta/`` is read.
        candidates: ``"detector"`` (the detector's proposals) or ``"labels"`` (the frame's
            labelled boxes of the three classes: grounding apart from detection; needs
            ``scene_labels``).
        workers: Processes that predict (:func:`model.evaluation.predict_pool.predictions`;
            1: this process, the model as given; more: CPU only, the same predictions).
        liveness: How long workers may go without a result
            (:class:`model.evaluation.worker_watch.Liveness`).
    """
    if not ids:
        raise ValueError(f"{root.path}: no samples to evaluate")
    decode = decode_threshold(model) if score_threshold is None else float(score_threshold)
    op = operating_threshold(model) if operating is None else float(operating)
    if not 0.0 <= op < 1.0:
        raise ValueError(f"operating threshold must be in [0, 1), got {op}")
    ground_at = min(decode, op)
    if candidates not in typing.get_args(CandidateSource):
        raise ValueError(f"candidates must be detector or labels, got {candidates!r}")
    if candidates == "labels" and scene_labels is None:
        raise ValueError(
            "candidates 'labels' need the frames' full labels (--scene-labels VOD_ROOT): a "
            "Talk2Radar label_2 lists only the referents"
        )
    classes = model_classes(model)
    if root.classes != classes or (scene_labels is not None and scene_labels.classes != classes):
        raise ValueError(
            f"{root.path}: labels read into the {root.classes.name!r} class set given to a "
            f"model of the {classes.name!r} class set (open the root with the model's)"
        )
    if scene_labels is not None and root.sidecar:
        root = Talk2RadarRoot(root.path, radar=root.radar_folder, sidecar=False, classes=classes)

    gt: dict[str, list[ObjectLabel]] = {}
    dt: dict[str, list[ObjectLabel]] = {}
    tags: dict[str, frozenset[str]] = {}
    seconds = []
    answers = AnswerSet()
    base: dict[BaselineName, AnswerSet] = {name: AnswerSet() for name in BASELINES}
    no_meta: list[str] = []
    outside: dict[str, dict[str, int]] = {}  # sample id -> its referents outside the set
    apart: list[str] = []  # prompts whose referents all lie outside the set: not scored
    settings = PredictSettings(
        score_threshold=ground_at,
        min_label_score=decode,
        candidates=None
        if scene_labels is None or candidates != "labels"
        else SceneLabelCandidates(scene_labels),
        extra_prompts=class_noun_of if baselines else None,
    )
    stream = predictions(
        model, root, ids, settings, workers=workers, progress=progress, liveness=liveness
    )
    with contextlib.closing(stream):  # an error or Ctrl-C here stops the workers at once
        for pred in stream:
            sample = pred.sample
            sid = sample.sample_id
            gt[sid] = list(sample.labels)
            dt[sid] = _as_written(pred.labels)  # as the files will hold them (rescored at no cost)
            tags[sid] = sample_tags(sample)
            seconds.append(pred.seconds)
            where = f"{root.path}: sample {sid}"
            referents = PromptBoxes.make(sample.boxes, sample.classes, source=f"{where} label_2")
            answer = PromptBoxes.make(
                pred.boxes, pred.classes, pred.scores, source=f"{where} model"
            )
            beyond = outside_class_counts(sample.labels, classes)
            if beyond:
                outside[sid] = beyond
            scored = not beyond or len(referents) > 0  # else: reported apart, never scored
            if not scored:
                apart.append(sid)
            missed = sum(beyond.values())
            if scored:
                answers.outcomes.append(
                    prompt_outcome(sid, tags[sid], answer, referents, op, missed)
                )
            if not baselines:
                continue
            cls = named_class(tags[sid], sample.classes)
            noun_boxes = pred.extra[class_noun_prompt(cls)]
            base["class_noun"].labels[sid] = _labels(noun_boxes, decode, sample)
            if scored:
                base["class_noun"].outcomes.append(
                    prompt_outcome(sid, tags[sid], noun_boxes, referents, op, missed)
                )
            if scene_labels is not None:
                boxes, labels = scene_labels.load(sid).metric()
                objects = [
                    Actor(i, classes.names[int(lab)], box, np.zeros(2))
                    for i, (box, lab) in enumerate(zip(boxes, labels, strict=True))
                ]
                oracle = oracle_boxes(objects, cls)
            elif sample.meta is None:
                no_meta.append(sid)
                continue
            else:
                skip = unsensed_ids(sample.meta, source=f"{root.path / 'meta' / sid}.json")
                oracle = oracle_boxes(sample.meta.actors, cls, exclude=skip)
            base["oracle"].labels[sid] = _labels(oracle, decode, sample)
            if scored:
                base["oracle"].outcomes.append(
                    prompt_outcome(sid, tags[sid], oracle, referents, op, missed)
                )
    report = build_report(gt, dt, tags, tuple(seconds), classes)
    found: dict[BaselineName, BaselineResult] = {}
    notes: dict[BaselineName, str] = {}
    if baselines:
        if no_meta:
            notes["oracle"] = (
                f"{len(no_meta)} sample(s) have no meta sidecar listing the frame's actors "
                f"(e.g. {root.path / 'meta' / (no_meta[0] + '.json')})"
            )
        for name in BASELINES:
            if name not in notes:
                found[name] = BaselineResult(
                    result=evaluate_frames(gt, base[name].labels, classes=classes),
                    grounding=grounding_metrics(base[name].outcomes, op),
                )
    return replace(
        report,
        grounding=grounding_metrics(answers.outcomes, op),
        baselines=found,
        notes=notes,
        outside=OutsideClasses.of(classes.name, outside, tuple(apart)),
    )


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
