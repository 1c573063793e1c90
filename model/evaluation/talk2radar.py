"""The Talk2Radar kind of ``python -m model.evaluate --data ROOT`` (:mod:`model.evaluation.pipeline`'s
stages): a split's samples grounded (:mod:`model.evaluation.predict`, several processes:
:mod:`model.evaluation.predict_pool`) and scored as they come into
:class:`model.evaluation.report.GroundingReport`'s figures (the VoD metric, the grounding metrics,
the baselines), the KITTI prediction folder written and scored again as read back.

Thresholds: the model grounds each prompt once, decoding at ``min(decode, operating)``; the boxes
scoring at least the decode threshold (``score_threshold``, default
:func:`model.evaluation.predict.decode_threshold`, what ``ground`` returns by itself) make the
prediction files and the mAP (unchanged by the operating threshold), the boxes scoring at least
the operating threshold make the answer set.

This kind is the Talk2Radar family's, so it reads that family's own formats directly: a
Talk2Radar root's radar tree and sidecar choices (:class:`scenes.talk2radar.root.Talk2RadarRoot`)
and a View-of-Delft root's full scene labels (:class:`scenes.talk2radar.scene_labels.SceneLabels`,
``--scene-labels``), which no other family has.
"""

from __future__ import annotations

import contextlib
import typing
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from model.core.labelled import LabelledBoxes
from model.evaluation.baselines import class_noun_prompt, named_class, oracle_boxes, unsensed_ids
from model.evaluation.files import EvaluationInputError, load_prediction_dir
from model.evaluation.grounding import (
    CandidateSource,
    PromptBoxes,
    PromptOutcome,
    grounding_metrics,
    prompt_outcome,
)
from model.evaluation.metrics import evaluate_frames
from model.evaluation.outside_classes import OutsideClasses
from model.evaluation.predict import (
    FramePrediction,
    PredictSettings,
    decode_threshold,
    operating_threshold,
    prediction_labels,
    write_predictions,
)
from model.evaluation.predict_pool import predictions
from model.evaluation.report import BaselineResult, GroundingReport, build_report
from model.evaluation.report_file import BASELINES, BaselineName
from model.evaluation.worker_watch import DEFAULT_LIVENESS, Liveness
from model.protocol import model_classes
from scenes.frame import Sample
from scenes.frame.kitti import (
    ObjectLabel,
    format_label_line,
    outside_class_counts,
    parse_label_line,
)
from scenes.geometry.actors import Actor
from scenes.geometry.classes import ClassSet
from scenes.language.prompts import infer_tags
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels

if TYPE_CHECKING:
    from model.tpcnet import TPCNet


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


@dataclass(frozen=True)
class SplitScoring:
    """What scoring a split's predictions needs beside them, checked (:meth:`of`): the root (read
    without its sidecars where scene labels are given), the class set, the two thresholds, the
    baselines and how each sample is predicted."""

    root: Talk2RadarRoot
    classes: ClassSet
    decode: float
    operating: float
    baselines: bool
    scene_labels: SceneLabels | None
    settings: PredictSettings

    @classmethod
    def of(
        cls,
        model: TPCNet,
        root: Talk2RadarRoot,
        ids: Sequence[str],
        score_threshold: float | None = None,
        operating: float | None = None,
        baselines: bool = False,
        scene_labels: SceneLabels | None = None,
        candidates: CandidateSource = "detector",
    ) -> SplitScoring:
        """The scoring of ``ids`` (the arguments as :func:`evaluate_predictions`'s)."""
        if not ids:
            raise ValueError(f"{root.path}: no samples to evaluate")
        decode = decode_threshold(model) if score_threshold is None else float(score_threshold)
        op = operating_threshold(model) if operating is None else float(operating)
        if not 0.0 <= op < 1.0:
            raise ValueError(f"operating threshold must be in [0, 1), got {op}")
        if candidates not in typing.get_args(CandidateSource):
            raise ValueError(f"candidates must be detector or labels, got {candidates!r}")
        if candidates == "labels" and scene_labels is None:
            raise ValueError(
                "candidates 'labels' need the frames' full labels (--scene-labels VOD_ROOT): a "
                "Talk2Radar label_2 lists only the referents"
            )
        classes = model_classes(model)
        if root.classes != classes or (
            scene_labels is not None and scene_labels.classes != classes
        ):
            raise ValueError(
                f"{root.path}: labels read into the {root.classes.name!r} class set given to a "
                f"model of the {classes.name!r} class set (open the root with the model's)"
            )
        if scene_labels is not None and root.sidecar:
            root = Talk2RadarRoot(
                root.path, radar=root.radar_folder, sidecar=False, classes=classes
            )
        settings = PredictSettings(
            score_threshold=min(decode, op),
            min_label_score=decode,
            candidates=None
            if scene_labels is None or candidates != "labels"
            else SceneLabelCandidates(scene_labels),
            extra_prompts=class_noun_of if baselines else None,
        )
        return cls(root, classes, decode, op, baselines, scene_labels, settings)


