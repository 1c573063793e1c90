"""LiDAR and radar simulation: surface points, radial velocities, ego motion, scans, weather."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scenes.geometry.actors import Actor
from scenes.geometry.calib import (
    LIDAR_HEIGHT,
    sensor_to_lidar,
    vod_lidar_calibration,
    vod_radar_calibration,
)
from scenes.synth.lidar import (
    LidarConfig,
    beam_elevations,
    intensity_response,
    ray_directions,
    simulate_lidar,
)
from scenes.synth.radar import CLUTTER, GHOST, RadarConfig, simulate_radar
from scenes.synth.weather import CLEAR, FOG, RAIN, weather_named
from scenes.synth.world import (
    REFLECTIVITY,
    Mat,
    RayCaster,
    TaggedMesh,
    World,
    box_part,
    generate_world,
)

RADAR_TO_LIDAR = sensor_to_lidar(vod_lidar_calibration(), vod_radar_calibration())
RADAR_ORIGIN = RADAR_TO_LIDAR[:3, 3]
EXACT_LIDAR = LidarConfig(range_noise=0.0, dropout=0.0, speckle=0.0)
EXACT_RADAR = RadarConfig().without_noise()
GROUND = box_part([-20.0, -60.0, -LIDAR_HEIGHT - 0.5], [150.0, 60.0, -LIDAR_HEIGHT], Mat.ASPHALT)


def _box_world(
    boxes: list[list[float]], velocities: list[list[float]], ego_speed: float = 0.0, ground=False
) -> World:
    """A world of box-shaped cars (meshes = their boxes), optionally on a ground plane."""
    actors, meshes = [], []
    for i, (box, vel) in enumerate(zip(boxes, velocities, strict=True)):
        actors.append(Actor(i, "Car", box, vel))
        half = np.asarray(box[3:6]) / 2
        meshes.append(box_part(-half, half, Mat.PAINT_LIGHT))
    static = GROUND if ground else TaggedMesh.empty()
    return World(0, None, LIDAR_HEIGHT, ego_speed, tuple(actors), static, tuple(meshes))


def _surface_distance(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Signed distance-like measure to the box surface: max over axes of |local| - half size."""
    c, s = math.cos(box[6]), math.sin(box[6])
    d = points[:, :3] - box[:3]
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)
    return np.max(np.abs(local) - box[3:6] / 2, axis=1)


# ---------------------------------------------------------------------------------------------
# LiDAR


def test_beam_layout_is_hdl64_like():
    el = beam_elevations()
    assert el.shape == (64,)
    assert el[0] == pytest.approx(2.0) and el[-1] == pytest.approx(-24.9)  # HDL-64: +2 .. -24.9
    assert np.all(np.diff(el) < 0)
    np.testing.assert_allclose(np.diff(el[:32]), -1 / 3, atol=2e-3)  # upper block: 1/3 degree
    np.testing.assert_allclose(np.diff(el[32:]), -0.5, atol=0.02)  # lower block: ~1/2 degree
    dirs = ray_directions()
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    azimuth = np.degrees(np.arctan2(dirs[:, 1], dirs[:, 0]))
    assert np.abs(azimuth).max() <= 90.0 + 1e-9  # the forward half: all of a model's grid (x >= 0)
    assert np.abs(azimuth).max() >= 90.0 - 1e-6
    step = LidarConfig().azimuth_step_deg
    assert len(dirs) == 64 * len(np.arange(-90.0, 90.0 + 1e-9, step))


