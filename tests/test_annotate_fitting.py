"""The parts of annotate/ that read the sensors: box fitting, per-box evidence, prompt suggestion."""

from __future__ import annotations

import math

import numpy as np
import pytest

from annotate import (
    BoxRegion,
    DiskRegion,
    FitConfig,
    FitError,
    Motion,
    SceneObject,
    box_evidence,
    convex_hull,
    estimate_velocity,
    fit_box,
    min_area_rectangle,
    scene_actors,
    suggest_prompt,
)
from scenes import Actor
from scenes.boxes import wrap_yaw
from scenes.prompts import resolve

GROUND = -1.7
TRUE_BOX = np.array([15.0, 3.0, GROUND + 0.75, 4.5, 1.9, 1.5, 0.6])


def _surface_points(
    box: np.ndarray, rng: np.random.Generator, faces=("+x", "-x", "+y", "-y", "top"), n=300
) -> np.ndarray:
    """Points on the chosen faces of a box (local faces: +x front, +y left), LiDAR frame."""
    x, y, z, length, width, height, yaw = box
    out = []
    for face in faces:
        u = rng.uniform(-0.5, 0.5, n)
        v = rng.uniform(-0.5, 0.5, n)
        if face in ("+x", "-x"):
            local = np.c_[np.full(n, 0.5 if face == "+x" else -0.5) * length, u * width, v * height]
        elif face in ("+y", "-y"):
            local = np.c_[u * length, np.full(n, 0.5 if face == "+y" else -0.5) * width, v * height]
        else:
            local = np.c_[u * length, v * width, np.full(n, 0.5) * height]
        c, s = math.cos(yaw), math.sin(yaw)
        world = np.c_[
            local[:, 0] * c - local[:, 1] * s + x,
            local[:, 0] * s + local[:, 1] * c + y,
            local[:, 2] + z,
        ]
        out.append(world)
    return np.concatenate(out)


def _ground(rng: np.random.Generator, around: np.ndarray, exclude: np.ndarray) -> np.ndarray:
    gx, gy = np.meshgrid(np.arange(-6, 6, 0.2) + around[0], np.arange(-6, 6, 0.2) + around[1])
    pts = np.c_[gx.ravel(), gy.ravel(), GROUND + rng.normal(0, 0.01, gx.size)]
    d = pts[:, :2] - exclude[:2]
    c, s = math.cos(exclude[6]), math.sin(exclude[6])
    inside = (np.abs(d[:, 0] * c + d[:, 1] * s) <= exclude[3] / 2) & (
        np.abs(-d[:, 0] * s + d[:, 1] * c) <= exclude[4] / 2
    )
    return pts[~inside]


def _scene(rng: np.random.Generator, faces=("+x", "-x", "+y", "-y", "top")) -> np.ndarray:
    pts = np.concatenate([_surface_points(TRUE_BOX, rng, faces), _ground(rng, TRUE_BOX, TRUE_BOX)])
    return np.c_[pts, rng.uniform(0, 255, len(pts))].astype(np.float32)


def _assert_fits(box: np.ndarray, expected: np.ndarray, size_tol: float = 0.05) -> None:
    np.testing.assert_allclose(box[:2], expected[:2], atol=0.03)
    np.testing.assert_allclose(box[3:6], expected[3:6], atol=size_tol)
    assert box[2] == pytest.approx(expected[2], abs=0.03)
    # Yaw modulo pi: points cannot tell the front from the back.
    assert abs(wrap_yaw(2.0 * (box[6] - expected[6]))) / 2.0 < 0.01


# ------------------------------------------------------------------------------------------ fitting


def test_fit_recovers_a_known_box_from_a_rough_box() -> None:
    points = _scene(np.random.default_rng(0))
    rough = BoxRegion((15.2, 3.1, -1.0, 4.4, 2.0, 1.5, 0.5), margin=0.5)
    result = fit_box(points, rough)
    _assert_fits(result.box, TRUE_BOX)
    assert result.ground_z == pytest.approx(GROUND, abs=0.02)
    assert result.num_points == int(result.used.sum()) and result.used.shape == (len(points),)
    # The heading follows the rough box: the other way round gives the opposite heading.
    flipped = BoxRegion((15.2, 3.1, -1.0, 4.4, 2.0, 1.5, 0.5 + math.pi), margin=0.5)
    assert fit_box(points, flipped).box[6] == pytest.approx(wrap_yaw(0.6 + math.pi), abs=0.01)


def test_fit_from_an_l_shaped_scan_and_a_disk() -> None:
    # Seen from the ego vehicle at a corner: the rear (-x) and right (-y) faces only, no roof.
    rng = np.random.default_rng(1)
    points = _scene(rng, faces=("-x", "-y"))
    points[:, :3] += rng.normal(0, 0.01, (len(points), 3))
    result = fit_box(points, DiskRegion((15.0, 3.0), 3.5), ground_z=GROUND)
    _assert_fits(result.box, TRUE_BOX, size_tol=0.06)
    assert result.ground_z == GROUND


