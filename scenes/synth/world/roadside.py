"""Static roadside geometry: buildings, walls and hedges beyond the building lines, and street
lights, signs, bollards and trees in the verges (whose footprints actors keep clear of)."""

from __future__ import annotations

import math

import numpy as np

from scenes.synth.world.footprint import Obstacle
from scenes.synth.world.materials import Mat
from scenes.synth.world.meshes import (
    TaggedMesh,
    box_part,
    cylinder_part,
    ellipsoid_part,
    hexahedron_part,
)
from scenes.synth.world.road import U_RANGE, Road, Side


def _curved_block(
    road: Road, u0: float, u1: float, s0: float, s1: float, z0: float, z1: float, mat: Mat
) -> TaggedMesh:
    """A block following the road between abscissae ``u0..u1`` and lateral offsets ``s0..s1``."""
    corners = np.zeros((8, 3))
    for i in range(8):
        bx, by, bz = (i >> 2) & 1, (i >> 1) & 1, i & 1
        corners[i, :2] = road.to_xy((u0, u1)[bx], (s0, s1)[by])
        corners[i, 2] = (z0, z1)[bz]
    return hexahedron_part(corners, mat)


def frontage(road: Road, side: Side, ground_z: float, rng: np.random.Generator) -> list[TaggedMesh]:
    """Buildings, walls and hedges along one side, beyond its building line."""
    parts = []
    u = U_RANGE[0] + rng.uniform(0, 10)
    kerb = road.kerb_height
    while u < U_RANGE[1]:
        kind = rng.random()
        length = rng.uniform(8.0, 30.0)
        front = side.building_line + side.sign * rng.uniform(0.0, 1.5)
        if kind < 0.7:
            depth, height = rng.uniform(6.0, 14.0), rng.uniform(3.5, 16.0)
            mat = (Mat.BRICK, Mat.CONCRETE, Mat.GLASS_FACADE)[int(rng.integers(0, 3))]
            s0, s1 = sorted((front, front + side.sign * depth))
            parts.append(
                _curved_block(road, u, u + length, s0, s1, ground_z, ground_z + height, mat)
            )
        elif kind < 0.85:
            thick, height = rng.uniform(0.2, 0.35), rng.uniform(0.8, 2.2)
            s0, s1 = sorted((front, front + side.sign * thick))
            mat = Mat.BRICK if rng.random() < 0.5 else Mat.CONCRETE
            z0 = ground_z + kerb
            parts.append(_curved_block(road, u, u + length, s0, s1, z0, z0 + height, mat))
        else:
            thick, height = rng.uniform(0.7, 1.2), rng.uniform(0.9, 1.8)
            s0, s1 = sorted((front, front + side.sign * thick))
            z0 = ground_z + kerb
            parts.append(_curved_block(road, u, u + length, s0, s1, z0, z0 + height, Mat.FOLIAGE))
        u += length + (rng.uniform(1.0, 8.0) if rng.random() < 0.5 else 0.0)
    return parts


def furniture(
    road: Road, side: Side, ground_z: float, rng: np.random.Generator
) -> tuple[list[TaggedMesh], list[Obstacle]]:
    """Street lights, signs, bollards and trees in one side's verge."""
    parts, obstacles = [], []
    z0 = ground_z + road.kerb_height
    v0, v1 = side.verge
    s_mid = (v0 + v1) / 2

    def place(u: float, s: float, radius: float) -> tuple[float, float]:
        x, y = road.to_xy(u, s)
        obstacles.append(Obstacle(float(x), float(y), 2 * radius, 2 * radius, 0.0))
        return float(x), float(y)

    u = U_RANGE[0] + rng.uniform(0, 30)
    while u < U_RANGE[1]:  # street lights with an arm over the road
        r, height = rng.uniform(0.08, 0.12), rng.uniform(6.0, 9.0)
        x, y = place(u, s_mid, r)
        parts.append(cylinder_part([x, y, z0], [x, y, z0 + height], r, Mat.METAL))
        arm = road.to_xy(u, s_mid - side.sign * rng.uniform(1.2, 2.0))
        top = z0 + height
        parts.append(cylinder_part([x, y, top], [arm[0], arm[1], top], 0.05, Mat.METAL))
        parts.append(
            box_part(
                [arm[0] - 0.3, arm[1] - 0.15, top - 0.2],
                [arm[0] + 0.3, arm[1] + 0.15, top],
                Mat.METAL,
            )
        )
        u += rng.uniform(20.0, 35.0)
    u = U_RANGE[0] + rng.uniform(0, 15)
    while u < U_RANGE[1]:  # signs and bollards
        s = rng.uniform(v0 + 0.2, v1 - 0.2)
        if rng.random() < 0.5:
            x, y = place(u, s, 0.05)
            parts.append(cylinder_part([x, y, z0], [x, y, z0 + 2.6], 0.04, Mat.METAL))
            half = rng.uniform(0.3, 0.45)
            ux, uy = math.cos(road.heading(u)), math.sin(road.heading(u))
            parts.append(
                box_part(
                    [x - 0.03, y - half, z0 + 2.2],
                    [x + 0.03, y + half, z0 + 2.2 + 2 * half],
                    Mat.SIGN,
                ).transformed(np.eye(3), [0.05 * ux, 0.05 * uy, 0.0])
            )
        else:
            for k in range(int(rng.integers(2, 5))):
                x, y = place(u + 1.5 * k, s, 0.08)
                parts.append(cylinder_part([x, y, z0], [x, y, z0 + 0.9], 0.08, Mat.METAL))
        u += rng.uniform(15.0, 40.0)
    if rng.random() < 0.7:  # a row of trees
        u = U_RANGE[0] + rng.uniform(0, 10)
        spacing = rng.uniform(8.0, 15.0)
        while u < U_RANGE[1]:
            if rng.random() < 0.85:
                r, trunk = rng.uniform(0.12, 0.25), rng.uniform(2.5, 4.0)
                x, y = place(u, s_mid, r)
                parts.append(cylinder_part([x, y, z0], [x, y, z0 + trunk], r, Mat.BARK))
                crown = rng.uniform([1.5, 1.5, 1.5], [3.0, 3.0, 2.5])
                parts.append(
                    ellipsoid_part([x, y, z0 + trunk + 0.9 * crown[2]], crown, Mat.FOLIAGE)
                )
            u += spacing * rng.uniform(0.8, 1.2)
    return parts, obstacles
