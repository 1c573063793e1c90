"""Prediction files: KittiMetric's filtering and the empty-file rule; the operating threshold;
one encoding per shared scene."""

from types import SimpleNamespace

import numpy as np
import pytest

from model.checkpoint_meta import CheckpointMeta
from model.evaluation.predict import (
    iterate_predictions,
    operating_threshold,
    prediction_labels,
    read_ahead,
    scene_key,
    write_predictions,
)
from scenes.frame.kitti import read_label_file
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.talk2radar.root import Talk2RadarRoot, Talk2RadarWriter


def test_prediction_labels_filter_and_format(tmp_path):
    calib = vod_lidar_calibration()
    boxes = np.array(
        [
            [15.0, 1.0, -0.9, 4.0, 1.8, 1.5, 0.2],  # in view: kept
            [15.0, 40.0, -0.9, 4.0, 1.8, 1.5, 0.0],  # far left, out of the image: dropped
            [-5.0, 0.0, -0.9, 4.0, 1.8, 1.5, 0.0],  # behind the LiDAR (x < 0): dropped
            [80.0, 0.0, -0.9, 4.0, 1.8, 1.5, 0.0],  # beyond 70.4 m: dropped
        ]
    )
    labels = prediction_labels(boxes, ["Car"] * 4, np.array([0.9, 0.8, 0.7, 0.6]), calib)
    assert len(labels) == 1
    lab = labels[0]
    assert lab.truncated == -1 and lab.occluded == -1 and lab.score == 0.9
    assert lab.bbox[3] - lab.bbox[1] > 40  # a real projected 2D box
    out = write_predictions({"00001": labels, "00002": []}, tmp_path)
    assert (out / "00002.txt").read_text() == ""
    again = read_label_file(out / "00001.txt")
    assert again[0].name == "Car" and abs(again[0].rotation_y - lab.rotation_y) < 1e-4
    fields = (out / "00001.txt").read_text().split()
    assert fields[1:3] == ["-1", "-1"] and len(fields) == 16


class _FakeModel:
    """Counts encodings; answers every prompt with one car box of score 0.5 and one of 0.05."""

    def __init__(self, metadata: dict | None = None, threshold: float = 0.1) -> None:
        self.cfg = SimpleNamespace(head=SimpleNamespace(score_threshold=threshold))
        self.grounding = SimpleNamespace(uncalibrated_threshold=threshold)  # as the paper's head
        if metadata is not None:
            self.checkpoint_metadata = CheckpointMeta.from_dict(metadata)
        self.encoded = 0
        self.grounded: list[str] = []

    def eval(self) -> None:
        pass

    def encode_scene(self, lidar, radar):
        self.encoded += 1
        return ("features", len(lidar))

    def ground(self, features, prompt, score_threshold=None):
        self.grounded.append(prompt)
        boxes = np.array(
            [[15.0, 1.0, -0.9, 4.0, 1.8, 1.5, 0.2], [25.0, 1.0, -0.9, 4.0, 1.8, 1.5, 0]]
        )
        scores = np.array([0.5, 0.05])
        keep = scores >= (0.0 if score_threshold is None else score_threshold)
        return SimpleNamespace(
            boxes=boxes[keep], scores=scores[keep], classes=("Car",) * keep.sum()
        )


def test_operating_threshold():
    assert operating_threshold(_FakeModel()) == 0.1
    assert operating_threshold(_FakeModel({"epoch": 2}, threshold=0.2)) == 0.2
    assert operating_threshold(_FakeModel({"operating_threshold": 0.35})) == 0.35
    for bad in (1.0, -0.1, "0.3", True):
        with pytest.raises(ValueError, match="'operating_threshold' must be a number in"):
            operating_threshold(_FakeModel({"operating_threshold": bad}))


def _root(tmp_path):
    rng = np.random.default_rng(0)
    writer = Talk2RadarWriter(tmp_path)
    ids = []
    for world in range(2):
        files = writer.write_sensors(
            f"w{world}",
            rng.uniform(-10, 10, (300 + world, 4)).astype(np.float32),
            rng.uniform(-10, 10, (30, 7)).astype(np.float32),
            vod_lidar_calibration(),
            vod_radar_calibration(),
        )
        for k in range(3):
            box = np.array([[15.0, 1.0, -0.9, 4.0, 1.8, 1.5, 0.2]])
            ids.append(writer.write_sample(3 * world + k, files, box, ["Car"], f"prompt {k}"))
    writer.write_image_sets({"test": ids})
    return Talk2RadarRoot(tmp_path)


def test_samples_sharing_sensor_files_are_encoded_once(tmp_path):
    root = _root(tmp_path)
    ids = root.ids("test")
    keys = [scene_key(root, sid) for sid in ids]
    assert len(set(keys[:3])) == 1 and len(set(keys[3:])) == 1 and keys[0] != keys[3]
    model = _FakeModel()
    preds = list(iterate_predictions(model, root, ids, 0.01, progress=False, min_label_score=0.1))
    assert model.encoded == 2 and len(preds) == 6
    assert model.grounded == [f"prompt {k}" for k in (0, 1, 2)] * 2
    assert preds[4].features == ("features", 301) and preds[4].scene_key == keys[3]
    # Every box the grounding threshold kept is returned; only those >= 0.1 become labels.
    assert len(preds[0].boxes) == 2 and [lab.score for lab in preds[0].labels] == [0.5]
    # Without the cache, every sample is encoded.
    again = _FakeModel()
    list(iterate_predictions(again, root, ids, progress=False, cache_scenes=0))
    assert again.encoded == 6


def test_read_ahead_keeps_the_order_reads_ahead_and_raises_in_place():
    import threading

    started: list[str] = []
    b_started, gate = threading.Event(), threading.Event()

    def read(sid: str) -> str:
        started.append(sid)
        if sid == "b":
            b_started.set()
            gate.wait(5)
        if sid == "c":
            raise ValueError("c is unreadable")
        return sid.upper()

    got = read_ahead(read, ["a", "b", "c", "d"], ahead=2)
    assert next(got) == "A"
    assert b_started.wait(5)  # b is read while A is in use, before it is asked for
    gate.set()
    assert next(got) == "B"
    with pytest.raises(ValueError, match="c is unreadable"):
        next(got)
    assert started[:3] == ["a", "b", "c"]
    assert list(read_ahead(lambda s: s * 2, ["x", "y"], ahead=5)) == ["xx", "yy"]
    assert list(read_ahead(lambda s: s, [], ahead=2)) == []
