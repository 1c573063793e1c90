"""Class prompts on a fully labelled root: ``python -m model.class_prompts --data ROOT``.

For every frame the model is asked the class prompts of its class set
(:func:`model.evaluation.class_prompt_counts.class_prompts`: "the cyclists", "the pedestrians",
"the cars" for ``vod``; one per class, "the trucks", "the traffic cones", ..., for ``nuscenes``)
on one encoded scene (``encode_scene`` once, ``ground`` once per class). The boxes scoring
at least the operating threshold (:func:`model.evaluation.predict.operating_threshold`, or ``--threshold``)
are the answer. Per prompt:

- **targets**: the ground-truth objects of the prompt's class in the *counted region*: BEV distance
  of the box centre from the LiDAR origin ``<= max_range`` (``sqrt(x^2 + y^2)``, LiDAR frame) and,
  with ``fov="camera"`` (default), inside the camera image (:func:`in_camera_view`), because
  View-of-Delft annotates only the camera's field of view. Only the model's classes (Car,
  Pedestrian, Cyclist for ``vod``) are ever targets; the other labels (with ``vod``: VoD's
  ``bicycle``, ``rider``, ``moped_scooter``, ``truck``, ...) are not, so a box on a parked
  bicycle is a false box.
- **found**: targets matched one-to-one by an answer box of the prompt's class, greedily in
  descending score order, each box taking the free ground-truth box of that class with the largest
  3D IoU strictly above the official minimum overlap (:data:`model.evaluation.metrics.MIN_OVERLAPS`: 0.5 Car,
  0.25 Pedestrian / Cyclist). The looser **found (centre)** figure matches the same way by BEV
  centre distance within the class's ``find_radius`` (:mod:`scenes.geometry.classes`: 1 m; 2 m
  for cars), the nearest first.
- **false boxes**: answer boxes in the counted region that match no ground-truth box of the
  prompt's class (a box of another class, a duplicate, a box on nothing or on a non-metric object).

Ground-truth boxes of the class outside the counted region can be matched but are never counted,
and answer boxes outside it are never counted either: an object at 30.5 m found by a box at 29.9 m
is neither a target nor a false box. Recall = found / targets (percent); false boxes per prompt =
false boxes / frames. The issue-14 targets (:data:`TARGET_RECALL`, :data:`TARGET_FALSE_PER_PROMPT`)
are reported against the pooled figures of the three prompts.

The root is a View-of-Delft release root as it comes (``lidar/training/{velodyne,calib,label_2}``,
a ``radar`` / ``radar_3frames`` / ``radar_5frames`` tree, no ``prompt/`` folder), whose label_2
holds every annotated object. A Talk2Radar root (with ``prompt/``) is read too, one frame per
distinct set of sensor files, but its label_2 holds only each prompt's referents, so the figures
are not meaningful there; the command says so. Errors are one line, ``error: ...``, exit 2.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from model.checkpoint import DEFAULT_CHECKPOINT
from model.checkpoint_meta import CheckpointMeta
from model.evaluation.class_prompt_counts import (
    CLASS_PROMPTS,
    TARGET_FALSE_PER_PROMPT,
    TARGET_RECALL,
    ClassSummary,
    PromptCount,
    bev_range,
    class_prompts,
    count_prompt,
    other_label_boxes,
)
from model.evaluation.class_prompt_frames import distinct_scenes, image_size_of
from model.protocol import GroundingModel, model_classes
from scenes.datasets.family_files import LIDAR_FOLDER, RADAR_FOLDERS, labelled_frame_ids
from scenes.datasets.source import Talk2RadarRoot
from scenes.frame import RootError, Sample
from scenes.geometry.calib import IMAGE_SIZE
from scenes.geometry.projection import in_camera_view
from scenes.utils.cli import add_options, from_args, option, report_errors
from scenes.utils.durable import atomic_write_text

FOVS = ("camera", "all")
"""Counted region: inside the camera image too, or anywhere within the range."""

CANDIDATE_KINDS = ("detector", "labels")
"""What the referent stage chooses among: the detector's proposals, or the frame's labelled
(metric-class) boxes (grounding apart from detection, :mod:`model.core.labelled`)."""


@dataclass(frozen=True)
class ScoringConfig:
    """How answers are counted (also ``python -m model.class_prompts``' flags of these settings).

    Attributes:
        threshold: Operating threshold: answer boxes with ``score >= threshold`` count; None
            (the command without ``--threshold``): the checkpoint's, which the command sets
            before scoring (:func:`score_root` refuses None).
        max_range: Counted region radius (m), BEV distance of the box centre from the LiDAR.
        fov: ``camera`` (also inside the camera image) or ``all``.
        sweep: Further thresholds to count at (pooled figures only; the model is asked once, at
            the smallest threshold).
        candidates: :data:`CANDIDATE_KINDS`: ``labels`` grounds over the frame's labelled boxes
            (every found object is then a labelled box, every false box a labelled box of
            another class or one not asked for).
    """

    threshold: float | None = option(None, help="default: the checkpoint's")
    max_range: float = option(30.0, help="metres, BEV (default %(default)s)")
    fov: str = option("camera", choices=FOVS, help="count only the camera's view (default)")
    sweep: tuple[float, ...] = option(
        (),
        nargs="+",
        metavar="T",
        help="also count at these thresholds (pooled table; one model pass)",
    )
    candidates: str = option(
        "detector",
        choices=CANDIDATE_KINDS,
        help="detector: the detector's proposals (default); labels: the frame's labelled boxes",
    )

    def __post_init__(self) -> None:
        for flag, values in (("--threshold", [self.threshold]), ("--sweep", self.sweep)):
            for value in values:
                if value is not None and not 0.0 <= value < 1.0:
                    raise ValueError(f"{flag} must be in [0, 1), got {value}")
        if not self.max_range > 0.0:
            raise ValueError(f"--max-range must be positive, got {self.max_range}")
        if self.fov not in FOVS:
            raise ValueError(f"--fov must be one of {FOVS}, got {self.fov!r}")
        if self.candidates not in CANDIDATE_KINDS:
            raise ValueError(
                f"--candidates must be one of {CANDIDATE_KINDS}, got {self.candidates!r}"
            )

    def resolved(self) -> tuple[float, ...]:
        """The thresholds counted at: the operating one, then :attr:`sweep`."""
        if self.threshold is None:
            raise ValueError("no operating threshold: give --threshold or a calibrated checkpoint")
        return (self.threshold, *self.sweep)


@dataclass(frozen=True, kw_only=True)
class ClassPromptsCommand:
    """The flags of ``python -m model.class_prompts`` beside :class:`ScoringConfig`'s.

    Attributes:
        data: The root (``lidar/`` and a radar tree), best a View-of-Delft root with full labels.
        checkpoint: The model.
        split: ``all`` (every frame with a ``label_2`` file) or an ImageSets list name.
        radar_folder: The radar tree (``auto``: the root's; ``none``: LiDAR only).
        limit: The first N frames only (0: all).
        device: ``cpu`` or ``cuda``.
        json: Where the figures go as JSON (None: not written).
        quiet: No progress bar.
    """

    data: Path = option(help="root folder (lidar/ + a radar tree)")
    checkpoint: Path = option(DEFAULT_CHECKPOINT)
    split: str = option(
        "all", help="all (every frame with a label_2 file; default) or an ImageSets list name"
    )
    radar_folder: str = option("auto", choices=("auto", *RADAR_FOLDERS, "none"), help="radar tree")
    limit: int = option(0, help="first N frames only (0: all)")
    device: str = option("cpu", help="cpu or cuda")
    json: Path | None = option(None, help="write the figures as JSON here")
    quiet: bool = option(False, help="no progress bar")

    def __post_init__(self) -> None:
        if self.limit < 0:
            raise ValueError(f"--limit must be >= 0, got {self.limit}")


_FLAG_ORDER: tuple[tuple[type, tuple[str, ...]], ...] = (
    (ClassPromptsCommand, ("data", "checkpoint", "split")),
    (ScoringConfig, ("max_range", "threshold")),
    (ClassPromptsCommand, ("radar_folder",)),
    (ScoringConfig, ("fov", "sweep", "candidates")),
    (ClassPromptsCommand, ("limit", "device", "json", "quiet")),
)
"""Which dataclass each flag comes from, in ``--help``'s order."""


@dataclass(frozen=True)
class FrameResult:
    """The three prompts' counts on one frame: ``counts[k]`` at threshold ``thresholds[k]`` (the
    operating threshold first, then ``ScoringConfig.sweep``), one :class:`PromptCount` per class."""

    sample_id: str
    thresholds: tuple[float, ...]
    counts: tuple[tuple[PromptCount, ...], ...]


@dataclass(frozen=True)
class ClassPromptReport:
    """Class-prompt figures over a root.

    Attributes:
        config: How answers were counted.
        frames: Per-frame counts, in scoring order.
        per_class: Class -> totals at the operating threshold.
        overall: The three prompts pooled, at the operating threshold.
        sweep: ``(threshold, per class, pooled)`` for each ``config.sweep`` threshold.
        other_labels: Non-metric label names -> count over the frames (never targets).
        seconds: Wall time of loading and the model calls.
        prompts: Class -> the prompt asked (:func:`class_prompts` of the model's class set).
    """

    config: ScoringConfig
    frames: tuple[FrameResult, ...]
    per_class: dict[str, ClassSummary]
    overall: ClassSummary
    sweep: tuple[tuple[float, dict[str, ClassSummary], ClassSummary], ...] = ()
    other_labels: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    prompts: dict[str, str] = field(default_factory=lambda: dict(CLASS_PROMPTS))

    def to_dict(self) -> dict[str, Any]:
        return {
            "config": asdict(self.config),
            "prompts": dict(self.prompts),
            "frames": len(self.frames),
            "per_class": {k: asdict(v) for k, v in self.per_class.items()},
            "overall": asdict(self.overall),
            "targets": {
                "recall_percent_at_least": TARGET_RECALL,
                "false_boxes_per_prompt_at_most": TARGET_FALSE_PER_PROMPT,
                "met": self.overall.meets_targets(),
            },
            "sweep": [
                {"threshold": t, "overall": asdict(o), **{k: asdict(v) for k, v in pc.items()}}
                for t, pc, o in self.sweep
            ],
            "other_labels": dict(self.other_labels),
            "seconds": self.seconds,
            "per_frame": [
                {"id": f.sample_id, **{c.cls: asdict(c) for c in f.counts[0]}} for f in self.frames
            ],
        }

    def format_table(self) -> str:
        """The per-class table and the threshold sweep (plain text)."""
        cfg = self.config
        view = ", camera field of view" if cfg.fov == "camera" else ""
        lines = [
            f"Class prompts on {len(self.frames)} frames (BEV range <= {cfg.max_range:g} m{view}; "
            f"threshold {cfg.threshold:g}; found: 3D IoU > 0.5 car, > 0.25 ped / cyc; (c): BEV "
            "centre within 2 m car, 1 m ped / cyc)",
            f"{'prompt':<17}{'targets':>8}{'found':>7}{'recall':>8}{'false/prompt':>13}"
            f"{'wrong cls':>10}{'on other':>9}{'found(c)':>9}{'recall(c)':>10}{'false(c)/pr':>12}",
        ]
        rows = [(self.prompts[c], s) for c, s in self.per_class.items()]
        for name, s in [*rows, ("all three", self.overall)]:
            n = max(s.prompts, 1)
            lines.append(
                f"{name:<17}{s.targets:>8}{s.found:>7}{s.recall:>7.1f}%{s.false_per_prompt:>13.2f}"
                f"{s.false_wrong_class / n:>10.2f}{s.false_on_other / n:>9.2f}"
                f"{s.found_centre:>9}{s.recall_centre:>9.1f}%"
                f"{s.false_centre_per_prompt:>12.2f}"
            )
        lines.append(
            "false/prompt: answer boxes in the region matching no target; of which 'wrong cls': "
            "of another class, 'on other': on a non-metric labelled object (per prompt)"
        )
        verdict = "met" if self.overall.meets_targets() else "not met"
        lines.append(
            f"issue-14 targets (pooled recall >= {TARGET_RECALL:g} %, <= "
            f"{TARGET_FALSE_PER_PROMPT:g} false boxes per prompt): {verdict}"
        )
        if self.sweep:
            lines.append("threshold sweep: recall % / false boxes per prompt")
            lines.append(
                f"{'threshold':<11}" + "".join(f"{c:>14}" for c in self.prompts) + f"{'pooled':>14}"
            )
            for t, pc, o in ((cfg.threshold, self.per_class, self.overall), *self.sweep):
                cells = [f"{s.recall:.1f} / {s.false_per_prompt:.2f}" for s in (*pc.values(), o)]
                mark = " *" if o.meets_targets() else ""
                lines.append(f"{t:<11g}" + "".join(f"{c:>14}" for c in cells) + mark)
            lines.append("(* meets the issue-14 targets)")
        if self.other_labels:
            others = ", ".join(f"{k} {v}" for k, v in sorted(self.other_labels.items()))
            lines.append(f"non-metric labels (never targets): {others}")
        return "\n".join(lines) + "\n"


def score_frame(model: GroundingModel, sample: Sample, config: ScoringConfig) -> FrameResult:
    """Ask the three class prompts on one sample (one ``encode_scene``, three ``ground`` at the
    smallest threshold) and count the answers at each threshold."""
    fov_size = image_size_of(sample) if config.fov == "camera" else IMAGE_SIZE

    def counted(boxes: np.ndarray) -> np.ndarray:
        mask = bev_range(boxes) <= config.max_range
        if config.fov == "camera":
            mask &= in_camera_view(boxes, sample.calib, fov_size)
        return mask

    thresholds = config.resolved()
    gt_boxes = np.asarray(sample.boxes, dtype=np.float64).reshape(-1, 7)
    gt_counted = counted(gt_boxes)
    classes = model_classes(model)
    other_boxes = other_label_boxes(sample.labels, sample.calib, classes)
    labelled = None
    if config.candidates == "labels":
        from model.core.labelled import LabelledBoxes

        labelled = LabelledBoxes(gt_boxes, [classes.index(c) for c in sample.classes], classes)
    if labelled is None:
        features = model.encode_scene(sample.lidar, sample.radar)
    else:  # a referent-path model (TPCNet.encode_scene); the protocol has no candidates
        features = model.encode_scene(sample.lidar, sample.radar, candidates=labelled)  # type: ignore[call-arg]
    per_threshold: list[list[PromptCount]] = [[] for _ in thresholds]
    for cls, prompt in class_prompts(classes).items():
        pred = model.ground(features, prompt, score_threshold=min(thresholds))
        scores = np.asarray(pred.scores, dtype=np.float64).reshape(-1)
        boxes = np.asarray(pred.boxes, dtype=np.float64).reshape(-1, 7)
        classes = np.array(list(pred.classes), dtype=object).reshape(-1)
        pred_counted = counted(boxes)
        for k, t in enumerate(thresholds):
            keep = scores >= t
            per_threshold[k].append(
                count_prompt(
                    cls,
                    boxes[keep],
                    scores[keep],
                    list(classes[keep]),
                    gt_boxes,
                    sample.classes,
                    pred_counted[keep],
                    gt_counted,
                    other_boxes,
                )
            )
    return FrameResult(sample.sample_id, thresholds, tuple(tuple(c) for c in per_threshold))


def summarize(
    frames: Sequence[FrameResult],
    config: ScoringConfig,
    prompts: dict[str, str] = CLASS_PROMPTS,
) -> tuple[dict[str, ClassSummary], ClassSummary, tuple]:
    """Per-class (each class of ``prompts``, the :func:`class_prompts` asked) and pooled totals
    at the operating threshold, and the sweep's."""
    out = []
    for k in range(1 + len(config.sweep)):
        counts = [c for f in frames for c in f.counts[k]]
        per_class = {cls: ClassSummary.of([c for c in counts if c.cls == cls]) for cls in prompts}
        out.append((per_class, ClassSummary.of(counts)))
    sweep = tuple((t, pc, o) for t, (pc, o) in zip(config.sweep, out[1:], strict=True))
    return out[0][0], out[0][1], sweep


def score_root(
    model: GroundingModel,
    root: Talk2RadarRoot,
    ids: Sequence[str],
    config: ScoringConfig,
    progress: bool = False,
) -> ClassPromptReport:
    """Score the class prompts of the model's class set on the given frames of ``root`` (eval
    mode, no gradients; the root read into that class set)."""
    from tqdm import tqdm

    if isinstance(model, torch.nn.Module):
        model.eval()
    frames = []
    others: dict[str, int] = {}
    classes = model_classes(model)
    start = time.perf_counter()
    with torch.no_grad():
        for sid in tqdm(ids, desc="class prompts", unit="frame", disable=not progress):
            sample = root.load(sid)
            frames.append(score_frame(model, sample, config))
            for lab in sample.labels:
                if classes.label_class(lab.name) is None:
                    others[lab.name] = others.get(lab.name, 0) + 1
    prompts = class_prompts(classes)
    per_class, overall, sweep = summarize(frames, config, prompts)
    seconds = time.perf_counter() - start
    return ClassPromptReport(
        config, tuple(frames), per_class, overall, sweep, others, seconds, prompts
    )


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m model.class_prompts",
        description="Ask 'the cyclists', 'the pedestrians', 'the cars' on every frame of a root "
        "with full labels (a View-of-Delft root) and count found objects and false boxes.",
    )
    for cls, names in _FLAG_ORDER:
        add_options(p, cls, only=names)
    return p


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """The command (see :func:`main`; ``argv`` is recorded in the JSON); raises on bad input."""
    from model.checkpoint import load_checkpoint
    from model.evaluation.predict import operating_threshold

    command = from_args(ClassPromptsCommand, args)
    given = from_args(ScoringConfig, args)
    if not command.data.is_dir():
        raise RootError(f"{command.data}: not a folder")
    lidar = Path(command.data) / LIDAR_FOLDER
    if not lidar.is_dir():
        raise RootError(f"{lidar}: missing (a VoD root has lidar/training/...)")
    root = Talk2RadarRoot(
        command.data, radar=None if command.radar_folder == "none" else command.radar_folder
    )
    talk2radar = root.has_prompts
    ids = distinct_scenes(root, labelled_frame_ids(root, command.split))
    if command.limit:
        ids = ids[: command.limit]
    if not ids:
        raise RootError(f"{command.data}: split {command.split!r} has no frames")
    model = load_checkpoint(command.checkpoint, device=command.device)
    if root.classes != model_classes(model):  # the labels read into the checkpoint's classes
        root = Talk2RadarRoot(root.path, radar=root.radar_folder, classes=model_classes(model))
    config = given
    if given.threshold is None:
        config = replace(given, threshold=float(operating_threshold(model)))
    threshold = config.threshold
    meta = CheckpointMeta.of(model)
    print(
        f"data: {command.data} ({len(ids)} frames, split {command.split}, radar "
        f"{root.radar_folder or 'none'}); checkpoint {command.checkpoint} (step {meta.step}, "
        f"epoch {meta.epoch}); threshold {threshold:g} "
        f"({'--threshold' if given.threshold is not None else 'checkpoint'}); candidates "
        f"{given.candidates}"
    )
    if talk2radar:
        print(
            f"note: {command.data} is a Talk2Radar root (lidar/training/prompt/): its label_2 holds "
            "only each prompt's referents, not every object, so found objects are undercounted "
            "and real objects count as false boxes; use a View-of-Delft root with full labels",
            file=sys.stderr,
        )
    report = score_root(model, root, ids, config, progress=not command.quiet)
    print(report.format_table(), end="")
    if command.json is not None:
        data = {
            "root": str(command.data),
            "root_kind": "talk2radar (referent labels only)" if talk2radar else "full labels",
            "split": command.split,
            "radar_folder": root.radar_folder,
            "checkpoint": str(command.checkpoint),
            "checkpoint_sha256": _sha256(command.checkpoint),
            "checkpoint_step": meta.step,
            "checkpoint_epoch": meta.epoch,
            "threshold_source": "--threshold" if given.threshold is not None else "checkpoint",
            "command": " ".join(["python -m model.class_prompts", *argv]),
            **report.to_dict(),
        }
        command.json.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(command.json, json.dumps(data, indent=1) + "\n")
        print(f"wrote {command.json}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m model.class_prompts``; errors are one line on stderr with exit code 2."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(argv)
    return report_errors(lambda: run(args, argv))  # RootError, LabelError, CheckpointError, ...


if __name__ == "__main__":
    sys.exit(main())