def predict_split(
    model: TPCNet,
    scoring: SplitScoring,
    ids: Sequence[str],
    workers: int = 1,
    progress: bool = True,
    liveness: Liveness = DEFAULT_LIVENESS,
) -> Iterator[FramePrediction]:
    """The predictions of ``ids`` in sample order
    (:func:`model.evaluation.predict_pool.predictions`; ``workers`` 1: this process)."""
    return predictions(
        model,
        scoring.root,
        ids,
        scoring.settings,
        workers=workers,
        progress=progress,
        liveness=liveness,
    )


def score_split(scoring: SplitScoring, stream: Iterator[FramePrediction]) -> GroundingReport:
    """Score the predictions as they come (the stream closed at the end or on an error: its
    workers stop at once)."""
    root, classes, decode, op = scoring.root, scoring.classes, scoring.decode, scoring.operating
    baselines, scene_labels = scoring.baselines, scoring.scene_labels
    gt: dict[str, list[ObjectLabel]] = {}
    dt: dict[str, list[ObjectLabel]] = {}
    tags: dict[str, frozenset[str]] = {}
    seconds = []
    answers = AnswerSet()
    base: dict[BaselineName, AnswerSet] = {name: AnswerSet() for name in BASELINES}
    no_meta: list[str] = []
    outside: dict[str, dict[str, int]] = {}  # sample id -> its referents outside the set
    apart: list[str] = []  # prompts whose referents all lie outside the set: not scored
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
    scoring = SplitScoring.of(
        model, root, ids, score_threshold, operating, baselines, scene_labels, candidates
    )
    return score_split(scoring, predict_split(model, scoring, ids, workers, progress, liveness))


@dataclass(frozen=True)
class Talk2RadarRun:
    """What :meth:`Talk2RadarEvaluation.prepare` opened: the model, the split's samples and how
    they are scored and predicted."""

    model: TPCNet
    ids: Sequence[str]
    scoring: SplitScoring
    workers: int
    liveness: Liveness