def test_lidar_points_of_an_isolated_box_lie_on_its_surface():
    box = np.array([10.0, 1.0, -0.8, 4.0, 2.0, 1.6, 0.3])
    world = _box_world([box], [[0.0, 0.0]])
    exact = simulate_lidar(RayCaster(world), np.random.default_rng(0), EXACT_LIDAR)
    assert exact.points.dtype == np.float32 and exact.points.shape[1] == 4
    assert len(exact.points) > 200 and (exact.owner == 0).all()
    np.testing.assert_allclose(_surface_distance(exact.points, box), 0.0, atol=2e-5)
    # Only faces seen from the sensor: no point on the far side (local x > 0 face is hidden).
    noisy = simulate_lidar(RayCaster(world), np.random.default_rng(0))
    d = _surface_distance(noisy.points, box)
    assert np.abs(d).max() < 0.1  # 5 sigma of the 2 cm range noise
    assert 0.01 < np.std(d) < 0.03
    assert len(noisy.points) < len(exact.points)  # dropout
    assert noisy.points[:, 3].min() >= 0.0 and noisy.points[:, 3].max() <= 255.0


def test_lidar_intensity_follows_reflectivity_and_incidence():
    # Two identical boxes facing the sensor, one bright paint, one dark: the same geometry.
    bright = box_part([-1.0, -1.0, -0.75], [1.0, 1.0, 0.75], Mat.PAINT_LIGHT)
    dark = box_part([-1.0, -1.0, -0.75], [1.0, 1.0, 0.75], Mat.PAINT_DARK)
    actors = (
        Actor(0, "Car", [10.0, 3.0, -0.9, 2.0, 2.0, 1.5, 0.0], [0, 0]),
        Actor(1, "Car", [10.0, -3.0, -0.9, 2.0, 2.0, 1.5, 0.0], [0, 0]),
    )
    world = World(0, None, LIDAR_HEIGHT, 0.0, actors, TaggedMesh.empty(), (bright, dark))
    # Unit gain so that nothing saturates: 255 * (rho * (floor + (1 - floor) cos)) ** gamma.
    cfg = replace(EXACT_LIDAR, intensity_noise=0.0, intensity_gain=1.0)
    scan = simulate_lidar(RayCaster(world), np.random.default_rng(0), cfg)
    front = scan.points[:, 0] < 9.0 + 1e-4  # the faces at x = 9
    i_bright = scan.points[front & (scan.owner == 0), 3]
    i_dark = scan.points[front & (scan.owner == 1), 3]
    rho_bright, rho_dark = REFLECTIVITY[Mat.PAINT_LIGHT], REFLECTIVITY[Mat.PAINT_DARK]
    dirs = scan.points[front & (scan.owner == 0), :3]
    cos = dirs[:, 0] / np.linalg.norm(dirs, axis=1)  # direction . (-1, 0, 0) of the face at x = 9
    floor, gamma = cfg.intensity_floor, cfg.intensity_gamma
    expected = 255 * (rho_bright * (floor + (1 - floor) * cos)) ** gamma
    np.testing.assert_allclose(i_bright, expected, rtol=1e-5)
    ratio = (rho_bright / rho_dark) ** gamma
    assert i_bright.mean() / i_dark.mean() == pytest.approx(ratio, rel=0.02)
    # The default gain saturates bright paint at normal incidence, as the HDL-64 does.
    assert intensity_response(np.array([rho_bright]), np.array([1.0]), LidarConfig())[0] == 1.0
    grazing = intensity_response(np.array([rho_dark] * 2), np.array([1.0, 0.1]), LidarConfig())
    assert grazing[0] > grazing[1] > 0


def test_lidar_is_deterministic_for_a_seed():
    world = generate_world(np.random.default_rng(5), 5)
    a = simulate_lidar(RayCaster(world), np.random.default_rng(9))
    b = simulate_lidar(RayCaster(world), np.random.default_rng(9))
    c = simulate_lidar(RayCaster(world), np.random.default_rng(10))
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.points[:100], c.points[:100])


# ---------------------------------------------------------------------------------------------
# Radar


