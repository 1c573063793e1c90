"""Drawing a random :class:`~scenes.synth.world.scene.World` (see :mod:`scenes.synth.world`): the road, its
frontage, furniture and clutter, then the actors placed without overlaps, all from one generator."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from scenes.geometry.actors import Actor
from scenes.synth.world.config import WorldConfig
from scenes.synth.world.footprint import overlaps_any
from scenes.synth.world.meshes import TaggedMesh
from scenes.synth.world.placement import EGO_FOOTPRINT, Candidate
from scenes.synth.world.road import Road, make_road, road_mesh
from scenes.synth.world.road_users import (
    clutter_actors,
    default_size,
    margin_of,
    plan,
    road_user_mesh,
)
from scenes.synth.world.scene import World
from scenes.synth.world.street import Roadside, draw_roadside

DEFAULT_CONFIG = WorldConfig()
"""The default ranges (:class:`~scenes.synth.world.config.WorldConfig` as it is)."""


def _fit(
    group: list[Candidate],
    road: Road,
    ground_z: float,
    taken: list[np.ndarray],
    taken_margin: list[float],
    rng: np.random.Generator,
) -> list[tuple[Candidate, np.ndarray, np.ndarray]] | None:
    """The group's members with their LiDAR-frame boxes ``(7,)`` and BEV footprints ``(5,)``, or
    None when one overlaps what is taken (with its class's margin) or an earlier member. Sizes
    not fixed by the placement are drawn here, member by member after its position."""
    out: list[tuple[Candidate, np.ndarray, np.ndarray]] = []
    for cand in group:
        size = default_size(cand, rng)
        xy = road.to_xy(cand.u, cand.s)
        yaw = float(road.heading(cand.u)) + cand.yaw_offset
        bev = np.array([xy[0], xy[1], size[0], size[1], yaw])
        if overlaps_any(bev, margin_of(cand.cls), taken, taken_margin):
            return None
        if out and overlaps_any(bev, 0.0, [b for _, _, b in out], [0.0] * len(out)):
            return None
        z = ground_z + road.surface_height(cand.s) + size[2] / 2
        yaw = float(np.mod(yaw + np.pi, 2 * np.pi) - np.pi)
        out.append((cand, np.array([xy[0], xy[1], z, *size, yaw]), bev))
    return out


def _split_clutter(
    roadside: Roadside,
) -> tuple[Roadside, list[tuple[str, np.ndarray, TaggedMesh]]]:
    """The roadside without the clutter that becomes parked road users, and those road users
    (:func:`scenes.synth.world.road_users.clutter_actors`), right side first."""
    sides, parked = [], []
    for parts, items in roadside.clutter:
        kept_parts, kept_items, users = clutter_actors(list(parts), list(items))
        sides.append((tuple(kept_parts), tuple(kept_items)))
        parked += users
    return replace(roadside, clutter=tuple(sides)), parked


def generate_world(
    rng: np.random.Generator, world_id: int = 0, config: WorldConfig = DEFAULT_CONFIG
) -> World:
    """A random world (see the module docstring); all randomness comes from ``rng``."""
    ground_z = -config.lidar_height
    road = make_road(rng)
    roadside, obstacles = draw_roadside(road, ground_z, rng)
    if config.classes != "vod":  # parked bicycles and mopeds are road users of the set
        roadside, parked = _split_clutter(roadside)
    else:
        parked = []

    taken = [EGO_FOOTPRINT] + [np.array([o.x, o.y, o.l, o.w, o.yaw]) for o in obstacles]
    taken_margin = [0.5] + [0.1] * len(obstacles)
    actors: list[Actor] = [
        Actor(i, cls, box, np.zeros(2)) for i, (cls, box, _) in enumerate(parked)
    ]
    meshes: list[TaggedMesh] = [mesh for _, _, mesh in parked]
    vod_counts = {"Car": config.cars, "Pedestrian": config.pedestrians, "Cyclist": config.cyclists}
    placements = plan(config.classes, vod_counts)
    counts = [int(rng.integers(p.counts[0], p.counts[1] + 1)) for p in placements]
    for placement, count in zip(placements, counts, strict=True):
        for _ in range(count):
            for _attempt in range(25):
                far = rng.random() < config.far_fraction
                u = rng.uniform(*(config.far_u if far else config.near_u))
                group = _fit(
                    placement.place(road, u, rng), road, ground_z, taken, taken_margin, rng
                )
                if group is None:
                    continue
                for cand, box, bev in group:
                    yaw = box[6]
                    velocity = cand.speed * np.array([math.cos(yaw), math.sin(yaw)])
                    actors.append(Actor(len(actors), cand.cls, box, velocity))
                    meshes.append(road_user_mesh(cand, box[3:6], rng))
                    taken.append(bev)
                    taken_margin.append(margin_of(cand.cls))
                break
    ego_speed = 0.0 if rng.random() < config.ego_stopped else rng.uniform(*config.ego_speed)
    if not config.street.is_default:  # drawn last: the actors stay those of the default street
        roadside = roadside.with_density(config.street, actors, road, ground_z, rng)
    return World(
        world_id=world_id,
        road=road,
        lidar_height=config.lidar_height,
        ego_speed=float(ego_speed),
        actors=tuple(actors),
        static_mesh=TaggedMesh.concatenate([road_mesh(road, ground_z), *roadside.parts()]),
        actor_meshes=tuple(meshes),
        clutter=tuple(roadside.items()),
    )
