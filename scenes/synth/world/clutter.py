"""Street clutter: parked bicycles, bicycle racks and mopeds on verges and sidewalks. Static
geometry both sensors see, never an :class:`~scenes.geometry.actors.Actor`, so never a referent nor in
``label_2``; each is recorded as a :class:`Clutter` with its View-of-Delft class and box."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenes.synth.world.actor_meshes import bicycle_parts
from scenes.synth.world.footprint import Obstacle, overlaps_any
from scenes.synth.world.materials import Mat
from scenes.synth.world.meshes import TaggedMesh, box_part, cylinder_part, fit_to_box, rotation_z
from scenes.synth.world.road import Road, Side

BICYCLE_SIZE = ((1.7, 1.9), (0.5, 0.65), (1.0, 1.15))
MOPED_SIZE = ((1.65, 1.9), (0.62, 0.75), (1.1, 1.25))
RACK_SLOT = 0.7
"""Spacing (m) of a bicycle rack's hoops along the road."""


@dataclass(frozen=True)
class Clutter:
    """A static object both sensors see but no prompt refers to (not an :class:`Actor`).

    Attributes:
        cls: Its View-of-Delft label: ``bicycle``, ``bicycle_rack`` or ``moped_scooter``.
        box: ``(7,)`` ``x, y, z, l, w, h, yaw`` in the LiDAR frame, z at the geometric centre.
    """

    cls: str
    box: np.ndarray = field(repr=False)

    def to_json(self) -> dict:
        """A JSON-serialisable dict (recorded in the sample sidecar's ``extra``)."""
        return {"cls": self.cls, "box": [round(float(v), 4) for v in self.box]}


def moped_mesh(size: np.ndarray) -> TaggedMesh:
    """A parked moped / scooter: two small wheels, body, seat, leg shield, handlebar."""
    parts = [
        cylinder_part([x, -0.05, 0.22], [x, 0.05, 0.22], 0.22, Mat.RUBBER) for x in (-0.6, 0.6)
    ]
    parts.append(box_part([-0.75, -0.2, 0.3], [0.25, 0.2, 0.75], Mat.PAINT_LIGHT))
    parts.append(box_part([-0.65, -0.17, 0.75], [0.0, 0.17, 0.86], Mat.RUBBER))
    parts.append(box_part([0.25, -0.25, 0.25], [0.42, 0.25, 1.0], Mat.PAINT_LIGHT))
    parts.append(cylinder_part([0.45, 0.0, 0.4], [0.45, 0.0, 1.15], 0.04, Mat.METAL))
    parts.append(cylinder_part([0.45, -0.36, 1.15], [0.45, 0.36, 1.15], 0.025, Mat.METAL))
    return fit_to_box(TaggedMesh.concatenate(parts), size)


def _rack_mesh(slots: int) -> tuple[TaggedMesh, np.ndarray]:
    """Inverted-U hoops ``RACK_SLOT`` apart along x, 0.8 m wide in y and tall; the mesh (ground at
    z = 0, centred in x and y) and its ``(l, w, h)``."""
    parts = []
    half = (slots - 1) * RACK_SLOT / 2
    for j in range(slots):
        x = j * RACK_SLOT - half
        for y in (-0.4, 0.4):
            parts.append(cylinder_part([x, y, 0.0], [x, y, 0.8], 0.03, Mat.METAL))
        parts.append(cylinder_part([x, -0.4, 0.8], [x, 0.4, 0.8], 0.03, Mat.METAL))
    mesh = TaggedMesh.concatenate(parts)
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    return mesh, hi - lo


