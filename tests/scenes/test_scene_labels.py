"""Full frame labels of a View-of-Delft root and grounding over labelled boxes."""

from __future__ import annotations

import numpy as np
import pytest

from model import LabelledBoxes
from model.checkpoint import load_checkpoint
from scenes.frame import RootError
from scenes.geometry.actors import CLASSES
from scenes.geometry.calib import IMAGE_SIZE, vod_lidar_calibration
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels, class_index, fov_mask


def test_scene_labels_read_every_object_with_vod_names(tmp_path, write_vod_root):
    root = write_vod_root(tmp_path / "vod", frames=2)
    labels = SceneLabels(root)
    sid = "00000"
    assert labels.has(sid)
    objects = labels.load(sid)
    assert "bicycle" in objects.names and "rider" in objects.names
    boxes, metric = objects.metric()
    assert len(boxes) == int(np.sum(objects.labels >= 0)) >= 3
    assert set(metric.tolist()) <= {0, 1, 2}
    assert len(objects.others()) == 2
    assert not labels.has("99999")
    with pytest.raises(RootError, match="99999"):
        labels.load("99999")


def test_scene_labels_refuse_a_root_without_labels(tmp_path):
    with pytest.raises(RootError, match="label_2"):
        SceneLabels(tmp_path)


def test_class_index_is_case_insensitive():
    assert class_index("car") == CLASSES.index("Car")
    assert class_index("bicycle") == -1


def test_fov_mask_is_the_camera_wedge():
    calib = vod_lidar_calibration()
    xy = np.array([[20.0, 0.0], [20.0, 40.0], [-5.0, 0.0], [5.0, -1.0], [60.0, 0.0]])
    assert fov_mask(xy, calib, IMAGE_SIZE).tolist() == [True, False, False, True, False]


def test_labelled_boxes_validate():
    with pytest.raises(ValueError, match="labels"):
        LabelledBoxes(np.zeros((2, 7)) + 1, np.array([0]))
    with pytest.raises(ValueError, match="index"):
        LabelledBoxes(np.ones((1, 7)), np.array([3]))
    with pytest.raises(ValueError, match="positive"):
        LabelledBoxes(np.zeros((1, 7)), np.array([0]))


def test_ground_over_labelled_boxes_returns_only_those_boxes(tmp_path, write_vod_root):
    root = write_vod_root(tmp_path / "vod", frames=1)
    sid = "00000"
    sample = Talk2RadarRoot(root).load(sid)
    boxes, labels = SceneLabels(root).load(sid).metric()
    model = load_checkpoint("checkpoints/tpcnet-small.pt")
    feats = model.encode_scene(sample.lidar, sample.radar, candidates=LabelledBoxes(boxes, labels))
    assert feats.objects is not None and feats.answerable == len(boxes)
    assert len(feats.objects) >= len(boxes)
    pred = model.ground(feats, "the pedestrians", score_threshold=0.0)
    assert len(pred.boxes) == len(boxes)
    for box in pred.boxes:
        assert np.min(np.abs(boxes - box).sum(axis=1)) < 1e-9
    top = pred.classes[int(np.argmax(pred.scores))]
    assert top == "Pedestrian"


def test_with_context_keeps_labels_first_and_drops_duplicates():
    from model.core.labelled import LABELLED_SCORE, with_context

    labelled = LabelledBoxes(
        np.array([[10.0, 0, -1, 4, 2, 1.5, 0], [20.0, 5, -1, 1, 1, 1.7, 0]]), [0, 1]
    )
    proposals = np.array(
        [
            [10.3, 0.2, -1, 4, 2, 1.5, 0.1],  # the labelled car again
            [30.0, -4, -1, 4, 2, 1.5, 0],  # context
            [20.5, 5.4, -1, 0.8, 0.8, 1.7, 0],  # the pedestrian, proposed as a cyclist
            [40.0, 0, -1, 4, 2, 1.5, 0],  # context, but over the total
        ]
    )
    boxes, labels, scores = with_context(
        labelled, proposals, np.array([0, 0, 2, 0]), np.array([0.7, 0.6, 0.5, 0.4]), 3
    )
    assert len(boxes) == 3 and labels.tolist() == [0, 1, 0]
    np.testing.assert_allclose(boxes[2], proposals[1])
    # a labelled box is certain, whatever the detector scored there; context keeps its score
    assert scores.tolist() == [LABELLED_SCORE, LABELLED_SCORE, 0.6]