def test_radar_radial_velocity_is_the_line_of_sight_projection():
    # Car A: 20 m ahead, driving away at 5 m/s. B: a 0.4 m cube at (15, 10), velocity (-3, 4).
    boxes = [[20.0, 0.0, -0.95, 4.0, 1.8, 1.5, 0.0], [15.0, 10.0, -0.95, 0.4, 0.4, 0.4, 2.2]]
    vel = [[5.0, 0.0], [-3.0, 4.0]]
    world = _box_world(boxes, vel, ego_speed=0.0)
    scan = simulate_radar(
        RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(1), EXACT_RADAR, scans=1
    )
    pts, owner = scan.points.astype(np.float64), scan.owner
    assert set(owner.tolist()) == {0, 1}
    los = pts[:, :3] - RADAR_ORIGIN
    u = los / np.linalg.norm(los, axis=1, keepdims=True)
    expected = np.where(owner == 0, 5.0 * u[:, 0], -3.0 * u[:, 0] + 4.0 * u[:, 1])
    np.testing.assert_allclose(pts[:, 5], expected, atol=1e-4)
    np.testing.assert_allclose(pts[:, 4], pts[:, 5], atol=1e-4)  # ego at rest: v_r = v_r_comp
    # Hand numbers: car A's rear face (x = 18) seen from the radar at (2.51, 0, -1.15) is within
    # atan(1 / 15.5) of the boresight, so v_r_comp is in [5 cos(3.7 deg), 5] = [4.990, 5].
    a = pts[owner == 0, 5]
    assert a.min() > 4.98 and a.max() <= 5.0 + 1e-5
    # B: line of sight to its centre (12.49, 10, 0.2) / 16.0 -> (-3 * 12.49 + 4 * 10) / 16.0; its
    # surface is within 0.3 m of the centre (+-1.1 deg), which moves the projection by < 0.1.
    np.testing.assert_allclose(pts[owner == 1, 5], 0.158, atol=0.1)


def test_ego_motion_term_and_scan_times():
    world = generate_world(np.random.default_rng(3), 3)
    world = replace(world, ego_speed=8.0)
    for scans in (1, 3, 5):
        radar = simulate_radar(
            RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(scans), scans=scans
        )
        pts = radar.points.astype(np.float64)
        assert radar.points.dtype == np.float32 and pts.shape[1] == 7
        assert set(np.unique(pts[:, 6]).tolist()) == set(range(0, -scans, -1))
        # Scan k was taken with the radar 8 m/s * 0.1 s * k further back along x.
        origin = RADAR_ORIGIN - np.outer(-pts[:, 6] * 0.8, [1.0, 0.0, 0.0])
        los = pts[:, :3] - origin
        u_x = los[:, 0] / np.linalg.norm(los, axis=1)
        np.testing.assert_allclose(pts[:, 4] - pts[:, 5], -8.0 * u_x, atol=2e-5)
    # Static surfaces have near-zero compensated velocity, their v_r is all ego motion.
    static = (radar.owner == -1) & (np.abs(pts[:, 5]) > 0.6)
    assert static.mean() < 0.01


def test_older_scans_see_actors_where_they_were():
    box = [20.0, 0.0, -0.95, 4.0, 1.8, 1.5, 0.0]
    world = _box_world([box], [[10.0, 0.0]], ego_speed=6.0)
    radar = simulate_radar(
        RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(2), EXACT_RADAR, scans=5
    )
    pts = radar.points.astype(np.float64)
    for k in range(5):
        at_k = pts[pts[:, 6] == -k]
        shifted = np.array(box)
        shifted[0] -= 10.0 * 0.1 * k  # the car was 1 m further back per older scan
        assert len(at_k) > 0
        np.testing.assert_allclose(_surface_distance(at_k, shifted), 0.0, atol=1e-4)
        # Relative radial velocity: (10 - 6) m/s along the line of sight.
        los = at_k[:, :3] - (RADAR_ORIGIN - [0.6 * k, 0.0, 0.0])
        u_x = los[:, 0] / np.linalg.norm(los, axis=1)
        np.testing.assert_allclose(at_k[:, 4], 4.0 * u_x, atol=1e-4)
        np.testing.assert_allclose(at_k[:, 5], 10.0 * u_x, atol=1e-4)


