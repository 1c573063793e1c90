"""Ground a whole split and score it: the official VoD result plus the paper's breakdowns.

- Overall: :func:`model.metrics.evaluate_frames` over every frame of the split.
- Per prompt type (the paper's table III): frames grouped by their prompt's type tags (``depth``,
  ``velocity``, ``motion``, ``position``); a prompt with several tags counts in each. Tags come from
  the sample's sidecar where present, else from :func:`scenes.prompts.infer_tags` on the text (so
  real Talk2Radar prompts are grouped by the same keyword rules).
- Per depth bin (table IV): "we partition the predicted objects into six depth intervals, each
  spanning 10 meters". An object's depth is its camera-frame forward distance (the label's
  ``location.z``); ground truth and detections are both restricted to the bin, then scored.

All AP values are the entire-area 3D mAP at 11 recall points unless a table says otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from model.metrics import VodResult, evaluate_frames
from model.predict import iterate_predictions
from scenes.kitti import ObjectLabel
from scenes.prompts import infer_tags
from scenes.root import Talk2RadarRoot

PROMPT_TYPES: tuple[str, ...] = ("depth", "velocity", "motion", "position")
DEPTH_BINS: tuple[tuple[float, float], ...] = tuple((10.0 * i, 10.0 * (i + 1)) for i in range(6))


@dataclass(frozen=True)
class GroundingReport:
    """The evaluation of a model on a split.

    Attributes:
        result: Official VoD result over all frames.
        by_type: Prompt type -> (number of frames, result on those frames).
        by_depth: ``"0-10"`` ... ``"50-60"`` -> (number of GT objects, result in that bin).
        predictions: Frame id -> prediction labels (what the files hold).
        ground_truth: Frame id -> ground-truth labels.
        seconds: Per-frame ``encode_scene + ground`` wall time.
    """

    result: VodResult
    by_type: Mapping[str, tuple[int, VodResult]]
    by_depth: Mapping[str, tuple[int, VodResult]]
    predictions: Mapping[str, list[ObjectLabel]] = field(repr=False)
    ground_truth: Mapping[str, list[ObjectLabel]] = field(repr=False)
    tags: Mapping[str, frozenset[str]] = field(repr=False, default_factory=dict)
    seconds: tuple[float, ...] = field(repr=False, default=())

    def rescored(self, predictions: Mapping[str, list[ObjectLabel]]) -> GroundingReport:
        """The same report with other predictions for the same frames (e.g. read back from the
        written files, as the official devkit would read them)."""
        return build_report(self.ground_truth, predictions, self.tags, self.seconds)

    def to_dict(self) -> dict:
        """JSON-ready: the official dict plus ``by_prompt_type``, ``by_depth`` and timing."""
        return {
            **self.result.to_dict(),
            "num_frames": self.result.num_frames,
            "by_prompt_type": {
                k: {"frames": n, **r.to_dict()} for k, (n, r) in self.by_type.items()
            },
            "by_depth": {
                k: {"gt_objects": n, **r.to_dict()} for k, (n, r) in self.by_depth.items()
            },
            "median_seconds_per_frame": float(np.median(self.seconds)) if self.seconds else None,
        }

    def format_tables(self) -> str:
        """The official table, then mAP by prompt type and by depth bin (3D, entire area, R11)."""
        lines = [self.result.format_table()]
        lines.append("mAP by prompt type (3D, entire area, 11-point / 40-point)")
        for name, (n, res) in self.by_type.items():
            area = res.entire_area
            lines.append(f"  {name:<10}{n:>6} frames  {area.map_3d:6.2f} / {area.map_3d_r40:6.2f}")
        lines.append("mAP by depth (3D, entire area, 11-point / 40-point)")
        for name, (n, res) in self.by_depth.items():
            area = res.entire_area
            lines.append(f"  {name:<10}{n:>6} objects {area.map_3d:6.2f} / {area.map_3d_r40:6.2f}")
        return "\n".join(lines) + "\n"


def _depth(label: ObjectLabel) -> float:
    return float(label.location[2])


def breakdown_by_type(
    gt: Mapping[str, list[ObjectLabel]],
    dt: Mapping[str, list[ObjectLabel]],
    tags: Mapping[str, frozenset[str]],
) -> dict[str, tuple[int, VodResult]]:
    """Score the frames of each prompt type separately (types with no frame are left out)."""
    out = {}
    for kind in PROMPT_TYPES:
        frames = [f for f in gt if kind in tags.get(f, frozenset())]
        if frames:
            out[kind] = (
                len(frames),
                evaluate_frames({f: gt[f] for f in frames}, {f: dt.get(f, []) for f in frames}),
            )
    return out


def breakdown_by_depth(
    gt: Mapping[str, list[ObjectLabel]],
    dt: Mapping[str, list[ObjectLabel]],
    bins: Sequence[tuple[float, float]] = DEPTH_BINS,
) -> dict[str, tuple[int, VodResult]]:
    """Score ground truth and detections restricted to each depth bin ``[lo, hi)``."""
    out = {}
    for lo, hi in bins:
        gt_bin = {f: [g for g in labs if lo <= _depth(g) < hi] for f, labs in gt.items()}
        dt_bin = {f: [d for d in labs if lo <= _depth(d) < hi] for f, labs in dt.items()}
        count = sum(len(v) for v in gt_bin.values())
        out[f"{lo:g}-{hi:g}"] = (count, evaluate_frames(gt_bin, dt_bin))
    return out


def evaluate_predictions(
    model: torch.nn.Module,
    root: Talk2RadarRoot,
    ids: Sequence[str],
    progress: bool = True,
    score_threshold: float | None = None,
) -> GroundingReport:
    """Ground every sample of ``ids`` and score the answers."""
    if not ids:
        raise ValueError(f"{root.path}: no samples to evaluate")
    gt: dict[str, list[ObjectLabel]] = {}
    dt: dict[str, list[ObjectLabel]] = {}
    tags: dict[str, frozenset[str]] = {}
    seconds = []
    for pred in iterate_predictions(model, root, ids, score_threshold, progress=progress):
        sid = pred.sample.sample_id
        gt[sid] = list(pred.sample.labels)
        dt[sid] = pred.labels
        meta = pred.sample.meta
        tags[sid] = meta.tags if meta is not None and meta.tags else infer_tags(pred.sample.prompt)
        seconds.append(pred.seconds)
    return build_report(gt, dt, tags, tuple(seconds))


def build_report(
    gt: Mapping[str, list[ObjectLabel]],
    dt: Mapping[str, list[ObjectLabel]],
    tags: Mapping[str, frozenset[str]],
    seconds: Sequence[float] = (),
) -> GroundingReport:
    """Score ``dt`` against ``gt`` overall, per prompt type and per depth bin."""
    return GroundingReport(
        result=evaluate_frames(gt, dt),
        by_type=breakdown_by_type(gt, dt, tags),
        by_depth=breakdown_by_depth(gt, dt),
        predictions=dict(dt),
        ground_truth=dict(gt),
        tags=dict(tags),
        seconds=tuple(seconds),
    )
