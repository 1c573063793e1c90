"""scenes.geometry.ground: the ground plane estimated from a LiDAR cloud, heights above it."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.geometry.ground import estimate_ground, level_clouds, level_points, unlevel_boxes
from scenes.synth.lidar import pitch_rotation


def ground_cloud(height: float, pitch_deg: float, seed: int = 0) -> np.ndarray:
    """A flat ground ``height`` below a sensor pitched ``pitch_deg`` nose down, with boxes of
    points standing on it (objects), in the sensor's frame: ``(N, 4)``."""
    rng = np.random.default_rng(seed)
    ground = np.c_[rng.uniform(0, 40, 20000), rng.uniform(-20, 20, 20000), np.full(20000, -height)]
    ground[:, 2] += rng.normal(0, 0.02, len(ground))
    objects = np.c_[
        rng.uniform(5, 25, 3000), rng.uniform(-8, 8, 3000), rng.uniform(-height, 0.5, 3000)
    ]
    level = np.r_[ground, objects]
    sensor = level @ pitch_rotation(pitch_deg)  # level -> sensor frame (R^T p, row-wise)
    return np.c_[sensor, rng.uniform(0, 255, len(sensor))].astype(np.float32)


@pytest.mark.parametrize(("height", "pitch"), [(1.7, 0.0), (1.4, 2.0), (1.84, -1.0)])
def test_the_plane_of_a_lowered_or_pitched_sensor_is_found(height, pitch):
    plane = estimate_ground(ground_cloud(height, pitch), 1.7)
    assert plane.cells > 100
    assert plane.a == pytest.approx(np.tan(np.radians(pitch)), abs=0.003)
    assert plane.b == pytest.approx(0.0, abs=0.003)
    assert plane.c == pytest.approx(-height / np.cos(np.radians(pitch)), abs=0.03)


def test_levelled_points_put_the_ground_at_the_reference_height_and_boxes_go_back():
    cloud = ground_cloud(1.4, 2.0)
    plane = estimate_ground(cloud, 1.7)
    level = level_points(cloud, plane, 1.7)
    assert level.dtype == cloud.dtype and np.array_equal(level[:, [0, 1, 3]], cloud[:, [0, 1, 3]])
    assert np.median(level[:20000, 2]) == pytest.approx(-1.7, abs=0.02)
    boxes = np.array([[10.0, 2.0, -0.8, 4, 2, 1.5, 0.3], [25.0, -3.0, -0.9, 0.6, 0.6, 1.7, 0.0]])
    back = unlevel_boxes(boxes, plane, 1.7)
    np.testing.assert_allclose(level_points(back, plane, 1.7), boxes)
    np.testing.assert_array_equal(back[:, [0, 1, 3, 4, 5, 6]], boxes[:, [0, 1, 3, 4, 5, 6]])


def test_level_clouds_levels_both_clouds_on_the_lidars_ground():
    cloud = ground_cloud(1.4, 2.0)
    radar = np.c_[cloud[:50, :3], np.ones((50, 4))].astype(np.float32)
    plane, lidar, levelled = level_clouds(cloud, radar, 1.7)
    assert plane == estimate_ground(cloud, 1.7)
    np.testing.assert_array_equal(lidar, level_points(cloud, plane, 1.7))
    np.testing.assert_array_equal(levelled, level_points(radar, plane, 1.7))
    assert level_clouds(cloud, None, 1.7)[2] is None


def test_too_few_points_give_the_level_reference_plane():
    plane = estimate_ground(np.zeros((0, 4), np.float32), 1.7)
    assert (plane.a, plane.b, plane.c, plane.cells) == (0.0, 0.0, -1.7, 0)
    assert estimate_ground(np.array([[5.0, 0.0, -1.0, 1.0]]), 1.5).c == -1.5