def test_radar_noise_clutter_ghosts_and_rcs_by_class():
    world = generate_world(np.random.default_rng(6), 6)
    radar = simulate_radar(RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(0))
    assert (radar.owner == CLUTTER).sum() > 20  # ~20 per scan over 5 scans
    assert np.isfinite(radar.points).all()
    actor_pts = radar.owner >= 0
    assert actor_pts.sum() > 20 and (radar.owner == GHOST).sum() < actor_pts.sum()
    cls = np.array([world.actors[o].cls if o >= 0 else "" for o in radar.owner])
    rcs = radar.points[:, 3]
    assert (cls == "Pedestrian").sum() >= 3  # the seed is chosen so that the check below runs
    assert np.median(rcs[cls == "Car"]) > np.median(rcs[cls == "Pedestrian"]) + 5
    with pytest.raises(ValueError, match="scans"):
        simulate_radar(RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(0), scans=0)
    with pytest.raises(ValueError, match="4, 4"):
        simulate_radar(RayCaster(world), np.eye(3), np.random.default_rng(0))


def test_radar_is_deterministic_for_a_seed():
    world = generate_world(np.random.default_rng(5), 5)
    a = simulate_radar(RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(4))
    b = simulate_radar(RayCaster(world), RADAR_TO_LIDAR, np.random.default_rng(4))
    np.testing.assert_array_equal(a.points, b.points)


# ---------------------------------------------------------------------------------------------
# Weather


def test_fog_removes_far_lidar_returns_but_not_radar():
    # A near car (10 m) and far cars (30 m, 40 m), side by side so nothing occludes them.
    boxes = [
        [10.0, 0.0, -0.95, 4.0, 1.8, 1.5, 0.0],
        [30.0, 6.0, -0.95, 4.0, 1.8, 1.5, 0.0],
        [40.0, -6.0, -0.95, 4.0, 1.8, 1.5, 0.0],
    ]
    world = _box_world(boxes, [[0.0, 0.0]] * 3, ground=True)
    caster = RayCaster(world)
    lidar, radar = {}, {}
    for weather in (CLEAR, FOG):
        scan = simulate_lidar(caster, np.random.default_rng(0), weather=weather)
        lidar[weather.name] = np.bincount(scan.owner[scan.owner >= 0], minlength=3)
        counts = np.zeros(3)
        for seed in range(4):
            r = simulate_radar(caster, RADAR_TO_LIDAR, np.random.default_rng(seed), weather=weather)
            counts += np.bincount(r.owner[r.owner >= 0], minlength=3)
        radar[weather.name] = counts
    assert lidar["clear"].min() > 50
    assert lidar["fog"][0] > 0.5 * lidar["clear"][0]  # the near car is still seen
    assert lidar["fog"][1:].sum() < 0.05 * lidar["clear"][1:].sum()  # the far ones vanish
    assert radar["fog"][1:].sum() > 0.7 * radar["clear"][1:].sum()  # radar barely cares
    assert radar["clear"][1:].min() > 0


def test_weather_backscatter_and_rain():
    world = generate_world(np.random.default_rng(2), 2)
    caster = RayCaster(world)
    clear = simulate_lidar(caster, np.random.default_rng(0), weather=CLEAR)
    fog = simulate_lidar(caster, np.random.default_rng(0), weather=FOG)
    rain = simulate_lidar(caster, np.random.default_rng(0), weather=RAIN)
    assert (clear.owner == -2).sum() == 0
    scatter = fog.points[fog.owner == -2]
    assert len(scatter) > 500 and np.linalg.norm(scatter[:, :3], axis=1).max() < 40
    assert np.median(np.linalg.norm(scatter[:, :3], axis=1)) < 6

    def far(scan) -> int:
        return int((np.hypot(scan.points[:, 0], scan.points[:, 1]) > 25).sum())

    assert far(fog) < 0.02 * far(clear) < far(rain) < far(clear)
    assert weather_named("fog") is FOG
    with pytest.raises(ValueError, match="unknown weather"):
        weather_named("snow")