def street_clutter(
    road: Road, side: Side, ground_z: float, obstacles: list[Obstacle], rng: np.random.Generator
) -> tuple[list[TaggedMesh], list[Clutter]]:
    """Bicycle racks with parked bicycles, loose parked bicycles and mopeds on one side's verge or
    sidewalk, in front (u in 1..90 m); appended to ``obstacles`` so that actors keep clear."""
    parts: list[TaggedMesh] = []
    items: list[Clutter] = []
    z0 = ground_z + road.kerb_height
    taken = [np.array([o.x, o.y, o.l, o.w, o.yaw]) for o in obstacles]

    def put(u: float, s: float, size: np.ndarray, yaw_offset: float) -> np.ndarray | None:
        """The LiDAR-frame box at ``(u, s)`` when it is free (and mark it taken), else None."""
        x, y = road.to_xy(u, s)
        yaw = float(np.mod(float(road.heading(u)) + yaw_offset + np.pi, 2 * np.pi) - np.pi)
        bev = np.array([x, y, size[0], size[1], yaw])
        if taken and overlaps_any(bev, 0.1, taken, [0.1] * len(taken)):
            return None
        taken.append(bev)
        obstacles.append(Obstacle(float(x), float(y), float(size[0]), float(size[1]), yaw))
        return np.array([x, y, z0 + size[2] / 2, *size, yaw])

    def add(cls: str, mesh: TaggedMesh, box: np.ndarray) -> None:
        centre = np.array([box[0], box[1], box[2] - box[5] / 2])
        parts.append(mesh.transformed(rotation_z(box[6]), centre))
        items.append(Clutter(cls, box))

    def bicycle(size: np.ndarray) -> TaggedMesh:
        mesh = fit_to_box(TaggedMesh.concatenate(bicycle_parts(rng)), size)
        return mesh.transformed(np.eye(3), [0.0, 0.0, size[2] / 2])

    strips = [side.verge, side.sidewalk]
    u = rng.uniform(1.0, 8.0)
    while u < 90.0:
        a, b = strips[0] if rng.random() < 0.5 else strips[1]
        width = b - a
        kind = rng.random()
        if kind < 0.4 and width >= 1.9:  # a rack, bicycles across the strip in most slots
            slots = int(rng.integers(3, 9))
            mesh, rsize = _rack_mesh(slots)
            s = (a + b) / 2
            group = np.array([rsize[0] + 0.6, 1.9, 1.2])
            if put(u + rsize[0] / 2, s, group, 0.0) is not None:
                x, y = road.to_xy(u + rsize[0] / 2, s)
                yaw = float(road.heading(u))
                rack_box = np.array([x, y, z0 + rsize[2] / 2, *rsize, yaw])
                add("bicycle_rack", mesh.transformed(np.eye(3), [0, 0, rsize[2] / 2]), rack_box)
                for j in range(slots):
                    if rng.random() < 0.75:
                        size = np.array([rng.uniform(*r) for r in BICYCLE_SIZE])
                        su = u + j * RACK_SLOT + 0.2
                        bx, by = road.to_xy(su, s + rng.normal(0.0, 0.1))
                        turn = np.pi / 2 if rng.random() < 0.5 else -np.pi / 2
                        byaw = float(np.mod(yaw + turn + rng.normal(0, 0.1) + np.pi, 2 * np.pi))
                        bbox = np.array([bx, by, z0 + size[2] / 2, *size, byaw - np.pi])
                        add("bicycle", bicycle(size), bbox)
            u += rsize[0] + rng.uniform(4.0, 15.0)
        elif kind < 0.8:  # loose bicycles parked along the road
            for _ in range(int(rng.integers(1, 4))):
                size = np.array([rng.uniform(*r) for r in BICYCLE_SIZE])
                s = rng.uniform(a + size[1] / 2, max(a + size[1] / 2, b - size[1] / 2))
                flip = np.pi if rng.random() < 0.5 else 0.0
                box = put(u, s, size, flip + rng.normal(0.0, 0.15))
                if box is not None:
                    add("bicycle", bicycle(size), box)
                u += size[0] + rng.uniform(0.1, 0.6)
            u += rng.uniform(4.0, 15.0)
        else:  # a parked moped or scooter
            size = np.array([rng.uniform(*r) for r in MOPED_SIZE])
            s = rng.uniform(a + size[1] / 2, max(a + size[1] / 2, b - size[1] / 2))
            box = put(u, s, size, (np.pi if rng.random() < 0.5 else 0.0) + rng.normal(0.0, 0.3))
            if box is not None:
                mesh = moped_mesh(size).transformed(np.eye(3), [0.0, 0.0, size[2] / 2])
                add("moped_scooter", mesh, box)
            u += size[0] + rng.uniform(4.0, 15.0)
    return parts, items
