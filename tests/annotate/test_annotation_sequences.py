"""Sequences (issue 19.3): pose files (scenes.talk2radar.poses), the generator's ``--sequence-length``
(scenes.synth, scenes.synth.sequence), the drives of a split (scenes.talk2radar.drives) and carrying boxes to the
next frame (annotate.carry)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from annotate.carry import CarryConfig, carry_boxes, speed_known
from scenes.frame import RootError
from scenes.geometry.calib import sensor_to_lidar, vod_lidar_calibration
from scenes.synth.generate import SynthSettings, generate_root, synthesize
from scenes.talk2radar.drives import find_drives
from scenes.talk2radar.poses import (
    FRAME_RATE,
    consecutive,
    lidar_motion,
    parse_pose,
    read_pose,
    synthetic_pose,
)
from scenes.talk2radar.root import Talk2RadarRoot

pytestmark = pytest.mark.serial  # the drive plays at 10 Hz


def test_pose_files_round_trip_and_name_the_bad_line(tmp_path) -> None:
    calib = vod_lidar_calibration()
    pose = synthetic_pose(3.5, calib, (500_000.0, 5_760_000.0))
    back = parse_pose(pose.to_text())
    for a, b in ((pose.odom, back.odom), (pose.map, back.map), (pose.utm, back.utm)):
        np.testing.assert_allclose(a, b)
    assert pose.to_text().splitlines()[0].startswith('{"odomToCamera": [')
    lines = pose.to_text().splitlines()
    with pytest.raises(RootError, match=r"p\.json:2: mapToCamera must hold 16 numbers"):
        parse_pose("\n".join([lines[0], '{"mapToCamera": [1, 2]}', lines[2]]), "p.json")
    with pytest.raises(RootError, match="no UTMToCamera line"):
        parse_pose("\n".join(lines[:2]), "p.json")
    assert read_pose(tmp_path, 7) is None  # no pose file


def test_lidar_motion_and_consecutive_frames() -> None:
    calib = vod_lidar_calibration()
    a = synthetic_pose(0.0, calib, (500_000.0, 0.0))
    b = synthetic_pose(1.2, calib, (500_000.0, 0.0))
    motion = lidar_motion(a, b, calib)  # a point 10 m ahead is 8.8 m ahead a frame later
    np.testing.assert_allclose(motion @ [10.0, 2.0, -1.0, 1.0], [8.8, 2.0, -1.0, 1.0], atol=1e-9)
    assert consecutive(a, b)
    assert not consecutive(a, synthetic_pose(0.0, calib, (501_000.0, 0.0)))  # another drive


@pytest.fixture(scope="module")
def sequence_root(tmp_path_factory):
    """Two worlds of three consecutive frames, one prompt per frame, no camera."""
    path = tmp_path_factory.mktemp("sequences") / "root"
    settings = SynthSettings(seed=3, prompts_per_world=1, camera=None, sequence_length=3)
    generate_root(path, 6, settings, split_fractions=(0.5, 0.0, 0.5))
    return path, settings


def test_a_sequence_root_has_moving_actors_poses_and_drives(sequence_root) -> None:
    path, settings = sequence_root
    root = Talk2RadarRoot(path)
    ids = sorted(sid for split in root.splits() for sid in root.ids(split))
    assert ids == [f"{i:05d}" for i in range(6)]
    for sid in ids:
        assert read_pose(root.radar_dir, sid) is not None  # both trees, as VoD
    drives = find_drives(root, ids)
    assert [len(d) for d in drives.drives] == [3, 3]
    first, third = root.load("00000"), root.load("00002")
    dt = 2 / FRAME_RATE
    ego = first.meta.ego_velocity
    by_id = {a.actor_id: a for a in third.meta.actors}
    for actor in first.meta.actors:  # moved by its velocity, less the ego's travel
        expected = actor.box[:2] + actor.velocity * dt - [ego * dt, 0.0]
        np.testing.assert_allclose(by_id[actor.actor_id].box[:2], expected, atol=1e-9)
    motion = lidar_motion(
        read_pose(root.lidar_dir, "00000"), read_pose(root.lidar_dir, "00002"), first.calib
    )
    np.testing.assert_allclose(motion[:3, 3], [-ego * dt, 0.0, 0.0], atol=1e-9)
    # Frame 0 of a sequence is the frame a single-frame root writes.
    lidar_calib, radar_calib = settings.calibrations()
    single = synthesize(
        SynthSettings(seed=3, prompts_per_world=1, camera=None),
        0,
        sensor_to_lidar(lidar_calib, radar_calib),
        lidar_calib,
    )
    np.testing.assert_allclose(first.lidar, single.lidar.points, atol=1e-5)


def _radar_in(box, v_r: float, n: int = 6) -> np.ndarray:
    """``n`` radar points at a box's centre with compensated radial velocity ``v_r``."""
    pts = np.zeros((n, 7))
    pts[:, :3] = np.asarray(box[:3]) + np.linspace(-0.2, 0.2, n)[:, None] * [1, 1, 0]
    pts[:, 5] = v_r
    return pts


