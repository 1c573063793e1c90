"""Drawing a random :class:`~scenes.synth.world.scene.World` (see :mod:`scenes.synth.world`): the road, its
frontage, furniture and clutter, then the actors placed without overlaps, all from one generator."""

from __future__ import annotations

import math

import numpy as np

from scenes.geometry.actors import CLASSES, Actor
from scenes.synth.world.config import WorldConfig
from scenes.synth.world.footprint import overlaps_any
from scenes.synth.world.meshes import TaggedMesh
from scenes.synth.world.placement import CANDIDATES, EGO_FOOTPRINT, MARGIN, SIZES, actor_mesh
from scenes.synth.world.road import make_road, road_mesh
from scenes.synth.world.scene import World
from scenes.synth.world.street import draw_roadside

DEFAULT_CONFIG = WorldConfig()
"""The default ranges (:class:`~scenes.synth.world.config.WorldConfig` as it is)."""


def generate_world(
    rng: np.random.Generator, world_id: int = 0, config: WorldConfig = DEFAULT_CONFIG
) -> World:
    """A random world (see the module docstring); all randomness comes from ``rng``."""
    ground_z = -config.lidar_height
    road = make_road(rng)
    roadside, obstacles = draw_roadside(road, ground_z, rng)

    taken = [EGO_FOOTPRINT] + [np.array([o.x, o.y, o.l, o.w, o.yaw]) for o in obstacles]
    taken_margin = [0.5] + [0.1] * len(obstacles)
    counts = {
        "Car": int(rng.integers(config.cars[0], config.cars[1] + 1)),
        "Pedestrian": int(rng.integers(config.pedestrians[0], config.pedestrians[1] + 1)),
        "Cyclist": int(rng.integers(config.cyclists[0], config.cyclists[1] + 1)),
    }
    actors: list[Actor] = []
    meshes: list[TaggedMesh] = []
    for cls in CLASSES:
        for _ in range(counts[cls]):
            for _attempt in range(25):
                far = rng.random() < config.far_fraction
                u = rng.uniform(*(config.far_u if far else config.near_u))
                cand = CANDIDATES[cls](road, u, rng)
                size = np.array([rng.uniform(*r) for r in SIZES[cls]])
                xy = road.to_xy(cand.u, cand.s)
                yaw = float(road.heading(cand.u)) + cand.yaw_offset
                bev = np.array([xy[0], xy[1], size[0], size[1], yaw])
                margin = MARGIN[cls]
                if overlaps_any(bev, margin, taken, taken_margin):
                    continue
                z = ground_z + road.surface_height(cand.s) + size[2] / 2
                yaw = float(np.mod(yaw + np.pi, 2 * np.pi) - np.pi)
                velocity = cand.speed * np.array([math.cos(yaw), math.sin(yaw)])
                box = np.array([xy[0], xy[1], z, *size, yaw])
                actors.append(Actor(len(actors), cls, box, velocity))
                meshes.append(actor_mesh(cand, size, rng))
                taken.append(bev)
                taken_margin.append(margin)
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
