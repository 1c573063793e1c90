"""Issue 38's held-out sensor set-ups and sensor randomisation (scenes.synth.setups,
scenes.synth.randomise, scenes.synth.world.street)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from scenes.geometry.calib import LIDAR_HEIGHT, RADAR_IN_LIDAR, sensor_to_lidar
from scenes.synth.frame import SynthError, SynthSettings, synthesize
from scenes.synth.generate import generate_root, main
from scenes.synth.lidar import LidarConfig, pitch_rotation, ray_directions
from scenes.synth.randomise import DEFAULT_RANDOMISATION, sensor_stream
from scenes.synth.setups import HELD_OUT, IN_DOMAIN, SETUPS, lidar_calibration_at
from scenes.talk2radar.layout import meta_dir, meta_file
from scenes.talk2radar.root import Talk2RadarRoot

WORLD = 3


def sense(name: str, world: int = WORLD, **settings):
    s = SynthSettings(seed=5, camera=None, sensor_setup=name, **settings)
    lidar, radar = s.calibrations()
    return synthesize(s, world, sensor_to_lidar(lidar, radar))


@pytest.fixture(scope="module")
def in_domain():
    return sense(IN_DOMAIN.name)


@pytest.mark.parametrize("name", [s.name for s in HELD_OUT])
def test_every_held_out_setup_renders_the_same_actors(name, in_domain):
    frame = sense(name)
    setup = SETUPS[name]
    assert len(frame.lidar.points) > 10_000 and len(frame.radar.points) > 20
    assert frame.setup is not None and frame.setup.name == name
    base = np.array([a.box for a in in_domain.world.actors])
    got = np.array([a.box for a in frame.world.actors])
    assert got.shape == base.shape
    np.testing.assert_allclose(got[:, [0, 1, 3, 4, 5, 6]], base[:, [0, 1, 3, 4, 5, 6]])
    # The world stands on the ground below this rig's LiDAR.
    np.testing.assert_allclose(got[:, 2] - base[:, 2], LIDAR_HEIGHT - setup.lidar_height, atol=1e-9)


def test_the_128_beam_lidar_casts_twice_the_rays_of_the_hdl64():
    lidar128 = SETUPS["lidar-128"].lidar
    assert lidar128.beams == 128 and LidarConfig().beams == 64
    assert len(ray_directions(lidar128)) == 2 * len(ray_directions(LidarConfig()))
    elevation = np.degrees(np.arcsin(ray_directions(lidar128)[:, 2]))
    assert elevation.max() == pytest.approx(15.0) and elevation.min() == pytest.approx(-25.0)


def _road_z(frame) -> float:
    """Median z of the static returns 8-12 m ahead within 1.5 m of the LiDAR's axis (road)."""
    p, owner = frame.lidar.points, frame.lidar.owner
    near = (owner == -1) & (p[:, 0] > 8) & (p[:, 0] < 12) & (np.abs(p[:, 1]) < 1.5)
    assert near.sum() > 50
    return float(np.median(p[near, 2])), float(np.median(p[near, 0]))


def test_the_lowered_pitched_mount_moves_the_ground_points(in_domain):
    z0, _ = _road_z(in_domain)
    assert z0 == pytest.approx(-LIDAR_HEIGHT, abs=0.08)
    z, x = _road_z(sense("lidar-low-pitched"))
    # 0.3 m lower, pitched 2 degrees nose down: the level ground at 1.40 m below, seen in the
    # sensor's pitched frame, rises ahead of it.
    expected = (pitch_rotation(2.0).T @ np.array([x / np.cos(np.radians(2)), 0.0, -1.40]))[2]
    assert z == pytest.approx(expected, abs=0.1)
    assert z > z0 + 0.5


def test_the_lowered_lidar_keeps_radar_and_camera_on_the_car():
    settings = SynthSettings(camera=None, sensor_setup="lidar-low-pitched")
    lidar, radar = settings.calibrations()
    assert np.allclose(
        radar.Tr_velo_to_cam, SynthSettings(camera=None).calibrations()[1].Tr_velo_to_cam
    )
    origin = sensor_to_lidar(lidar, radar)[:3, 3]
    np.testing.assert_allclose(origin, np.add(RADAR_IN_LIDAR, (0.0, 0.0, 0.3)), atol=0.02)
    base = SynthSettings(camera=None).calibrations()[0]
    assert lidar_calibration_at(base, LIDAR_HEIGHT) is base