def test_carry_moves_by_radar_speed_and_ego_motion_and_refits_only_unknown_speeds() -> None:
    calib = vod_lidar_calibration()
    motion = lidar_motion(
        synthetic_pose(0.0, calib, (0, 0)), synthetic_pose(1.0, calib, (0, 0)), calib
    )
    away = np.array([20.0, 0.0, -0.95, 4.2, 1.8, 1.5, 0.0])  # heading +x, moving away at 5 m/s
    parked = np.array([15.0, 6.0, -0.95, 4.2, 1.8, 1.5, 0.0])  # no radar point
    radar = _radar_in(away, 5.0)
    carried = carry_boxes(np.stack([away, parked]), ["Car", "Car"], radar, motion, 0.1, None)
    np.testing.assert_allclose(carried[0].box[:2], [19.5, 0.0], atol=1e-9)  # +0.5 m, ego -1 m
    np.testing.assert_allclose(carried[1].box[:2], [14.0, 6.0], atol=1e-9)  # ego motion only
    assert carried[0].radar_points == 6 and carried[1].radar_points == 0
    assert speed_known(away, 6) and not speed_known(parked, 0)
    crossing = np.array([20.0, 0.0, -0.95, 4.2, 1.8, 1.5, np.pi / 2])  # heading across the view
    assert not speed_known(crossing, 6)

    # The parked car's points in the next frame sit 0.4 m further left than the moved box.
    rng = np.random.default_rng(0)
    target = np.array([14.0, 6.4, -0.95, 4.2, 1.8, 1.5, 0.0])
    car = rng.uniform(target[:3] - target[3:6] / 2, target[:3] + target[3:6] / 2, (800, 3))
    ground = np.c_[rng.uniform([5, -10], [30, 12], (3000, 2)), np.full(3000, -1.7)]
    lidar = np.r_[car, ground]
    refit = carry_boxes(parked[None], ["Car"], radar, motion, 0.1, lidar)[0]
    assert refit.refit and np.hypot(*(refit.box[:2] - target[:2])) < 0.15
    np.testing.assert_allclose(refit.box[3:6], parked[3:6])  # the size is kept
    never = carry_boxes(
        parked[None], ["Car"], radar, motion, 0.1, lidar, CarryConfig(refit="never")
    )
    assert not never[0].refit
    # A box whose speed the radar tells is not refit by default.
    assert not carry_boxes(away[None], ["Car"], radar, motion, 0.1, lidar)[0].refit


def test_a_step_by_hand_pauses_the_drive(
    sequence_root, ws_client, torch_threads, serve_app, untrained_model, monkeypatch
) -> None:
    """Page Up / Previous while the drive plays pauses it: the player cannot step over the
    frame the person chose (it did, and the browser test saw the drive end on its last frame)."""
    import app.annotate_tab.sequence as sequence

    monkeypatch.setattr(sequence, "FRAME_RATE", 2.0)  # a step every 0.5 s: room to step between
    root, _ = sequence_root
    with torch_threads(1):
        model = untrained_model("tpcnet", text_encoder="gru")
        with serve_app(root, model) as app:
            client = ws_client(app.port)
            client.pump_until(
                lambda: any("of this drive" in m for m in client.markdown.values()),
                15,
                "the Sequence folder",
            )
            start = app.frame.index
            client.click("Play")
            client.pump_until(lambda: app.frame.index == start + 1, 15, "the drive playing")
            client.click("Drive", "Previous")
            client.pump_until(lambda: app.frame.index == start, 15, "the step back")
            client.drain(1.5)  # the player would have stepped twice by now
            assert app.frame.index == start
            assert not any(t.name == "talk2pc-play" for t in threading.enumerate())
            client.close()
