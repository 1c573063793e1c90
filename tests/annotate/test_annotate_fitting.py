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
from annotate.fitting import Rectangle, complete_rectangle
from scenes import Actor
from scenes.geometry.boxes import points_in_boxes, wrap_yaw
from scenes.language.prompts import resolve

GROUND = -1.7
MINIMUM = FitConfig(grow_to_typical=False)
"""Completion to the class minimum only (the default grows a hidden side to the typical size)."""
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


# ------------------------------------------------------------------------------------ class prior


def _face(
    start: tuple[float, float], end: tuple[float, float], rng: np.random.Generator, n: int = 400
) -> np.ndarray:
    """Points ``(n, 3)`` on a vertical face from BEV ``start`` to ``end``, 0.25-1.65 m above ground."""
    t = rng.uniform(0.0, 1.0, n)
    xy = np.asarray(start) + t[:, None] * (np.asarray(end) - np.asarray(start))
    xy += rng.normal(0.0, 0.01, xy.shape)
    return np.c_[xy, GROUND + rng.uniform(0.25, 1.65, n)]


def _with_ground(obj: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``obj`` plus a 0.25 m ground grid around it, with an intensity column: ``(N, 4)`` float32."""
    centre = obj[:, :2].mean(axis=0)
    gx, gy = np.meshgrid(np.arange(-5, 5, 0.25) + centre[0], np.arange(-5, 5, 0.25) + centre[1])
    ground = np.c_[gx.ravel(), gy.ravel(), GROUND + rng.normal(0, 0.01, gx.size)]
    pts = np.concatenate([obj, ground])
    return np.c_[pts, rng.uniform(0, 255, len(pts))].astype(np.float32)


def _check_completion(points: np.ndarray, result, n_object: int) -> None:
    """The box holds every object point, and along each axis its end nearer the sensor (origin)
    lies at the points: nothing was added on the side that was seen."""
    assert result.used[:n_object].all() and not result.used[n_object:].any()
    obj = points[:n_object, :3].astype(np.float64)
    grown = result.box.copy()
    grown[3:6] += 1e-6
    assert points_in_boxes(obj, grown[None])[:, 0].all()
    x, y, _, length, width, _, yaw = result.box
    c, s = math.cos(yaw), math.sin(yaw)
    d = obj[:, :2] - [x, y]
    local = np.c_[d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c]
    sensor = np.array([-x * c - y * s, x * s - y * c])
    for axis, half in ((0, length / 2), (1, width / 2)):
        if sensor[axis] < -half:
            assert local[:, axis].min() == pytest.approx(-half, abs=1e-6)
        elif sensor[axis] > half:
            assert local[:, axis].max() == pytest.approx(half, abs=1e-6)


@pytest.mark.parametrize("bearing_deg", [0.0, 30.0])
def test_car_seen_from_behind_is_completed_away_from_the_sensor(bearing_deg: float) -> None:
    # The rear face only: 1.8 m wide, facing the origin 9 m away along the bearing.
    rng = np.random.default_rng(10)
    b = math.radians(bearing_deg)
    ray, across = np.array([math.cos(b), math.sin(b)]), np.array([-math.sin(b), math.cos(b)])
    mid = 9.0 * ray
    obj = _face(tuple(mid - 0.9 * across), tuple(mid + 0.9 * across), rng)
    points = _with_ground(obj, rng)
    region = BoxRegion((*(mid + 0.8 * ray), GROUND + 0.75, 4.2, 1.8, 1.5, 0.0))  # a ground click

    slab = fit_box(points, region, ground_z=GROUND)  # the points alone: a slab turned across
    assert slab.box[3] == pytest.approx(1.8, abs=0.03) and slab.box[4] <= 0.1 + 1e-9
    assert abs(wrap_yaw(2.0 * (slab.box[6] - b - math.pi / 2))) < 0.02 and not slab.completed

    result = fit_box(points, region, ground_z=GROUND, cls="Car", config=MINIMUM)
    assert result.completed
    # The 1.8 m face is the width; the length runs away from the sensor, to the car's minimum.
    np.testing.assert_allclose(result.box[3:5], [3.5, 1.8], atol=0.03)
    assert result.box[6] == pytest.approx(b, abs=0.02)  # the heading nearest prior_yaw = 0
    np.testing.assert_allclose(result.box[:2], mid + 1.75 * ray, atol=0.06)
    assert result.box[5] == pytest.approx(slab.box[5]) and result.box[2] == slab.box[2]
    _check_completion(points, result, len(obj))
    behind = fit_box(
        points, region, ground_z=GROUND, cls="Car", config=MINIMUM, prior_yaw=b + math.pi
    )
    assert behind.box[6] == pytest.approx(wrap_yaw(b + math.pi), abs=0.02)
    np.testing.assert_allclose(behind.box[:5], result.box[:5], atol=1e-9)
    # Typical instead of minimum: the same near face, the length of DEFAULT_SIZES.
    typical = fit_box(points, region, ground_z=GROUND, cls="Car")  # the default
    np.testing.assert_allclose(typical.box[3:5], [4.2, 1.8], atol=0.03)
    np.testing.assert_allclose(typical.box[:2], mid + 2.1 * ray, atol=0.06)
    _check_completion(points, typical, len(obj))


def test_car_seen_from_the_side_keeps_its_length_and_grows_its_width() -> None:
    # A car crossing 9 m ahead: its left side only, 4.3 m long, along y at x = 9.
    rng = np.random.default_rng(11)
    obj = _face((9.0, -2.15), (9.0, 2.15), rng)
    points = _with_ground(obj, rng)
    region = DiskRegion((9.5, 0.0), 3.0)
    result = fit_box(points, region, ground_z=GROUND, cls="Car", config=MINIMUM)
    assert result.completed
    np.testing.assert_allclose(result.box[3:5], [4.3, 1.5], atol=0.03)  # length as seen
    assert abs(wrap_yaw(2.0 * (result.box[6] - math.pi / 2))) < 0.02  # along the side
    np.testing.assert_allclose(result.box[:2], [9.75, 0.0], atol=0.06)  # grown to x = 10.5
    _check_completion(points, result, len(obj))


def test_an_l_shaped_scan_is_not_inflated() -> None:
    rng = np.random.default_rng(12)
    rear = _face((9.0, -0.95), (9.0, 0.95), rng)
    # The whole right side seen: both sides already exceed the car's minimum.
    whole = np.concatenate([rear, _face((9.0, -0.95), (13.5, -0.95), rng)])
    points = _with_ground(whole, rng)
    region = BoxRegion((11.2, 0.0, -0.95, 4.2, 1.8, 1.5, 0.0))
    plain = fit_box(points, region, ground_z=GROUND)
    result = fit_box(points, region, ground_z=GROUND, cls="Car", config=MINIMUM)
    assert not result.completed
    np.testing.assert_array_equal(result.box, plain.box)
    np.testing.assert_allclose(result.box[3:5], [4.5, 1.9], atol=0.04)
    # 2.5 m of the side seen (the rest hidden): the length grows away from the sensor, the
    # 1.9 m the points show across it stays 1.9 m.
    part = np.concatenate([rear, _face((9.0, -0.95), (11.5, -0.95), rng)])
    points = _with_ground(part, rng)
    result = fit_box(points, region, ground_z=GROUND, cls="Car", config=MINIMUM)
    assert result.completed
    np.testing.assert_allclose(result.box[3:5], [3.5, 1.9], atol=0.04)
    assert abs(wrap_yaw(2.0 * result.box[6])) < 0.02
    assert result.box[0] == pytest.approx(9.0 + 1.75, abs=0.03)
    _check_completion(points, result, len(part))


def test_pedestrian_and_cyclist_priors() -> None:
    rng = np.random.default_rng(13)
    # A pedestrian seen from the front 8 m ahead: 0.5 m wide, 0.15 m deep.
    body = np.c_[
        rng.uniform(8.0, 8.15, 300), rng.uniform(-0.25, 0.25, 300), rng.uniform(-1.4, 0.0, 300)
    ]
    points = _with_ground(body, rng)
    region = DiskRegion((8.2, 0.0), 1.0)
    result = fit_box(points, region, ground_z=GROUND, cls="Pedestrian", config=MINIMUM)
    assert result.completed
    np.testing.assert_allclose(sorted(result.box[3:5]), [0.4, 0.5], atol=0.02)
    _check_completion(points, result, len(body))
    assert result.box[:2] == pytest.approx([8.2, 0.0], abs=0.02)  # grown to x = 8.4
    # A cyclist head-on 10 m ahead (0.6 m wide): the length runs away from the sensor.
    rider = np.c_[
        rng.uniform(10.0, 10.3, 300), rng.uniform(-0.3, 0.3, 300), rng.uniform(-1.4, 0.0, 300)
    ]
    points = _with_ground(rider, rng)
    result = fit_box(
        points, DiskRegion((10.5, 0.0), 1.5), ground_z=GROUND, cls="Cyclist", config=MINIMUM
    )
    np.testing.assert_allclose(result.box[[0, 3, 4]], [10.75, 1.5, 0.6], atol=0.02)
    assert abs(wrap_yaw(2.0 * result.box[6])) < 0.02
    _check_completion(points, result, len(rider))
    # Its side seen crossing (1 m: frame and rider, the wheels too sparse): wider than a
    # cyclist's width may be, so it is the length, not turned.
    side = np.c_[
        rng.uniform(12.0, 12.25, 300), rng.uniform(-0.5, 0.5, 300), rng.uniform(-1.4, 0.0, 300)
    ]
    points = _with_ground(side, rng)
    result = fit_box(
        points, DiskRegion((12.5, 0.0), 1.5), ground_z=GROUND, cls="Cyclist", config=MINIMUM
    )
    np.testing.assert_allclose(result.box[3:5], [1.5, 0.5], atol=0.02)
    assert abs(wrap_yaw(2.0 * (result.box[6] - math.pi / 2))) < 0.1


def test_without_a_known_class_the_fit_is_unchanged() -> None:
    rng = np.random.default_rng(14)
    obj = _face((9.0, -0.9), (9.0, 0.9), rng)
    points = _with_ground(obj, rng)
    region = BoxRegion((9.8, 0.0, -0.95, 4.2, 1.8, 1.5, 0.0))
    plain = fit_box(points, region)
    for cls in (None, "Truck"):  # no class, or one without a typical size and minimum
        other = fit_box(points, region, cls=cls)
        np.testing.assert_array_equal(other.box, plain.box)
        assert not other.completed
    no_minimum = FitConfig(class_min_sizes=(("Pedestrian", 0.4, 0.4),))
    assert not fit_box(points, region, cls="Car", config=no_minimum).completed


def test_complete_rectangle_by_hand_and_bad_configs() -> None:
    # The sensor between the two ends of a side: it grows about its middle.
    rect = Rectangle(np.array([0.0, 5.0]), 1.0, 0.2, 0.0)
    out, done = complete_rectangle(rect, (0.7, 0.7), (0.4, 0.4), MINIMUM)
    assert done and (out.length, out.width) == pytest.approx((1.0, 0.4))
    np.testing.assert_allclose(out.centre, [0.0, 4.9 + 0.2])  # near edge y = 4.9 kept
    big = Rectangle(np.array([5.0, 0.0]), 4.0, 1.6, 0.3)
    assert complete_rectangle(big, (4.2, 1.8), (3.5, 1.5), FitConfig()) == (big, False)
    with pytest.raises(ValueError, match="need length > 0, width >= 0"):
        complete_rectangle(
            Rectangle(np.zeros(2), 0.0, 0.0, 0.0), (4.2, 1.8), (3.5, 1.5), FitConfig()
        )
    with pytest.raises(ValueError, match=r"class_min_sizes\[1\] must be"):
        FitConfig(class_min_sizes=(("Car", 3.5, 1.5), ("Van", -1.0, 1.0)))
    with pytest.raises(ValueError, match=r"class_min_sizes\[1\]: class 'Car' repeated"):
        FitConfig(class_min_sizes=(("Car", 3.5, 1.5), ("Car", 3.0, 1.5)))
    with pytest.raises(ValueError, match="degenerate_fraction"):
        FitConfig(degenerate_fraction=0.0)