@pytest.mark.parametrize(("name", "scale"), [("intensity-x0.5", 0.5), ("intensity-x2", 2.0)])
def test_intensity_is_scaled(name, scale, in_domain):
    frame = sense(name)
    base = in_domain.lidar.points
    got = frame.lidar.points
    np.testing.assert_array_equal(got[:, :3], base[:, :3])  # same rays, same draws
    raw = base[:, 3]
    ok = (raw < 254.0) & (raw * scale < 254.0)
    assert ok.sum() > 1000
    np.testing.assert_allclose(got[ok, 3], raw[ok] * scale, rtol=1e-5)


def test_single_scan_radar_has_one_scan_index_and_writes_the_radar_tree(tmp_path):
    frame = sense("radar-1scan")
    assert set(np.unique(frame.radar.points[:, 6])) == {0.0}
    assert SynthSettings(sensor_setup="radar-1scan").radar_scans == 1
    generate_root(tmp_path, 2, SynthSettings(seed=5, camera=None, sensor_setup="radar-1scan"))
    root = Talk2RadarRoot(tmp_path)
    assert root.radar_folder == "radar"
    sid = root.ids("train")[0] if root.ids("train") else root.ids("test")[0]
    meta = json.loads(meta_file(tmp_path, sid).read_text())
    assert meta["radar_scans"] == 1 and meta["extra"]["sensor_setup"]["name"] == "radar-1scan"


def test_sparse_radar_is_the_merged_2d_radars(in_domain):
    frame = sense("radar-sparse")
    assert len(frame.radar.points) < 0.7 * len(in_domain.radar.points)
    np.testing.assert_array_equal(frame.lidar.points, in_domain.lidar.points)


def test_street_densities_keep_the_actors_and_change_the_roadside(in_domain):
    faces = len(in_domain.world.static_mesh.faces)
    sparse, dense = sense("streets-sparse"), sense("streets-dense")
    assert len(sparse.world.static_mesh.faces) < 0.8 * faces
    assert len(dense.world.static_mesh.faces) > 1.3 * faces
    assert len(dense.world.clutter) > len(in_domain.world.clutter) > len(sparse.world.clutter)
    # Nothing added stands in an actor: no static LiDAR return inside an actor's box.
    for actor in dense.world.actors:
        x, y, z, length, width, height, yaw = actor.box
        p = dense.lidar.points[dense.lidar.owner == -1, :3] - [x, y, z]
        c, s = np.cos(-yaw), np.sin(-yaw)
        u, v = c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]
        inside = (abs(u) < length / 2 - 0.05) & (abs(v) < width / 2 - 0.05)
        inside &= abs(p[:, 2]) < height / 2 - 0.05
        assert inside.sum() == 0, actor


def test_randomised_rigs_stay_in_their_ranges_and_off_the_held_out_values():
    r = DEFAULT_RANDOMISATION
    rigs = [r.draw(sensor_stream(1, i), 5) for i in range(150)]
    beams = {rig.lidar.beams for rig in rigs}
    assert beams <= set(r.beams) and not beams & {32, 128} and len(beams) > 3
    for rig in rigs:
        lid = rig.lidar
        assert r.height[0] <= rig.lidar_height <= r.height[1]
        assert r.pitch_deg[0] <= lid.pitch_deg <= r.pitch_deg[1]
        assert r.intensity_scale[0] <= lid.intensity_scale <= r.intensity_scale[1]
        assert r.top_deg[0] <= lid.upper_block[0] <= r.top_deg[1]
        assert r.bottom_deg[0] <= lid.lower_block[1] <= r.bottom_deg[1]
        assert lid.upper_block[1] > lid.lower_block[0]
        assert r.azimuth_step_deg[0] <= lid.azimuth_step_deg <= r.azimuth_step_deg[1]
        assert 0 <= lid.beam_dropout <= r.beam_dropout[1] and 0 <= lid.dropout <= r.dropout[1]
        assert 2 <= rig.radar_scans <= 5
        assert r.static_prob_scale[0] <= rig.radar.static_prob_scale <= r.static_prob_scale[1]
    held = {(s.lidar_height, s.lidar.pitch_deg, s.lidar.intensity_scale) for s in HELD_OUT}
    for height, pitch, scale in held:
        if height != LIDAR_HEIGHT:
            assert not r.height[0] <= height <= r.height[1]
        if pitch:
            assert not r.pitch_deg[0] <= pitch <= r.pitch_deg[1]
        if scale != 1.0:
            assert not r.intensity_scale[0] <= scale <= r.intensity_scale[1]
    assert r.draw(sensor_stream(1, 7), 3).radar_scans <= 3