def test_fit_ignores_a_separate_object_in_the_region() -> None:
    rng = np.random.default_rng(2)
    # A pole about 1.9 m beside the car's rear-right corner, inside the selected disk.
    pole = np.c_[rng.normal(0.0, 0.05, (60, 2)), rng.uniform(-1.4, 1.0, 60), np.zeros(60)]
    pole[:, :2] += [13.0, -0.8]
    points = np.concatenate([_scene(rng), pole.astype(np.float32)])
    region = DiskRegion((14.5, 2.0), 4.0)
    result = fit_box(points, region, ground_z=GROUND)
    _assert_fits(result.box, TRUE_BOX)
    assert not result.used[-60:].any()
    with_pole = fit_box(points, region, ground_z=GROUND, config=FitConfig(cluster_gap=None))
    area = with_pole.box[3] * with_pole.box[4]
    assert area > TRUE_BOX[3] * TRUE_BOX[4] + 1.0  # without clustering the pole inflates the box


def test_too_few_points_is_a_clear_error() -> None:
    points = _scene(np.random.default_rng(3))
    with pytest.raises(FitError, match="no LiDAR points in the selected region"):
        fit_box(points, DiskRegion((40.0, -10.0), 1.0))
    with pytest.raises(FitError, match=r"only 0 LiDAR point\(s\) above the ground .* at least 5"):
        fit_box(points, DiskRegion((10.0, -2.0), 1.0))  # ground only
    with pytest.raises(ValueError, match="radius must be positive"):
        DiskRegion((0.0, 0.0), 0.0)


def test_min_area_rectangle_and_hull_by_hand() -> None:
    square = np.array([[0, 0], [2, 0], [2, 1], [0, 1], [1, 0.5], [1, 0]], dtype=float)
    hull = convex_hull(square)
    assert len(hull) == 4 and {tuple(p) for p in hull} == {(0, 0), (2, 0), (2, 1), (0, 1)}
    # Counter-clockwise: positive shoelace area.
    x, y = hull[:, 0], hull[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) == pytest.approx(2.0)
    rect = min_area_rectangle(square)
    assert (rect.length, rect.width, rect.yaw) == pytest.approx((2.0, 1.0, 0.0))
    np.testing.assert_allclose(rect.centre, [1.0, 0.5])
    # A rotated 3 x 1 rectangle's corners.
    a = 0.3
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    corners = np.array([[1.5, 0.5], [-1.5, 0.5], [-1.5, -0.5], [1.5, -0.5]]) @ rot.T + [5, 5]
    rect = min_area_rectangle(corners)
    assert (rect.length, rect.width, rect.yaw) == pytest.approx((3.0, 1.0, a))
    # Collinear points: a segment widened to min_size.
    seg = min_area_rectangle(np.array([[0.0, 0.0], [0.0, 2.0], [0.0, 1.0]]), min_size=0.1)
    assert (seg.length, seg.width) == pytest.approx((2.0, 0.1))
    assert seg.yaw == pytest.approx(-math.pi / 2)


# ------------------------------------------------------------------------------------------ evidence


