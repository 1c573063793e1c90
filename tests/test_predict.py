"""Prediction files: KittiMetric's filtering and the empty-file rule."""

import numpy as np

from model.predict import prediction_labels, write_predictions
from scenes.calib import vod_lidar_calibration
from scenes.kitti import read_label_file


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
