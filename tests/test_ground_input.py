"""The model's ground-relative heights (issue 38): ``PillarConfig.ground = "estimated"``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from model import build_model
from model.config import ConfigError, ModelConfig, PillarConfig, build_config
from model.core.labelled import LabelledBoxes
from scenes.geometry.calib import sensor_to_lidar
from scenes.geometry.ground import estimate_ground, level_points, unlevel_boxes
from scenes.synth.frame import SynthSettings, synthesize


@pytest.fixture(scope="module")
def pitched_frame():
    settings = SynthSettings(seed=38, camera=None, sensor_setup="lidar-low-pitched")
    return synthesize(settings, 1, sensor_to_lidar(*settings.calibrations()))


def estimated(model):
    levelled = replace(model.cfg, pillars=replace(model.cfg.pillars, ground="estimated"))
    model.cfg = levelled
    return model


def test_the_default_is_the_sensors_origin_and_old_configs_read_so():
    assert PillarConfig().ground == "sensor"
    plain = build_config("small", grounding="referent").to_dict()
    del plain["pillars"]["ground"], plain["pillars"]["ground_height"]
    cfg = ModelConfig.from_dict(plain)
    assert cfg.pillars.ground == "sensor" and cfg.pillars.ground_height == 1.65


def test_estimated_ground_is_the_referent_paths_and_checked():
    with pytest.raises(ConfigError, match="needs grounding='referent'"):
        build_model("small", grounding="tpcnet", pillars=PillarConfig(ground="estimated"))
    with pytest.raises(ConfigError, match="ground"):
        PillarConfig(ground="tilted")


def test_the_model_sees_levelled_clouds_and_answers_in_the_sensors_frame(
    pitched_frame, untrained_model
):
    lidar, radar = pitched_frame.lidar.points, pitched_frame.radar.points
    height = PillarConfig().ground_height
    plane = estimate_ground(lidar, height)
    assert plane.a > 0.03  # pitched 2 degrees nose down: the ground rises ahead
    plain = untrained_model("referent", text_encoder="gru")
    expected = plain.encode_scene(
        level_points(lidar, plane, height), level_points(radar, plane, height)
    )
    model = estimated(untrained_model("referent", text_encoder="gru"))
    got = model.encode_scene(lidar, radar)
    assert len(got.objects) == len(expected.objects) > 0
    np.testing.assert_allclose(
        got.objects.boxes, unlevel_boxes(expected.objects.boxes, plane, height)
    )
    np.testing.assert_array_equal(got.objects.labels, expected.objects.labels)
    np.testing.assert_allclose(got.objects.scores, expected.objects.scores)
    answer = model.ground(got, "the cyclists", score_threshold=0.0)
    assert {tuple(b) for b in np.round(answer.boxes, 9)} <= {
        tuple(b) for b in np.round(got.objects.boxes, 9)
    }


def test_labelled_boxes_come_back_as_given(pitched_frame, untrained_model):
    model = estimated(untrained_model("referent", text_encoder="gru"))
    actors = pitched_frame.world.actors[:4]
    boxes = np.array([a.box for a in actors])
    labelled = LabelledBoxes(boxes, np.array([0, 1, 2, 0][: len(boxes)]))
    features = model.encode_scene(
        pitched_frame.lidar.points, pitched_frame.radar.points, candidates=labelled
    )
    answer = model.ground(features, "the cars", score_threshold=0.0)
    assert len(answer.boxes) > 0
    for box in answer.boxes:
        assert np.abs(boxes - box).max(axis=1).min() < 1e-9