def test_randomisation_is_deterministic_per_seed_and_world_and_keeps_the_worlds():
    s = SynthSettings(seed=4, camera=None, sensor_randomise=True)
    assert s.world_setup(2) == SynthSettings(
        seed=4, camera=None, sensor_randomise=True
    ).world_setup(2)
    assert s.world_setup(2) != s.world_setup(3)
    assert s.world_setup(2) != replace(s, seed=5).world_setup(2)
    rig = s.world_setup(2)
    frame = synthesize(s, 2, sensor_to_lidar(*s.calibrations(rig)))
    base = SynthSettings(seed=4, camera=None)
    ref = synthesize(base, 2, sensor_to_lidar(*base.calibrations()))
    a = np.array([x.box for x in frame.world.actors])
    b = np.array([x.box for x in ref.world.actors])
    np.testing.assert_allclose(a[:, :2], b[:, :2])
    np.testing.assert_allclose(a[:, 2] - b[:, 2], LIDAR_HEIGHT - rig.lidar_height, atol=1e-9)


def test_a_randomised_root_records_each_worlds_rig(tmp_path):
    generate_root(tmp_path, 4, SynthSettings(seed=2, camera=None, sensor_randomise=True))
    metas = [json.loads(p.read_text()) for p in sorted(meta_dir(tmp_path).glob("*.json"))]
    rigs = {json.dumps(m["extra"]["sensor_setup"], sort_keys=True) for m in metas}
    assert len(rigs) >= 2
    root = Talk2RadarRoot(tmp_path)
    heights = set()
    for m, sid in zip(
        metas,
        sorted(p.stem for p in meta_dir(tmp_path).glob("*.json")),
        strict=True,
    ):
        assert m["extra"]["sensor_setup"]["name"] == "randomised"
        heights.add(round(float(root.load(sid).calib.Tr_velo_to_cam[1, 3]), 4))
    assert len(heights) >= 2  # each world's LiDAR calibration at its own height


def test_contradicting_rig_options_are_one_line_errors(tmp_path, capsys):
    with pytest.raises(SynthError, match="vod sensors only"):
        SynthSettings(sensors="nuscenes", sensor_setup="lidar-128")
    with pytest.raises(SynthError, match="exclude each other"):
        SynthSettings(sensor_setup="lidar-128", sensor_randomise=True)
    with pytest.raises(SynthError, match="one radar scan"):
        SynthSettings(sensor_setup="radar-1scan", radar_scans=3)
    code = main(
        [
            "--out",
            str(tmp_path / "r"),
            "--frames",
            "1",
            "--sensor-randomise",
            "--radar-scans",
            "1",
            "--quiet",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--radar-scans 3 or 5" in err


def test_a_pitched_lidars_targets_are_the_boxes_in_its_own_frame():
    boxes = np.array([[20.0, 1.0, -0.85, 4.0, 1.8, 1.5, 0.4]])
    pitched = SETUPS["lidar-low-pitched"].boxes_in_lidar_frame(boxes)
    s, c = np.sin(np.radians(2.0)), np.cos(np.radians(2.0))
    np.testing.assert_allclose(pitched[0, :3], [20.0 * c + 0.85 * s, 1.0, 20.0 * s - 0.85 * c])
    np.testing.assert_array_equal(pitched[0, 3:], boxes[0, 3:])
    np.testing.assert_array_equal(SETUPS["lidar-128"].boxes_in_lidar_frame(boxes), boxes)