@dataclass(frozen=True, kw_only=True)
class Talk2RadarEvaluation:
    """``python -m model.evaluate --data ROOT`` on a Talk2Radar root: a kind of
    :mod:`model.evaluation.pipeline` (the fields: the command line's settings of model mode)."""

    data: Path
    split: str
    checkpoint: Path
    out: Path
    json: Path | None
    threshold: float | None = None
    baselines: bool = True
    radar_folder: str = "auto"
    scene_labels: Path | None = None
    candidates: CandidateSource = "detector"
    device: str = "cpu"
    workers: int = 0
    worker_timeout: float = 20.0
    limit: int = 0

    def prepare(self) -> Talk2RadarRun:
        """Check the settings, open the root and its split, load the checkpoint.

        Raises:
            EvaluationInputError: a setting out of range, ``--candidates labels`` without scene
                labels or for a paper-path checkpoint, an empty split; the root's and the
                checkpoint's errors.
        """
        from model.checkpoint import load_checkpoint
        from model.evaluation.predict_pool import auto_workers, frame_groups

        if self.threshold is not None and not 0.0 <= self.threshold < 1.0:
            raise EvaluationInputError(f"--threshold must be in [0, 1), got {self.threshold}")
        if self.workers < 0:
            raise EvaluationInputError(
                f"--workers must be 0 (automatic) or more, got {self.workers}"
            )
        if self.workers > 1 and self.device != "cpu":
            raise EvaluationInputError(
                f"--workers {self.workers} runs on the CPU, not {self.device}"
            )
        if not self.worker_timeout > 0:
            raise EvaluationInputError(f"--worker-timeout must be > 0 s, got {self.worker_timeout}")
        radar = None if self.radar_folder == "none" else self.radar_folder
        if self.candidates == "labels" and self.scene_labels is None:
            raise EvaluationInputError(
                "--candidates labels needs --scene-labels VOD_ROOT (a Talk2Radar label_2 lists "
                "only the referents, which would give the answer away)"
            )
        scene_labels = None if self.scene_labels is None else SceneLabels(self.scene_labels)
        root = Talk2RadarRoot(self.data, radar=radar, sidecar=scene_labels is None)
        ids = root.ids(self.split)
        if self.limit:
            ids = ids[: self.limit]
        if not ids:
            raise EvaluationInputError(f"{self.data}: split {self.split!r} has no samples")
        model = load_checkpoint(self.checkpoint, device=self.device)
        classes = model.cfg.class_set  # the checkpoint's: the labels are read into its classes
        if classes != root.classes:
            root = Talk2RadarRoot(self.data, radar=radar, sidecar=root.sidecar, classes=classes)
            if scene_labels is not None:
                scene_labels = SceneLabels(self.scene_labels, classes)
        operating = operating_threshold(model) if self.threshold is None else self.threshold
        if self.candidates == "labels" and not model.takes_labelled_candidates:
            raise EvaluationInputError(
                f"{self.checkpoint}: --candidates labels needs a referent-path checkpoint"
            )
        workers = self.workers or auto_workers(len(frame_groups(root, ids)), self.device)
        scoring = SplitScoring.of(
            model,
            root,
            ids,
            operating=operating,
            baselines=self.baselines,
            scene_labels=scene_labels,
            candidates=self.candidates,
        )
        return Talk2RadarRun(model, ids, scoring, workers, Liveness.with_floor(self.worker_timeout))

    def predict(self, run: Talk2RadarRun) -> Iterator[FramePrediction]:
        """Every sample's prediction, in sample order (:func:`predict_split`)."""
        return predict_split(run.model, run.scoring, run.ids, run.workers, True, run.liveness)

    def score(self, run: Talk2RadarRun, stream: Iterator[FramePrediction]) -> GroundingReport:
        """:func:`score_split`."""
        return score_split(run.scoring, stream)

    def write(self, run: Talk2RadarRun, report: GroundingReport) -> tuple[GroundingReport, Path]:
        """One prediction file per frame into ``out``; the report scored again on the files as
        written (4 decimals), as the official devkit reads them."""
        out = write_predictions(report.predictions, self.out)
        from_files, missing = load_prediction_dir(out, tuple(sorted(run.ids)))
        if missing:
            raise EvaluationInputError(f"{out}: prediction files missing for {list(missing)[:5]}")
        return report.rescored(from_files), out

    def heading(self, run: Talk2RadarRun, report: GroundingReport, written: Path) -> list[str]:
        """The lines printed before the tables: what was grounded, where the files went."""
        source = "--threshold" if self.threshold is not None else "checkpoint"
        return [
            f"data: {self.data} split {self.split} ({len(run.ids)} frames); checkpoint "
            f"{self.checkpoint}; candidates: {self.candidates}; {run.workers} prediction "
            "process(es)"
            + ("" if self.scene_labels is None else f"; scene labels {self.scene_labels}"),
            f"predictions written to {written}; operating threshold "
            f"{run.scoring.operating:g} ({source})",
        ]

    def closing(self, run: Talk2RadarRun, report: GroundingReport, written: Path) -> list[str]:
        """Nothing after the tables."""
        return []
