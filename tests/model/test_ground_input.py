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
    assert not cfg.pillars.levels_on_ground
    assert PillarConfig(ground="estimated").levels_on_ground


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


def test_a_training_frame_is_levelled_as_the_model_sees_it_at_inference(pitched_frame):
    """``level_item``: both clouds and every box move by the plane under them (the ground then at
    the reference height, each actor keeping its height above it); the bird's-eye view is kept."""
    from scenes.datasets.frames import FrameItem
    from scenes.datasets.levelled import level_item

    lidar, radar = pitched_frame.lidar.points, pitched_frame.radar.points
    actors = tuple(pitched_frame.world.actors)
    ignore = np.array([a.box for a in actors[:2]])
    item = FrameItem("00001", lidar, radar, actors, ignore_boxes=ignore)
    height = PillarConfig().ground_height
    plane = estimate_ground(lidar, height)
    got = level_item(item, height)
    np.testing.assert_allclose(got.lidar, level_points(lidar, plane, height))
    np.testing.assert_allclose(got.radar, level_points(radar, plane, height))
    np.testing.assert_allclose(got.ignore_boxes, level_points(ignore, plane, height))
    for before, after in zip(actors, got.actors, strict=True):
        np.testing.assert_array_equal(after.box[[0, 1, 3, 4, 5, 6]], before.box[[0, 1, 3, 4, 5, 6]])
        above = before.box[2] - plane.height_at(before.box[None, :2])[0]
        assert after.box[2] == pytest.approx(above - height)
        assert (after.cls, after.actor_id) == (before.cls, before.actor_id)
    assert estimate_ground(got.lidar, height).a == pytest.approx(0.0, abs=2e-3)


def test_training_levels_frames_only_for_a_ground_estimating_model(pitched_frame, untrained_model):
    from model.training.referent_step import model_frame
    from scenes.datasets.frames import FrameItem

    item = FrameItem(
        "00001",
        pitched_frame.lidar.points,
        pitched_frame.radar.points,
        tuple(pitched_frame.world.actors),
    )
    plain = untrained_model("referent", text_encoder="gru")
    assert model_frame(plain, item) is item
    levelled = model_frame(estimated(untrained_model("referent", text_encoder="gru")), item)
    assert not np.array_equal(levelled.lidar[:, 2], item.lidar[:, 2])


def test_a_run_takes_its_start_checkpoints_ground_unless_told(tmp_path, write_tiny_root):
    """``--ground`` builds the model so; without it the ``--init-detector`` / ``--init``
    checkpoint's ground carries over (how that detector sees heights) to a model of its grounding
    kind, else the sensor's."""
    import torch

    from model.checkpoint import load_checkpoint, save_checkpoint
    from model.training.config import TrainConfig
    from model.training.start import start_model

    shipped = load_checkpoint("checkpoints/tpcnet-small.pt")
    levelled = save_checkpoint(tmp_path / "levelled.pt", estimated(shipped))
    root = str(write_tiny_root(tmp_path / "t2r"))

    def ground(**flags) -> str:
        cfg = TrainConfig(data=(root,), out=str(tmp_path / "run"), **flags)
        return start_model(cfg, False, 0, 1, torch.device("cpu"))[0].cfg.pillars.ground

    assert ground(init_detector=str(levelled)) == "estimated"
    assert ground(init=str(levelled)) == "estimated"
    assert ground(init=str(levelled), ground="sensor") == "sensor"
    # a checkpoint of the other grounding kind lends no ground (the paper's path has none)
    assert ground(init=str(levelled), grounding="tpcnet") == "sensor"
    assert ground(ground="estimated") == "estimated"
    assert ground() == "sensor"


def test_adaptation_frames_are_levelled_for_a_ground_estimating_checkpoint(tmp_path):
    from model.adapt.frames import UnlabelledFrames
    from scenes.synth.generate import generate_root

    root = tmp_path / "r"
    generate_root(root, 2, SynthSettings(seed=38, camera=None, sensor_setup="lidar-low-pitched"))
    plain = UnlabelledFrames(root)[0]
    got = UnlabelledFrames(root, ground_height=1.65)[0]
    plane = estimate_ground(plain.lidar, 1.65)
    np.testing.assert_allclose(got.lidar, level_points(plain.lidar, plane, 1.65))
    np.testing.assert_allclose(got.radar, level_points(plain.radar, plane, 1.65))
