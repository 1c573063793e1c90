"""Triangle meshes whose faces carry a material and an owner (:class:`TaggedMesh`), and the
primitive parts the world is built from (boxes, hexahedra, cylinders, ellipsoids), in whatever
frame the caller gives their coordinates in."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache

import numpy as np
import trimesh

from scenes.synth.world.materials import Mat


@dataclass(frozen=True)
class TaggedMesh:
    """A triangle soup whose faces carry a material and an owner.

    Attributes:
        vertices: ``(V, 3)`` float64.
        faces: ``(F, 3)`` int64 vertex indices.
        material: ``(F,)`` int16 :class:`Mat` values.
        owner: ``(F,)`` int32: index into :attr:`World.actors`, or -1 for static geometry.
    """

    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)
    material: np.ndarray = field(repr=False)
    owner: np.ndarray = field(repr=False)

    @staticmethod
    def empty() -> TaggedMesh:
        return TaggedMesh(
            np.zeros((0, 3)),
            np.zeros((0, 3), np.int64),
            np.zeros(0, np.int16),
            np.zeros(0, np.int32),
        )

    @staticmethod
    def concatenate(parts: Sequence[TaggedMesh]) -> TaggedMesh:
        """One mesh from several (vertex indices shifted)."""
        if not parts:
            return TaggedMesh.empty()
        offsets = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
        return TaggedMesh(
            np.concatenate([p.vertices for p in parts]),
            np.concatenate([p.faces + o for p, o in zip(parts, offsets, strict=True)]),
            np.concatenate([p.material for p in parts]).astype(np.int16),
            np.concatenate([p.owner for p in parts]).astype(np.int32),
        )

    def with_owner(self, owner: int) -> TaggedMesh:
        return TaggedMesh(
            self.vertices, self.faces, self.material, np.full(len(self.faces), owner, np.int32)
        )

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> TaggedMesh:
        """Vertices mapped by ``rotation (3, 3) @ v + translation (3,)``."""
        return TaggedMesh(
            self.vertices @ np.asarray(rotation).T + np.asarray(translation),
            self.faces,
            self.material,
            self.owner,
        )

    def to_trimesh(self) -> trimesh.Trimesh:
        """A :class:`trimesh.Trimesh` (unprocessed: vertices and faces kept as they are)."""
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


@cache
def _unit_box() -> tuple[np.ndarray, np.ndarray]:
    """Corners of ``[-0.5, 0.5]^3`` (index bits: x, y, z = 4, 2, 1) and their 12 triangles."""
    box = trimesh.creation.box()
    return np.asarray(box.vertices), np.asarray(box.faces, dtype=np.int64)


@cache
def _unit_cylinder(sections: int) -> tuple[np.ndarray, np.ndarray]:
    """Radius 1, axis z from 0 to 1."""
    cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=sections)
    return np.asarray(cyl.vertices) + np.array([0.0, 0.0, 0.5]), np.asarray(cyl.faces, np.int64)


@cache
def _unit_sphere() -> tuple[np.ndarray, np.ndarray]:
    sph = trimesh.creation.icosphere(subdivisions=1)
    return np.asarray(sph.vertices), np.asarray(sph.faces, dtype=np.int64)


def _part(vertices: np.ndarray, faces: np.ndarray, mat: Mat) -> TaggedMesh:
    return TaggedMesh(
        np.asarray(vertices, dtype=np.float64),
        faces,
        np.full(len(faces), int(mat), np.int16),
        np.full(len(faces), -1, np.int32),
    )


def box_part(lo: Sequence[float], hi: Sequence[float], mat: Mat) -> TaggedMesh:
    """Axis-aligned box from corner ``lo`` to ``hi``."""
    verts, faces = _unit_box()
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return _part((verts + 0.5) * (hi - lo) + lo, faces, mat)


def hexahedron_part(corners: np.ndarray, mat: Mat, top_mat: Mat | None = None) -> TaggedMesh:
    """A convex hexahedron with the unit box's topology.

    Args:
        corners: ``(8, 3)`` in the unit box's vertex order (index bits x, y, z = 4, 2, 1, i.e.
            corner ``i`` is at the ``-``/``+`` side of x when bit 4 is 0/1, etc.).
        top_mat: Material of the two upward faces (e.g. a car roof), default ``mat``.
    """
    _, faces = _unit_box()
    part = _part(corners, faces, mat)
    if top_mat is not None:
        tri = part.vertices[faces]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        part.material[normal[:, 2] > 0.7] = int(top_mat)
    return part


def _frame_for(direction: Sequence[float]) -> np.ndarray:
    """A rotation whose third column is the unit ``direction`` (scalar maths: called per part)."""
    dx, dy, dz = (float(v) for v in direction)
    n = math.sqrt(dx * dx + dy * dy + dz * dz)
    dx, dy, dz = dx / n, dy / n, dz / n
    if abs(dx) < 0.9:  # u = x_axis x d
        ux, uy, uz = 0.0, -dz, dy
    else:  # u = y_axis x d
        ux, uy, uz = dz, 0.0, -dx
    m = math.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux / m, uy / m, uz / m
    vx, vy, vz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
    return np.array([[ux, vx, dx], [uy, vy, dy], [uz, vz, dz]])


def cylinder_part(p0: Sequence[float], p1: Sequence[float], radius: float, mat: Mat) -> TaggedMesh:
    """A cylinder from ``p0`` to ``p1``: 10-sided, 6-sided when thinner than 0.1 m in radius (limbs,
    tubes, thin poles: fewer faces make the per-scan embree scenes cheaper)."""
    verts, faces = _unit_cylinder(10 if radius >= 0.1 else 6)
    axis = [float(b) - float(a) for a, b in zip(p0, p1, strict=True)]
    length = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    frame = _frame_for(axis) * np.array([radius, radius, length])
    return _part(verts @ frame.T + np.asarray(p0, float), faces, mat)


def frustum_part(
    base: Sequence[float], height: float, r_bottom: float, r_top: float, mat: Mat
) -> TaggedMesh:
    """A vertical truncated cone (10-sided) standing on ``base`` (its bottom centre), radius
    ``r_bottom`` at the bottom and ``r_top`` (``>= 0``) at ``height`` above: traffic cones."""
    verts, faces = _unit_cylinder(10)
    z = verts[:, 2]
    radius = r_bottom + (r_top - r_bottom) * z
    out = np.stack([verts[:, 0] * radius, verts[:, 1] * radius, z * height], axis=1)
    return _part(out + np.asarray(base, float), faces, mat)


def ellipsoid_part(centre: Sequence[float], radii: Sequence[float], mat: Mat) -> TaggedMesh:
    """An axis-aligned ellipsoid (80-face icosphere, scaled)."""
    verts, faces = _unit_sphere()
    return _part(verts * np.asarray(radii, float) + np.asarray(centre, float), faces, mat)


def fit_to_box(mesh: TaggedMesh, size: np.ndarray) -> TaggedMesh:
    """Scale and shift ``mesh`` so that its axis-aligned bounds are ``[-size/2, size/2]``."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    verts = (mesh.vertices - (lo + hi) / 2.0) * (np.asarray(size) / (hi - lo))
    return TaggedMesh(verts, mesh.faces, mesh.material, mesh.owner)


def rotation_z(yaw: float) -> np.ndarray:
    """``(3, 3)`` rotation by ``yaw`` radians about +z."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
