"""The :class:`World`: a static mesh plus moving actors, in the LiDAR frame at ``t = 0``."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenes.geometry.actors import Actor
from scenes.synth.world.clutter import Clutter
from scenes.synth.world.meshes import TaggedMesh, rotation_z
from scenes.synth.world.road import Road


@dataclass(frozen=True)
class World:
    """A static scene plus moving actors, in the LiDAR frame at ``t = 0``.

    Attributes:
        world_id: Index of the world within a generated set.
        road: The road layout.
        lidar_height: Ground at ``z = -lidar_height``.
        ego_speed: Ego speed along +x (m/s).
        actors: The actors (``actor_id`` = index).
        static_mesh: Road, kerbs, buildings and clutter (owner -1).
        actor_meshes: One mesh per actor in its own box frame (centre at the origin, heading +x).
        clutter: Parked bicycles, bicycle racks and mopeds (their meshes are in ``static_mesh``);
            never referents.
    """

    world_id: int
    road: Road | None
    lidar_height: float
    ego_speed: float
    actors: tuple[Actor, ...]
    static_mesh: TaggedMesh = field(repr=False)
    actor_meshes: tuple[TaggedMesh, ...] = field(repr=False)
    clutter: tuple[Clutter, ...] = ()

    def __post_init__(self) -> None:
        if len(self.actors) != len(self.actor_meshes):
            raise ValueError("World: one mesh per actor is required")

    def actor_mesh_at(self, time: float = 0.0) -> TaggedMesh:
        """All actors at ``time`` seconds (negative = earlier), each translated by ``velocity *
        time``, in the LiDAR frame of ``t = 0``; ``owner`` = actor index."""
        parts = []
        for i, (actor, mesh) in enumerate(zip(self.actors, self.actor_meshes, strict=True)):
            centre = actor.box[:3].copy()
            centre[:2] += actor.velocity * time
            parts.append(mesh.with_owner(i).transformed(rotation_z(actor.box[6]), centre))
        return TaggedMesh.concatenate(parts)

    def ego_position(self, time: float = 0.0) -> np.ndarray:
        """``(3,)`` offset of the ego vehicle (and its sensors) at ``time`` from its ``t = 0`` pose."""
        return np.array([self.ego_speed * time, 0.0, 0.0])

    def boxes(self) -> np.ndarray:
        """``(K, 7)`` boxes of all actors (LiDAR frame)."""
        return np.array([a.box for a in self.actors]).reshape(-1, 7)
