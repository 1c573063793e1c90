"""The synthetic world: determinism, tight actor boxes, realistic ranges, no overlaps, ray casting."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trimesh.ray.ray_pyembree import RayMeshIntersector

from scenes.geometry.actors import Actor
from scenes.geometry.boxes import bev_iou
from scenes.geometry.calib import LIDAR_HEIGHT
from scenes.synth.world import (
    CAR_SIZE,
    CYCLIST_SIZE,
    EGO_FOOTPRINT,
    PEDESTRIAN_SIZE,
    Mat,
    RayCaster,
    TaggedMesh,
    World,
    WorldConfig,
    box_part,
    cylinder_part,
    generate_world,
)

SEEDS = (0, 1, 2, 3)


@pytest.fixture(scope="module")
def worlds() -> list[World]:
    return [generate_world(np.random.default_rng(s), s) for s in SEEDS]


def _local(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Points in the box frame (centre at the origin, heading +x)."""
    c, s = math.cos(box[6]), math.sin(box[6])
    d = points - box[:3]
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


def test_same_seed_same_world_other_seed_other_world():
    a = generate_world(np.random.default_rng(7), 7)
    b = generate_world(np.random.default_rng(7), 7)
    c = generate_world(np.random.default_rng(8), 8)
    assert len(a.actors) == len(b.actors)
    for x, y in zip(a.actors, b.actors, strict=True):
        assert x.cls == y.cls
        np.testing.assert_array_equal(x.box, y.box)
        np.testing.assert_array_equal(x.velocity, y.velocity)
    np.testing.assert_array_equal(a.static_mesh.vertices, b.static_mesh.vertices)
    np.testing.assert_array_equal(a.actor_mesh_at(-0.2).vertices, b.actor_mesh_at(-0.2).vertices)
    assert a.ego_speed == b.ego_speed
    assert not np.array_equal(a.boxes()[:1], c.boxes()[:1])


def test_actor_box_is_the_tight_box_of_its_mesh(worlds):
    for world in worlds:
        mesh = world.actor_mesh_at(0.0)
        for i, actor in enumerate(world.actors):
            verts = mesh.vertices[np.unique(mesh.faces[mesh.owner == i])]
            local = _local(verts, actor.box)
            half = actor.box[3:6] / 2
            np.testing.assert_allclose(local.min(axis=0), -half, atol=1e-9)
            np.testing.assert_allclose(local.max(axis=0), half, atol=1e-9)


def test_sizes_velocities_and_ground_contact_are_realistic(worlds):
    sizes = {"Car": CAR_SIZE, "Pedestrian": PEDESTRIAN_SIZE, "Cyclist": CYCLIST_SIZE}
    ground = -LIDAR_HEIGHT
    for world in worlds:
        assert 0.0 <= world.ego_speed <= 12.0
        for a in world.actors:
            for value, (lo, hi) in zip(a.box[3:6], sizes[a.cls], strict=True):
                assert lo <= value <= hi, (a.cls, a.box)
            speed = a.speed
            if a.cls == "Car":
                assert 0.0 <= speed <= 15.0
            elif a.cls == "Pedestrian":
                assert 0.0 <= speed <= 2.0
            else:
                assert 2.0 <= speed <= 7.0
            if speed > 0:  # moving along the heading
                heading = np.array([math.cos(a.box[6]), math.sin(a.box[6])])
                np.testing.assert_allclose(a.velocity, speed * heading, atol=1e-9)
            bottom = a.box[2] - a.box[5] / 2
            assert ground - 1e-9 <= bottom <= ground + world.road.kerb_height + 1e-9
            assert -math.pi <= a.box[6] < math.pi


def test_counts_and_referable_actors(worlds):
    cfg = WorldConfig()
    referable = []
    for world in worlds:
        counts = {
            c: sum(a.cls == c for a in world.actors) for c in ("Car", "Pedestrian", "Cyclist")
        }
        assert counts["Car"] <= cfg.cars[1] and counts["Pedestrian"] <= cfg.pedestrians[1]
        assert counts["Cyclist"] <= cfg.cyclists[1]
        assert counts["Car"] >= cfg.cars[0] - 1  # placement may drop one in a crowded world
        assert [a.actor_id for a in world.actors] == list(range(len(world.actors)))
        inside = [
            a
            for a in world.actors
            if 0 <= a.box[0] <= 50 and abs(math.degrees(math.atan2(a.box[1], a.box[0]))) <= 32
        ]
        referable.append(len(inside))
    assert min(referable) >= 1 and np.mean(referable) >= 4


def test_actors_overlap_neither_each_other_nor_the_ego(worlds):
    ego = np.array(
        [[EGO_FOOTPRINT[0], EGO_FOOTPRINT[1], 0, EGO_FOOTPRINT[2], EGO_FOOTPRINT[3], 1, 0]]
    )
    for world in worlds:
        boxes = world.boxes()
        iou = bev_iou(boxes, boxes)
        np.fill_diagonal(iou, 0.0)
        assert iou.max() == 0.0
        assert bev_iou(boxes, ego).max() == 0.0