def test_evidence_on_a_hand_built_scene() -> None:
    boxes = np.array(
        [
            [10.0, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # approaching car
            [20.0, 5.0, -1.0, 1.0, 1.0, 1.7, 0.0],  # receding
            [30.0, -4.0, -1.0, 1.0, 1.0, 1.7, 0.0],  # static
            [40.0, 0.0, -1.0, 1.0, 1.0, 1.7, 0.0],  # no radar
        ]
    )
    lidar = np.array(
        [
            [9.0, 0.5, -1.0, 10],
            [11.9, -0.9, -0.3, 10],
            [10.0, 0.0, -1.7, 10],  # on the bottom face: inside
            [12.1, 0.0, -1.0, 10],  # 0.1 m past the front: outside
            [20.0, 5.0, -1.0, 10],
            [40.0, 0.2, -0.5, 10],
        ],
        dtype=np.float32,
    )
    radar = np.zeros((7, 7), dtype=np.float32)
    radar[:, :3] = [
        [10.0, 0.0, -1.0],
        [11.0, 0.5, -1.0],
        [12.2, 0.0, -1.0],  # 0.2 m past the front: inside the 0.3 m radar margin
        [20.0, 5.2, -1.0],
        [19.8, 4.8, -1.0],
        [30.0, -4.0, -1.0],
        [30.1, -4.0, -1.0],
    ]
    radar[:, 5] = [-2.0, -3.0, -4.0, 1.0, 2.0, 0.1, -0.2]
    radar[:, 4] = 99.0  # the uncompensated column must not be used
    ev = box_evidence(boxes, lidar, radar)
    assert [e.lidar_points for e in ev] == [3, 1, 0, 1]
    assert [e.radar_points for e in ev] == [3, 2, 2, 0]
    assert ev[0].mean_radial_velocity == pytest.approx(-3.0)
    assert ev[1].mean_radial_velocity == pytest.approx(1.5)
    assert ev[2].mean_radial_velocity == pytest.approx(-0.05)
    assert ev[3].mean_radial_velocity is None
    assert [e.motion for e in ev] == [
        Motion.APPROACHING,
        Motion.RECEDING,
        Motion.STATIC,
        Motion.UNKNOWN,
    ]
    assert ev[0].distance == pytest.approx(10.0) and ev[0].depth == pytest.approx(8.0)
    assert ev[1].distance == pytest.approx(math.hypot(20.0, 5.0)) and ev[1].depth == 19.5
    assert box_evidence(np.zeros((0, 7)), lidar, radar) == ()


def test_velocity_from_radial_velocity() -> None:
    ahead = np.array([10.0, 0.0, -1.0, 4.0, 2.0, 1.5, math.pi])  # facing us
    np.testing.assert_allclose(estimate_velocity(ahead, -3.0), [-3.0, 0.0], atol=1e-12)
    diagonal = np.array([10.0, 10.0, -1.0, 4.0, 2.0, 1.5, 0.0])  # heading +x, 45 deg off the LoS
    v = estimate_velocity(diagonal, 2.0)
    np.testing.assert_allclose(v, [2.0 * math.sqrt(2.0), 0.0])
    crossing = np.array([10.0, 0.0, -1.0, 4.0, 2.0, 1.5, math.pi / 2])
    np.testing.assert_allclose(estimate_velocity(crossing, 0.8), [0.8, 0.0])
    np.testing.assert_allclose(estimate_velocity(ahead, None), [0.0, 0.0])


# ------------------------------------------------------------------------------------------ suggestion


def _radar_in(box: np.ndarray, v: float, n: int = 4) -> np.ndarray:
    pts = np.zeros((n, 7))
    pts[:, :3] = box[:3] + np.linspace(-0.3, 0.3, n)[:, None] * [1, 0, 0]
    pts[:, 5] = v
    return pts


def test_suggestion_refers_exactly_to_the_draft_boxes() -> None:
    moving = np.array([15.0, 3.0, -0.95, 4.2, 1.8, 1.5, math.pi])  # drives towards us
    parked = np.array([15.5, 8.0, -0.95, 4.2, 1.8, 1.5, 0.0])
    walker = SceneObject((10.0, -4.0, -0.85, 0.6, 0.6, 1.7, 0.0), "Pedestrian")
    radar = _radar_in(moving, -5.0)
    s = suggest_prompt(
        moving[None],
        ["Car"],
        [SceneObject(tuple(parked), "Car"), walker],
        radar,
        np.random.default_rng(0),
    )
    assert s.text and s.reason is None
    assert s.tags <= {"class", "depth", "velocity", "motion", "position"}
    assert resolve(s.predicate, s.actors.all) == (0,)
    referent = s.actors.referents[0]
    assert referent.is_moving and referent.radial_velocity == pytest.approx(-5.0)
    assert [a.cls for a in s.actors.distractors] == ["Car", "Pedestrian"]
    assert not any(a.is_moving for a in s.actors.distractors)
    # Same seed, same sentence.
    again = suggest_prompt(
        moving[None],
        ["Car"],
        [SceneObject(tuple(parked), "Car"), walker],
        radar,
        np.random.default_rng(0),
    )
    assert again.text == s.text


def test_known_actor_velocity_wins_and_is_not_a_distractor() -> None:
    car = np.array([20.0, -4.0, -0.95, 4.2, 1.8, 1.5, 0.0])
    nearby = car.copy()
    nearby[:2] += [0.3, 0.1]
    known = Actor(7, "Car", nearby, [6.0, 0.0])
    radar = _radar_in(car, -9.0)  # would say approaching; the known velocity says moving away
    actors = scene_actors(car[None], ["Car"], [known], radar)
    assert actors.distractors == ()
    np.testing.assert_allclose(actors.referents[0].velocity, [6.0, 0.0])


def test_suggestion_reasons() -> None:
    rng = np.random.default_rng(0)
    car = np.array([15.0, 3.0, -0.95, 4.2, 1.8, 1.5, 0.0])
    assert "add the boxes" in suggest_prompt(np.zeros((0, 7)), [], [], None, rng).reason
    behind = car * [-1, 1, 1, 1, 1, 1, 1]
    assert "outside the region" in suggest_prompt(behind[None], ["Car"], [], None, rng).reason
    # Three parked cars side by side at the same depth; the outer two cannot be singled out.
    row = np.array([car, car, car])
    row[:, 1] = [3.0, 6.0, 9.0]
    middle = SceneObject(tuple(row[1]), "Car")
    s = suggest_prompt(row[[0, 2]], ["Car", "Car"], [middle], None, rng)
    assert s.text is None and "no sentence" in s.reason
    assert "class 'Truck'" in suggest_prompt(car[None], ["Truck"], [], None, rng).reason
