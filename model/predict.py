"""Run a model over a split of a Talk2Radar root and write KITTI prediction files.

The writer follows mmdet3d's ``KittiMetric`` as the Talk2Radar workflow uses it (spec §1.7, §2.2):

- one ``<frame id>.txt`` per frame of the split, **empty when nothing is found** (the VoD
  evaluator takes its frame list from the prediction folder, so a missing file would silently drop
  that frame's ground truth);
- each line ``Class -1 -1 alpha x1 y1 x2 y2 h w l x y z ry score`` with four decimals, the camera-
  frame bottom centre, and the *real* projected and clipped 2D box (the evaluator ignores
  detections whose 2D height is under 40 px);
- a detection is kept only if its 2D box overlaps the image and its LiDAR-frame bottom centre lies
  strictly inside ``pcd_limit_range = [0, -40, -3, 70.4, 40, 0]``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from scenes.calib import IMAGE_SIZE, Calibration, bottom_centres
from scenes.kitti import ObjectLabel, boxes_to_labels, write_label_file
from scenes.root import Sample, Talk2RadarRoot

PCD_LIMIT_RANGE = (0.0, -40.0, -3.0, 70.4, 40.0, 0.0)
"""mmdet3d's default ``pcd_limit_range`` (x_min, y_min, z_min, x_max, y_max, z_max), LiDAR frame."""


def prediction_labels(
    boxes: np.ndarray,
    classes: Sequence[str],
    scores: np.ndarray,
    calib: Calibration,
    image_size: tuple[int, int] = IMAGE_SIZE,
) -> list[ObjectLabel]:
    """Turn LiDAR-frame detections into KITTI prediction labels, filtered as ``KittiMetric`` does.

    Args:
        boxes: ``(K, 7)`` LiDAR frame, z at the geometric centre.
        classes: ``K`` class names.
        scores: ``(K,)`` confidences.
        calib: The frame's LiDAR calibration.

    Returns:
        The kept detections as labels (``truncated = occluded = -1``), in input order.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return []
    labels = boxes_to_labels(
        b,
        list(classes),
        calib,
        scores=np.asarray(scores),
        image_size=image_size,
        truncated=-1.0,
        occluded=-1,
    )
    width, height = image_size
    lo, hi = np.array(PCD_LIMIT_RANGE[:3]), np.array(PCD_LIMIT_RANGE[3:])
    kept = []
    for label, centre in zip(labels, bottom_centres(b), strict=True):
        x1, y1, x2, y2 = label.bbox
        in_image = x1 < width and y1 < height and x2 > 0 and y2 > 0
        in_range = bool(np.all(centre > lo) and np.all(centre < hi))
        if in_image and in_range:
            kept.append(label)
    return kept


@dataclass(frozen=True)
class FramePrediction:
    """The model's answer for one sample, with its ground truth and timing."""

    sample: Sample
    boxes: np.ndarray
    scores: np.ndarray
    classes: tuple[str, ...]
    labels: list[ObjectLabel]
    seconds: float


def iterate_predictions(
    model: torch.nn.Module,
    root: Talk2RadarRoot,
    ids: Sequence[str],
    score_threshold: float | None = None,
    progress: bool = True,
) -> Iterator[FramePrediction]:
    """Run ``model.encode_scene`` + ``model.ground`` on each sample (eval mode, no gradients)."""
    model.eval()
    with torch.no_grad():
        for sid in tqdm(ids, desc="predict", unit="frame", disable=not progress):
            sample = root.load(sid)
            if sample.prompt is None:
                raise ValueError(f"{root.path}: sample {sid} has no prompt to ground")
            start = time.perf_counter()
            features = model.encode_scene(sample.lidar, sample.radar)
            pred = model.ground(features, sample.prompt, score_threshold=score_threshold)
            seconds = time.perf_counter() - start
            labels = prediction_labels(pred.boxes, pred.classes, pred.scores, sample.calib)
            yield FramePrediction(
                sample,
                np.asarray(pred.boxes),
                np.asarray(pred.scores),
                tuple(pred.classes),
                labels,
                seconds,
            )


def write_predictions(predictions: dict[str, list[ObjectLabel]], out_dir: str | Path) -> Path:
    """Write one prediction file per frame (empty files included) into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for sid, labels in predictions.items():
        write_label_file(out / f"{sid}.txt", labels, decimals=4)
    return out
