"""The generator's nuScenes-like sensor set (issue 40 item 5, ``--sensors nuscenes``).

The default (``vod``) output's hash is checked in tests/scenes/language/test_commands.py; here: the preset's LiDAR
(32 beams, +10.67 to -30.67 degrees, 1.84 m up), the five sparse 2D radars merged in the LiDAR
frame, the 1600 x 900 CAM_FRONT, and a root that today's reader opens, with the set in its sidecar.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenes.geometry.calib import sensor_to_lidar
from scenes.synth.frame import SynthError, SynthSettings
from scenes.synth.generate import main as synth_main
from scenes.synth.lidar import beam_elevations
from scenes.synth.sensors import NUSCENES, sensor_set
from scenes.talk2radar.root import Talk2RadarRoot


def test_the_preset_is_shaped_as_nuscenes_sensors():
    el = beam_elevations(NUSCENES.lidar)
    assert len(el) == 32
    assert el.max() == pytest.approx(10.67) and el.min() == pytest.approx(-30.67)
    assert np.allclose(np.diff(el), -4.0 / 3.0, atol=0.01)  # evenly spaced, as the HDL-32E
    assert NUSCENES.lidar_height == pytest.approx(1.84) and NUSCENES.lidar_spin_hz == 20.0
    channels = {m.channel for m in NUSCENES.radars}
    assert channels == {
        "RADAR_FRONT",
        "RADAR_FRONT_LEFT",
        "RADAR_FRONT_RIGHT",
        "RADAR_BACK_LEFT",
        "RADAR_BACK_RIGHT",
    }
    front = [m.config for m in NUSCENES.radars if m.channel == "RADAR_FRONT"]
    assert sorted(c.azimuth_half_fov_deg for c in front) == [9.0, 60.0]  # far and near fields
    assert all(not m.config.measures_elevation for m in NUSCENES.radars)
    assert NUSCENES.image_size == (1600, 900)
    calib = NUSCENES.calibration()
    assert calib.P2[0, 0] == pytest.approx(1266.4, abs=1) and calib.P2[1, 1] == calib.P2[0, 0]
    assert calib.P2[0, 2] == pytest.approx(816, abs=1) and calib.P2[1, 2] == pytest.approx(
        491, abs=1
    )
    assert sensor_set("vod") is None
    with pytest.raises(ValueError, match="sensors"):
        sensor_set("kitti")
    with pytest.raises(SynthError, match="sensors"):
        SynthSettings(sensors="kitti")


def test_settings_take_the_presets_lidar_height_and_camera():
    s = SynthSettings(sensors="nuscenes")
    assert s.lidar == NUSCENES.lidar and s.world.lidar_height == pytest.approx(1.84)
    assert s.camera is not None and s.camera.image_size == (1600, 900)
    assert s.key()["sensors"] == "nuscenes" and "sensors" not in SynthSettings().key()
    lidar, radar = s.calibrations()
    assert np.allclose(sensor_to_lidar(lidar, radar), np.eye(4))  # radar cloud in the LiDAR frame
    with pytest.raises(SynthError, match="1600 x 900"):
        synth_settings_with_scale(0.125)


def synth_settings_with_scale(scale: float) -> SynthSettings:
    from scenes.synth.camera import CameraConfig

    return SynthSettings(sensors="nuscenes", camera=CameraConfig(image_scale=scale, ray_step=1))


@pytest.fixture(scope="module")
def nusc_root(tmp_path_factory):
    out = tmp_path_factory.mktemp("nusc") / "root"
    args = ["--out", str(out), "--frames", "4", "--prompts-per-world", "1", "--seed", "5"]
    args += ["--sensors", "nuscenes", "--camera-scale", "0.25", "--camera-ray-step", "1", "--quiet"]
    assert synth_main(args) == 0
    return Talk2RadarRoot(out)


def _samples(root: Talk2RadarRoot):
    ids = [i for split in ("train", "val", "test") for i in root.ids(split)]
    assert len(ids) == 4
    return [(i, root.load(i)) for i in ids]


def test_lidar_beams_elevations_and_mounting_height(nusc_root):
    for _, s in _samples(nusc_root):
        xyz = s.lidar[:, :3].astype(np.float64)
        el = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
        assert el.min() > -30.8 and el.max() < 10.8
        beams = np.unique(np.round((10.67 - el) / (4.0 / 3.0)))
        assert 28 <= len(beams) <= 32
        ground = xyz[(np.hypot(xyz[:, 0], xyz[:, 1]) < 15.0) & (el < -15.0)]
        assert np.median(ground[:, 2]) == pytest.approx(-1.84, abs=0.1)
        assert (xyz[:, 0] < -1.0).any()  # the whole turn, not only the forward half
        assert 5_000 < len(xyz) < 40_000
        assert s.lidar[:, 3].min() >= 0.0 and s.lidar[:, 3].max() <= 255.0


def test_radars_are_sparse_2d_and_merged_in_the_lidar_frame(nusc_root):
    for sid, s in _samples(nusc_root):
        r = s.radar
        assert r.shape[1] == 7
        times = set(np.unique(r[:, 6]).tolist())
        assert times <= {0.0, -1.0, -2.0, -3.0, -4.0} and 0.0 in times
        for k in range(5):
            assert 10 <= int((r[:, 6] == -k).sum()) <= 250  # tens to a couple of hundred a sweep
        # 2D: heights near the radars' mounting (0.5-0.8 m above the ground), whatever the target.
        assert np.percentile(r[:, 2], 95) < -1.84 + 2.0 and np.percentile(r[:, 2], 5) > -1.84
        # Points all around the car: the corner radars see the sides and the back.
        assert (r[:, 0] < 0).any() and (np.abs(r[:, 1]) > 5).any()
        meta = nusc_root.load_meta(sid)
        sensors = meta.extra["sensors"]
        assert sensors["set"] == "nuscenes" and sensors["radar_frame"] == "lidar"
        assert sensors["lidar"]["beams"] == 32 and len(sensors["radars"]) == 6
        json.dumps(sensors)


def test_camera_is_cam_front_sized(nusc_root):
    for _, s in _samples(nusc_root):
        assert s.image is not None and s.image.shape == (225, 400, 3)
        assert s.calib.P2[0, 0] == pytest.approx(1266.417 / 4)
