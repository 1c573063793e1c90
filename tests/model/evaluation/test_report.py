"""model/evaluation/report.py's breakdowns: frames grouped by prompt type (paper table III) and objects by
camera depth (table IV), each scored with the official VoD protocol (:func:`evaluate_frames`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from model.evaluation.metrics import evaluate_frames
from model.evaluation.report import DEPTH_BINS, PROMPT_TYPES, breakdown_by_depth, breakdown_by_type
from scenes.frame.kitti import ObjectLabel, boxes_to_labels
from scenes.geometry.calib import vod_lidar_calibration

FRAMES = 8
"""Frames per group, one object each."""

PERFECT = math.ceil(FRAMES / 4) / 11 * 100
"""The devkit's AP R11 of :data:`FRAMES` objects all found (distinct scores, no false positive
before them): ``ceil(k / 4) / 11 x 100`` with fewer than 40 objects (see tests/model/evaluation/test_metrics.py)."""


def _cars(*xs: float, score: float | None = None) -> list[ObjectLabel]:
    """Cars straight ahead at LiDAR ``x`` metres (camera-frame labels, as label_2 holds them)."""
    boxes = np.array([[x, 0.0, -0.95, 4.2, 1.8, 1.5, 0.0] for x in xs]).reshape(-1, 7)
    scores = None if score is None else np.full(len(xs), score)
    return boxes_to_labels(boxes, ["Car"] * len(xs), vod_lidar_calibration(), scores=scores)


def _car_ap(result) -> float:
    return result.entire_area["Car"].ap_3d.r11


def test_breakdown_by_type_scores_each_types_frames_alone() -> None:
    found = {f"f{i}": 12.0 + i for i in range(FRAMES)}  # depth prompts, detected
    missed = {f"m{i}": 20.0 + i for i in range(FRAMES)}  # velocity prompts, not detected
    gt = {f: _cars(x) for f, x in {**found, **missed, "other": 30.0}.items()}
    dt = {f: _cars(x, score=0.9 - 0.01 * i) for i, (f, x) in enumerate(found.items())}
    tags = {f: frozenset({"depth"}) for f in found}
    tags |= {f: frozenset({"velocity", "position"}) for f in missed}  # counts in both types
    tags["other"] = frozenset({"class"})  # no prompt type of the table
    out = breakdown_by_type(gt, dt, tags)
    assert set(out) == {"depth", "velocity", "position"} and set(out) <= set(PROMPT_TYPES)
    frames, depth = out["depth"]
    assert frames == FRAMES == depth.num_frames == depth.entire_area["Car"].num_gt
    assert _car_ap(depth) == pytest.approx(PERFECT)
    assert _car_ap(out["velocity"][1]) == 0.0 == _car_ap(out["position"][1])
    assert out["velocity"][1].to_dict() == evaluate_frames({f: gt[f] for f in missed}, {}).to_dict()


def test_breakdown_by_depth_keeps_ground_truth_and_detections_in_their_bin() -> None:
    gt = {f"f{i}": _cars(8.0, 15.0 + 0.5 * i) for i in range(FRAMES)}
    gt["far"] = _cars(35.0)
    dt = {
        f"f{i}": _cars(8.0, score=0.9 - 0.01 * i) + _cars(26.0, score=0.95) for i in range(FRAMES)
    }
    dt["far"] = _cars(35.0, score=0.9)
    depths = sorted({int(lab.location[2] // 10) for labs in gt.values() for lab in labs})
    assert depths == [0, 1, 3]  # the cars' camera-frame depth bins
    out = breakdown_by_depth(gt, dt)
    assert list(out) == [f"{lo:g}-{hi:g}" for lo, hi in DEPTH_BINS]
    assert [count for count, _ in out.values()] == [FRAMES, FRAMES, 0, 1, 0, 0]  # GT per bin
    assert _car_ap(out["0-10"][1]) == pytest.approx(PERFECT)  # every near car found
    assert _car_ap(out["10-20"][1]) == 0.0  # no 10-20 m car detected
    # The false positives at 26 m (scored above every true positive) count in 20-30 only,
    # where there is no ground truth: the near bin is scored as if they did not exist.
    assert out["20-30"][1].entire_area["Car"].num_gt == 0
    near = {f: [lab for lab in labs if lab.location[2] < 10] for f, labs in gt.items()}
    near_dt = {f: [lab for lab in labs if lab.location[2] < 10] for f, labs in dt.items()}
    assert out["0-10"][1].to_dict() == evaluate_frames(near, near_dt).to_dict()
    assert _car_ap(evaluate_frames(near, dt)) < PERFECT  # what they would do unbinned