def test_actor_mesh_moves_with_velocity():
    world = generate_world(np.random.default_rng(11), 11)
    now, before = world.actor_mesh_at(0.0), world.actor_mesh_at(-0.3)
    for i, actor in enumerate(world.actors):
        verts = np.unique(now.faces[now.owner == i])
        shift = before.vertices[verts] - now.vertices[verts]
        np.testing.assert_allclose(shift[:, :2], np.tile(-0.3 * actor.velocity, (len(verts), 1)))
        np.testing.assert_allclose(shift[:, 2], 0.0)


def test_ground_is_at_minus_lidar_height_and_the_ego_lane_is_asphalt():
    world = generate_world(np.random.default_rng(4), 4)
    caster = RayCaster(world)
    assert caster.uses_embree and isinstance(caster._static.intersector, RayMeshIntersector)
    # Straight down, 3 m and 6 m ahead of the LiDAR, in the ego lane (centred on y = 0).
    origins = np.array([[3.0, 0.0, 0.0], [6.0, 0.4, 0.0]])
    hits = caster.cast(origins, np.tile([0.0, 0.0, -1.0], (2, 1)))
    assert hits.hit.all()
    np.testing.assert_allclose(hits.points[:, 2], -LIDAR_HEIGHT, atol=1e-5)
    np.testing.assert_allclose(hits.distance, LIDAR_HEIGHT, atol=1e-5)
    assert set(hits.material.tolist()) <= {Mat.ASPHALT, Mat.MARKING}
    assert (hits.owner == -1).all()
    np.testing.assert_allclose(hits.cos_incidence, 1.0, atol=1e-9)


def test_ray_cast_hits_the_nearest_of_static_and_actor():
    # A 2 m cube centred 10 m ahead (actor) in front of a wall at x = 20 (static).
    wall = box_part([20.0, -5.0, -2.0], [20.5, 5.0, 3.0], Mat.BRICK)
    cube = box_part([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], Mat.PAINT_LIGHT)
    actor = Actor(0, "Car", [10.0, 0.0, 0.0, 2.0, 2.0, 2.0, 0.0], [0.0, 0.0])
    world = World(0, None, 1.7, 0.0, (actor,), wall, (cube,))
    caster = RayCaster(world)
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.2, 0.0] / np.hypot(1.0, 0.2)])
    hits = caster.cast(np.zeros((3, 3)), dirs)
    np.testing.assert_array_equal(hits.hit, [True, False, True])
    assert hits.distance[0] == pytest.approx(9.0)  # the cube's face at x = 9
    assert hits.owner[0] == 0 and hits.material[0] == Mat.PAINT_LIGHT
    assert hits.distance[2] == pytest.approx(20.0 * np.hypot(1.0, 0.2))  # misses the cube
    assert hits.owner[2] == -1 and hits.material[2] == Mat.BRICK
    assert hits.cos_incidence[2] == pytest.approx(1.0 / np.hypot(1.0, 0.2))


def test_tagged_mesh_parts():
    cyl = cylinder_part([1.0, 2.0, 3.0], [1.0, 2.0, 5.0], 0.5, Mat.METAL)
    np.testing.assert_allclose(cyl.vertices.min(axis=0)[2], 3.0)
    np.testing.assert_allclose(cyl.vertices.max(axis=0)[2], 5.0)
    radial = np.hypot(cyl.vertices[:, 0] - 1.0, cyl.vertices[:, 1] - 2.0)
    assert radial.max() == pytest.approx(0.5)
    both = TaggedMesh.concatenate([cyl, box_part([0, 0, 0], [1, 1, 1], Mat.BRICK).with_owner(3)])
    assert both.faces.max() == len(both.vertices) - 1
    assert set(both.owner.tolist()) == {-1, 3}
    with pytest.raises(ValueError, match="one mesh per actor"):
        World(0, None, 1.7, 0.0, (Actor(0, "Car", [5, 0, 0, 4, 2, 1.5, 0], [0, 0]),), cyl, ())


def test_street_clutter_is_static_visible_and_never_an_actor(worlds):
    clutter = [c for w in worlds for c in w.clutter]
    assert len(clutter) >= 10 * len(worlds)  # Delft: parked bicycles everywhere
    assert {c.cls for c in clutter} <= {"bicycle", "bicycle_rack", "moped_scooter"}
    assert {"bicycle", "bicycle_rack", "moped_scooter"} <= {c.cls for c in clutter}
    for world in worlds:
        assert all(a.cls in ("Car", "Pedestrian", "Cyclist") for a in world.actors)
        boxes = np.array([c.box for c in world.clutter])
        assert bev_iou(world.boxes(), boxes).max() == 0.0  # actors keep clear of the clutter
        # The clutter is static geometry (owner -1): a ray down onto a parked bicycle hits it.
        bikes = boxes[[c.cls == "bicycle" for c in world.clutter]]
        origins = bikes[:, :3] + np.array([0.0, 0.0, 3.0])
        hits = RayCaster(world).cast(origins, np.tile([0.0, 0.0, -1.0], (len(bikes), 1)))
        top = bikes[:, 2] + bikes[:, 5] / 2
        assert np.mean(hits.points[:, 2] > top - 0.8) > 0.5 and (hits.owner == -1).all()
    refs = sum(a.cls != "Car" for w in worlds for a in w.actors) / sum(
        len(w.actors) for w in worlds
    )
    assert refs > 0.6  # mostly cyclists and pedestrians
