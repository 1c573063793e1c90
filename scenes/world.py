"""The synthetic driving world: a road with kerbs, buildings and street clutter, plus actors, as
triangle meshes in the LiDAR frame, and first-hit ray casting against it with embree.

Frame and time
    Everything is in the LiDAR frame at the frame's time stamp ``t = 0`` (x forward, y left, z up,
    metres, origin at the LiDAR). The ground plane is ``z = -lidar_height``. The ego vehicle drives
    along +x at ``ego_speed`` without yaw rate, so at time ``t`` the ego (and every sensor on it) sits
    ``ego_speed * t`` further along x, and an actor's mesh is translated by ``velocity * t``: that is
    how older radar scans are simulated (:meth:`World.actor_mesh_at`).

Streets
    Delft-like city streets (calibrated to View-of-Delft, issue 14): mostly one narrow lane each
    way, raised cycle paths or red cycle lanes on most sides, few cars and many cyclists and
    pedestrians (a median of 10 referable road users per frame, about 80 % of them cyclists
    and pedestrians; docs/SENSOR_STATS.md), and parked bicycles, bicycle racks and mopeds on verges and sidewalks.
    Those are :class:`Clutter`: static geometry that both sensors see but that is never an
    :class:`~scenes.actors.Actor`, so never a referent nor in ``label_2``; :attr:`World.clutter`
    records their VoD class and box.

Road
    A centreline ``y = offset + curvature * u**2 / 2`` (``u`` = x; gently curved, radius >= 300 m,
    or straight), with a lateral profile of bands (lanes, markings, parking, kerb, verge, bike path,
    sidewalk, yard) extruded along it: the carriageway is at ground level, everything beyond the
    kerbs is raised by ``kerb_height``. Right-hand traffic: the ego's lanes lie right of the
    centreline (``s < 0``), oncoming lanes left of it. Buildings, walls and hedges line the road
    beyond the yards; street lights, signs, bollards and trees stand in the verges.

Actors
    Cars (body + cabin + wheels), pedestrians (legs, torso, arms, head) and cyclists (bicycle +
    rider) are built in their own box frame and scaled so that their axis-aligned bounds are exactly
    the sampled ``l, w, h``: the :class:`~scenes.actors.Actor` box is the tight box of the mesh, with
    ``z`` at its geometric centre (a pedestrian on a sidewalk stands ``kerb_height`` higher).
    Velocities are ground velocities along the heading (cars 0..15 m/s in lanes, both directions, or
    parked; pedestrians 0..2 m/s along sidewalks or crossing; cyclists 2..7 m/s). Actor boxes never
    overlap each other, the ego vehicle, or the trunks and poles.

Materials
    Each face carries a :class:`Mat` (LiDAR reflectivity, radar behaviour of static surfaces) and
    an owner (actor index, or -1 for static geometry). The sensors read both from :class:`RayHits`.

Determinism: :func:`generate_world` draws everything from the generator it is given; the same seed
gives the same world, bit for bit.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

from scenes.actors import CLASSES, Actor
from scenes.calib import LIDAR_HEIGHT

# --------------------------------------------------------------------------------------------------
# Materials


class Mat(enum.IntEnum):
    """Surface materials (the integer is the index into :data:`MATERIALS`)."""

    ASPHALT = 0
    MARKING = 1
    BIKE_PATH = 2
    PAVING = 3
    GRASS = 4
    SOIL = 5
    BRICK = 6
    CONCRETE = 7
    GLASS_FACADE = 8
    METAL = 9
    SIGN = 10
    BARK = 11
    FOLIAGE = 12
    PAINT_DARK = 13
    PAINT_LIGHT = 14
    CAR_GLASS = 15
    RUBBER = 16
    CLOTHING = 17
    SKIN = 18
    BIKE_FRAME = 19


@dataclass(frozen=True)
class Material:
    """Sensor-facing properties of a surface.

    Attributes:
        reflectivity: LiDAR diffuse reflectivity in ``[0, 1]`` (retro-reflective signs near 1).
        lidar_dropout: Extra probability that a LiDAR return is lost (glass, foliage).
        lidar_depth_jitter: Extra range spread in metres (penetration into foliage).
        radar_rcs: RCS in dBsm of one radar detection on this surface (static clutter).
        radar_prob: Probability that one ray of the radar's visibility grid (0.4 x 1.5 degrees)
            hitting this static surface becomes a detection, before the SNR factor.
    """

    reflectivity: float
    lidar_dropout: float = 0.0
    lidar_depth_jitter: float = 0.0
    radar_rcs: float = -10.0
    radar_prob: float = 0.0


MATERIALS: tuple[Material, ...] = (
    Material(0.25, 0.1, radar_rcs=-28.0, radar_prob=0.012),  # ASPHALT (dark or wet: drops)
    Material(0.80, radar_rcs=-28.0, radar_prob=0.012),  # MARKING
    Material(0.30, radar_rcs=-27.0, radar_prob=0.012),  # BIKE_PATH (red asphalt)
    Material(0.35, radar_rcs=-25.0, radar_prob=0.02),  # PAVING
    Material(0.55, radar_rcs=-26.0, radar_prob=0.015),  # GRASS
    Material(0.30, radar_rcs=-28.0, radar_prob=0.004),  # SOIL
    Material(0.40, radar_rcs=-12.0, radar_prob=0.1),  # BRICK
    Material(0.45, radar_rcs=-10.0, radar_prob=0.1),  # CONCRETE
    Material(0.15, lidar_dropout=0.3, radar_rcs=-8.0, radar_prob=0.12),  # GLASS_FACADE
    Material(0.50, radar_rcs=0.0, radar_prob=0.5),  # METAL (poles, racks)
    Material(0.95, radar_rcs=4.0, radar_prob=0.6),  # SIGN (retro-reflective)
    Material(0.35, radar_rcs=-14.0, radar_prob=0.15),  # BARK
    Material(0.60, 0.25, 0.6, radar_rcs=-22.0, radar_prob=0.04),  # FOLIAGE
    Material(0.20, radar_rcs=-6.0, radar_prob=0.3),  # PAINT_DARK (static: mopeds)
    Material(0.80, radar_rcs=-6.0, radar_prob=0.3),  # PAINT_LIGHT
    Material(0.06, lidar_dropout=0.4),  # CAR_GLASS
    Material(0.08, radar_rcs=-20.0, radar_prob=0.05),  # RUBBER
    Material(0.40, radar_rcs=-20.0, radar_prob=0.05),  # CLOTHING (panniers)
    Material(0.50),  # SKIN
    Material(0.45, radar_rcs=-12.0, radar_prob=0.3),  # BIKE_FRAME (parked bicycles)
)
"""Material properties indexed by :class:`Mat`."""

REFLECTIVITY = np.array([m.reflectivity for m in MATERIALS])
LIDAR_DROPOUT = np.array([m.lidar_dropout for m in MATERIALS])
LIDAR_DEPTH_JITTER = np.array([m.lidar_depth_jitter for m in MATERIALS])
RADAR_RCS = np.array([m.radar_rcs for m in MATERIALS])
RADAR_PROB = np.array([m.radar_prob for m in MATERIALS])


# --------------------------------------------------------------------------------------------------
# Meshes with per-face tags


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


def ellipsoid_part(centre: Sequence[float], radii: Sequence[float], mat: Mat) -> TaggedMesh:
    """An axis-aligned ellipsoid (80-face icosphere, scaled)."""
    verts, faces = _unit_sphere()
    return _part(verts * np.asarray(radii, float) + np.asarray(centre, float), faces, mat)


def _fit_to_box(mesh: TaggedMesh, size: np.ndarray) -> TaggedMesh:
    """Scale and shift ``mesh`` so that its axis-aligned bounds are ``[-size/2, size/2]``."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    verts = (mesh.vertices - (lo + hi) / 2.0) * (np.asarray(size) / (hi - lo))
    return TaggedMesh(verts, mesh.faces, mesh.material, mesh.owner)


# --------------------------------------------------------------------------------------------------
# Actor meshes, in the actor's box frame (centre at the origin, heading +x, z up)

CAR_SIZE = ((3.5, 5.0), (1.6, 2.0), (1.4, 1.8))
PEDESTRIAN_SIZE = ((0.5, 0.9), (0.5, 0.9), (1.5, 1.9))
CYCLIST_SIZE = ((1.6, 1.9), (0.5, 0.8), (1.5, 1.9))
"""``(l, w, h)`` ranges in metres per class."""


def car_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A car: bevelled body, glass cabin with a painted roof, four wheels. Bounds = ``size``."""
    l, w, h = size
    zb = -h / 2.0
    paint = Mat.PAINT_DARK if rng.random() < 0.5 else Mat.PAINT_LIGHT
    clearance, r_wheel = 0.17, rng.uniform(0.30, 0.35)
    body_top = zb + h * rng.uniform(0.52, 0.60)
    hl, hw = l / 2.0, w / 2.0
    nose, tail = rng.uniform(0.10, 0.25), rng.uniform(0.05, 0.15)
    body = hexahedron_part(
        _corners(
            x_bottom=(-hl, hl),
            x_top=(-hl + tail, hl - nose),
            y_bottom=hw,
            y_top=hw * 0.97,
            z=(zb + clearance, body_top),
        ),
        paint,
    )
    rear = -hl + l * rng.uniform(0.08, 0.22)
    front = hl - l * rng.uniform(0.30, 0.38)
    cabin = hexahedron_part(
        _corners(
            x_bottom=(rear, front),
            x_top=(rear + 0.15, front - rng.uniform(0.35, 0.6)),
            y_bottom=hw * 0.94,
            y_top=hw * 0.80,
            z=(body_top, zb + h),
        ),
        Mat.CAR_GLASS,
        top_mat=paint,
    )
    parts = [body, cabin]
    axle = hl - rng.uniform(0.65, 0.90)
    for x in (-axle, axle):
        for side in (-1.0, 1.0):
            y_out, y_in = side * (hw - 0.02), side * (hw - 0.24)
            parts.append(
                cylinder_part(
                    [x, y_in, zb + r_wheel], [x, y_out, zb + r_wheel], r_wheel, Mat.RUBBER
                )
            )
    return _fit_to_box(TaggedMesh.concatenate(parts), size)


def _corners(
    x_bottom: tuple[float, float],
    x_top: tuple[float, float],
    y_bottom: float,
    y_top: float,
    z: tuple[float, float],
) -> np.ndarray:
    """Hexahedron corners (unit-box order) of a prism symmetric in y, tapering from bottom to top."""
    out = np.zeros((8, 3))
    for i in range(8):
        bx, by, bz = (i >> 2) & 1, (i >> 1) & 1, i & 1
        xs = x_top if bz else x_bottom
        half = y_top if bz else y_bottom
        out[i] = (xs[bx], half if by else -half, z[bz])
    return out


def pedestrian_mesh(size: np.ndarray, walking: bool, rng: np.random.Generator) -> TaggedMesh:
    """A pedestrian in outdoor clothes: two legs (in stride when walking), hips, coat-clad torso,
    two arms, head, and sometimes a shoulder bag or backpack. Bounds = ``size``."""
    h = 1.75
    stride = rng.uniform(0.22, 0.32) if walking else rng.uniform(0.0, 0.05)
    hip, shoulder = 0.48 * h, 0.82 * h
    parts = []
    for side, phase in ((-1.0, 1.0), (1.0, -1.0)):
        foot = [phase * stride, side * 0.1, 0.05]
        parts.append(cylinder_part([0.0, side * 0.1, hip], foot, 0.085, Mat.CLOTHING))
        hand = [-phase * stride * 0.8, side * 0.25, 0.47 * h]
        parts.append(cylinder_part([0.0, side * 0.21, shoulder], hand, 0.055, Mat.CLOTHING))
    parts.append(ellipsoid_part([0.0, 0.0, hip + 0.02], [0.13, 0.19, 0.13], Mat.CLOTHING))
    parts.append(
        ellipsoid_part([0.0, 0.0, (hip + shoulder) / 2 + 0.03], [0.15, 0.22, 0.3], Mat.CLOTHING)
    )
    if rng.random() < 0.4:
        parts.append(ellipsoid_part([-0.2, 0.0, 0.7 * h], [0.1, 0.16, 0.2], Mat.CLOTHING))
    parts.append(ellipsoid_part([0.02, 0.0, h - 0.11], [0.1, 0.085, 0.11], Mat.SKIN))
    mesh = TaggedMesh.concatenate(parts)
    return _fit_to_box(mesh, size)


def bicycle_parts(rng: np.random.Generator) -> list[TaggedMesh]:
    """A Dutch city bicycle (wheels with mudguards, frame, chain guard, handlebar, often a crate or
    panniers) in its own frame: wheels at ``x = +-0.52``, ground at ``z = 0``, heading +x."""
    r = 0.34
    rear, front = [-0.52, 0.0, r], [0.52, 0.0, r]
    bracket, seat, stem = [-0.05, 0.0, 0.30], [-0.22, 0.0, 0.88], [0.38, 0.0, 0.98]
    parts = [cylinder_part([x, -0.03, r], [x, 0.03, r], r, Mat.RUBBER) for x in (rear[0], front[0])]
    for x in (rear[0], front[0]):  # mudguards over the upper half of the wheels
        parts.append(box_part([x - 0.3, -0.05, r + 0.12], [x + 0.3, 0.05, r + 0.4], Mat.BIKE_FRAME))
    for a, b in ((rear, bracket), (bracket, seat), (seat, stem), (stem, front), (rear, seat)):
        parts.append(cylinder_part(a, b, 0.03, Mat.BIKE_FRAME))
    parts.append(box_part([-0.55, -0.06, 0.22], [0.0, 0.06, 0.42], Mat.BIKE_FRAME))  # chain guard
    parts.append(cylinder_part([0.38, -0.3, 1.0], [0.38, 0.3, 1.0], 0.025, Mat.BIKE_FRAME))
    load = rng.random()
    if load < 0.35:  # front crate
        parts.append(box_part([0.45, -0.2, 0.72], [0.85, 0.2, 1.0], Mat.BIKE_FRAME))
    elif load < 0.7:  # rear rack with panniers
        parts.append(box_part([-0.75, -0.24, 0.45], [-0.3, 0.24, 0.8], Mat.CLOTHING))
    return parts


def cyclist_mesh(size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """A cyclist: a city bicycle (:func:`bicycle_parts`) and a rider in a jacket (a backpack
    sometimes). Bounds = ``size``."""
    parts = bicycle_parts(rng)
    lean = rng.uniform(0.25, 0.4)
    shoulders = [-0.2 + lean, 0.0, 1.42]
    parts.append(cylinder_part([-0.22, 0.0, 0.85], shoulders, 0.22, Mat.CLOTHING))
    if rng.random() < 0.3:  # backpack
        parts.append(
            ellipsoid_part([shoulders[0] - 0.3, 0.0, 1.2], [0.12, 0.16, 0.22], Mat.CLOTHING)
        )
    parts.append(ellipsoid_part([shoulders[0] + 0.06, 0.0, 1.61], [0.11, 0.1, 0.12], Mat.SKIN))
    crank = rng.uniform(0, 2 * np.pi)
    for side, phase in ((-1.0, 0.0), (1.0, np.pi)):
        pedal = [
            -0.05 + 0.17 * np.cos(crank + phase),
            side * 0.12,
            0.3 + 0.17 * np.sin(crank + phase),
        ]
        parts.append(cylinder_part([-0.2, side * 0.12, 0.92], pedal, 0.09, Mat.CLOTHING))
        parts.append(
            cylinder_part(
                [shoulders[0], side * 0.22, 1.4], [0.36, side * 0.27, 1.0], 0.06, Mat.CLOTHING
            )
        )
    return _fit_to_box(TaggedMesh.concatenate(parts), size)


# --------------------------------------------------------------------------------------------------
# Road


@dataclass(frozen=True)
class Band:
    """One lateral strip of the road profile, from ``s0`` to ``s1`` (m, left of the centreline).

    Attributes:
        z: Height of its surface above the ground (0 or the kerb height).
        dashed: A marking drawn as 3 m dashes with 6 m gaps (asphalt in between).
    """

    s0: float
    s1: float
    mat: Mat
    z: float = 0.0
    dashed: bool = False


@dataclass(frozen=True)
class Side:
    """Lateral layout of one side of the road (``s`` signed: negative right, positive left).

    Each ``(a, b)`` interval has ``a < b``; ``None`` where the side has no such strip.
    """

    sign: float
    lane_centres: tuple[float, ...]
    parking: tuple[float, float] | None
    carriageway_edge: float
    verge: tuple[float, float]
    bike_path: tuple[float, float] | None
    sidewalk: tuple[float, float]
    building_line: float
    cycle_lane: tuple[float, float] | None = None


@dataclass(frozen=True)
class Road:
    """A road along +x: centreline ``y = offset + curvature * u**2 / 2`` and its lateral profile.

    Attributes:
        curvature: 1/m (0 = straight).
        offset: Centreline y at x = 0 (the ego drives in a right-hand lane at y = 0).
        lane_width: m.
        ego_lane: Index of the ego's lane, counted from the centreline (0 = innermost).
        kerb_height: m, height of everything beyond the carriageway.
        right, left: The two sides' layouts.
        bands: The whole profile from right to left.
    """

    curvature: float
    offset: float
    lane_width: float
    ego_lane: int
    kerb_height: float
    right: Side
    left: Side
    bands: tuple[Band, ...]

    def centre(self, u: np.ndarray) -> np.ndarray:
        """Centreline points ``(..., 2)`` at abscissa ``u``."""
        u = np.asarray(u, float)
        return np.stack([u, self.offset + 0.5 * self.curvature * u**2], axis=-1)

    def heading(self, u: np.ndarray | float) -> np.ndarray | float:
        """Centreline heading (rad, from +x) at ``u``."""
        return np.arctan(self.curvature * np.asarray(u, float))

    def to_xy(self, u: np.ndarray, s: np.ndarray) -> np.ndarray:
        """LiDAR-frame ``(..., 2)`` of the point at abscissa ``u``, lateral offset ``s`` (left +)."""
        if np.ndim(u) == 0 and np.ndim(s) == 0:  # scalar fast path (placement)
            u, s = float(u), float(s)
            theta = math.atan(self.curvature * u)
            y = self.offset + 0.5 * self.curvature * u * u
            return np.array([u - s * math.sin(theta), y + s * math.cos(theta)])
        u, s = np.broadcast_arrays(np.asarray(u, float), np.asarray(s, float))
        theta = np.arctan(self.curvature * u)
        normal = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
        return self.centre(u) + s[..., None] * normal

    def surface_height(self, s: float) -> float:
        """Height above the ground of the profile at lateral offset ``s``."""
        for band in self.bands:
            if band.s0 <= s <= band.s1:
                return band.z
        return 0.0


def _make_side(
    sign: float, lanes: int, lane_width: float, kerb: float, rng: np.random.Generator
) -> tuple[Side, list[Band]]:
    """One side's layout and bands, walking outwards from the centreline."""
    bands: list[Band] = []

    def strip(width: float, mat: Mat, z: float = 0.0, dashed: bool = False) -> tuple[float, float]:
        nonlocal edge
        a, b = sorted((sign * edge, sign * (edge + width)))
        bands.append(Band(a, b, mat, z, dashed))
        edge += width
        return a, b

    edge = 0.06  # half the centre line (drawn by the caller)
    centres = []
    for lane in range(lanes):
        a, b = strip(lane_width - 0.12, Mat.ASPHALT)
        centres.append((a + b) / 2)
        strip(0.12, Mat.MARKING, dashed=lane < lanes - 1)
    separate_path = rng.random() < 0.65  # a raised cycle path, else often a red cycle lane
    cycle_lane = None
    if not separate_path and rng.random() < 0.75:
        cycle_lane = strip(rng.uniform(1.5, 1.9), Mat.BIKE_PATH)
    parking = strip(rng.uniform(2.0, 2.3), Mat.ASPHALT) if rng.random() < 0.45 else None
    carriageway = sign * edge
    verge = strip(rng.uniform(1.0, 2.5), Mat.PAVING if rng.random() < 0.5 else Mat.GRASS, kerb)
    bike = strip(rng.uniform(1.8, 2.6), Mat.BIKE_PATH, kerb) if separate_path else None
    sidewalk = strip(rng.uniform(1.8, 3.5), Mat.PAVING, kerb)
    strip(rng.uniform(0.0, 2.5) + 0.01, Mat.PAVING if rng.random() < 0.6 else Mat.GRASS, kerb)
    side = Side(
        sign=sign,
        lane_centres=tuple(centres),
        parking=parking,
        carriageway_edge=carriageway,
        verge=verge,
        bike_path=bike,
        sidewalk=sidewalk,
        building_line=sign * edge,
        cycle_lane=cycle_lane,
    )
    return side, bands


def make_road(rng: np.random.Generator) -> Road:
    """A random road layout (see the module docstring)."""
    curvature = 0.0 if rng.random() < 0.5 else rng.uniform(-1.0, 1.0) / 300.0
    lane_width = rng.uniform(2.8, 3.4)  # Delft city streets: mostly one lane each way
    lanes_same = 1 if rng.random() < 0.8 else 2
    lanes_opp = 1 if rng.random() < 0.85 else 2
    kerb = rng.uniform(0.10, 0.16)
    right, right_bands = _make_side(-1.0, lanes_same, lane_width, kerb, rng)
    left, left_bands = _make_side(1.0, lanes_opp, lane_width, kerb, rng)
    centre_line = Band(-0.06, 0.06, Mat.MARKING, 0.0, lanes_same + lanes_opp == 2)
    bands = tuple(sorted([*right_bands, centre_line, *left_bands], key=lambda b: b.s0))
    ego_lane = int(rng.integers(0, lanes_same))
    return Road(
        curvature=curvature,
        offset=-right.lane_centres[ego_lane],
        lane_width=lane_width,
        ego_lane=ego_lane,
        kerb_height=kerb,
        right=right,
        left=left,
        bands=bands,
    )


U_RANGE = (-30.0, 150.0)
"""Abscissa range of the modelled road (m); the LiDAR looks forward, so little is behind."""

_SEGMENT = 1.5  # m, tessellation of dashed markings: dashes are 2 segments on, 4 off
_COARSE = 7.5  # m, tessellation of everything else on a curved road (chord sag ~2 cm)


def _strip(
    road: Road, u: np.ndarray, s: tuple[float, float], z: tuple[float, float], mats: np.ndarray
) -> TaggedMesh:
    """A ruled strip between the curves ``(u, s[0], z[0])`` and ``(u, s[1], z[1])``; ``mats`` per
    segment."""
    n = len(u)
    j = np.arange(n - 1)
    faces = np.stack([np.stack([j, j + n, j + 1], 1), np.stack([j + 1, j + n, j + n + 1], 1)], 1)
    verts = np.concatenate(
        [
            np.hstack([road.to_xy(u, np.full(n, s_k)), np.full((n, 1), z_k)])
            for s_k, z_k in zip(s, z, strict=True)
        ]
    )
    return TaggedMesh(
        verts,
        faces.reshape(-1, 3),
        np.repeat(np.asarray(mats, np.int16), 2),
        np.full(2 * (n - 1), -1, np.int32),
    )


def road_mesh(road: Road, ground_z: float) -> TaggedMesh:
    """The extruded profile (band tops + kerb faces) and a large soil plane just below it."""
    fine = np.arange(U_RANGE[0], U_RANGE[1] + 1e-9, _SEGMENT)
    coarse = fine[:: int(round(_COARSE / _SEGMENT))] if road.curvature != 0 else fine[[0, -1]]
    dash_on = (np.arange(len(fine) - 1) % 6) < 2
    parts = []
    for band in road.bands:
        z = ground_z + band.z
        if band.dashed:
            mats = np.where(dash_on, int(band.mat), int(Mat.ASPHALT))
            parts.append(_strip(road, fine, (band.s0, band.s1), (z, z), mats))
        else:
            mats = np.full(len(coarse) - 1, int(band.mat))
            parts.append(_strip(road, coarse, (band.s0, band.s1), (z, z), mats))
    for lower, upper in zip(road.bands[:-1], road.bands[1:], strict=True):
        if abs(lower.z - upper.z) > 1e-6:  # a kerb face
            mats = np.full(len(coarse) - 1, int(Mat.CONCRETE))
            zs = (ground_z + lower.z, ground_z + upper.z)
            parts.append(_strip(road, coarse, (lower.s1, lower.s1), zs, mats))
    lo, hi = U_RANGE[0] - 20, U_RANGE[1] + 60
    parts.append(box_part([lo, -200.0, ground_z - 0.05], [hi, 200.0, ground_z - 0.02], Mat.SOIL))
    return TaggedMesh.concatenate(parts)


# --------------------------------------------------------------------------------------------------
# Static clutter


@dataclass(frozen=True)
class Obstacle:
    """A static footprint actors must not overlap: a BEV box ``(x, y, l, w, yaw)``."""

    x: float
    y: float
    l: float
    w: float
    yaw: float


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


def _frontage(
    road: Road, side: Side, ground_z: float, rng: np.random.Generator
) -> list[TaggedMesh]:
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


def _furniture(
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


# --------------------------------------------------------------------------------------------------
# Parked bicycles, bicycle racks and mopeds: street clutter, never a referent

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
    return _fit_to_box(TaggedMesh.concatenate(parts), size)


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


def _street_clutter(
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
        if taken and _overlaps_any(bev, 0.1, taken, [0.1] * len(taken)):
            return None
        taken.append(bev)
        obstacles.append(Obstacle(float(x), float(y), float(size[0]), float(size[1]), yaw))
        return np.array([x, y, z0 + size[2] / 2, *size, yaw])

    def add(cls: str, mesh: TaggedMesh, box: np.ndarray) -> None:
        centre = np.array([box[0], box[1], box[2] - box[5] / 2])
        parts.append(mesh.transformed(_rotation_z(box[6]), centre))
        items.append(Clutter(cls, box))

    def bicycle(size: np.ndarray) -> TaggedMesh:
        mesh = _fit_to_box(TaggedMesh.concatenate(bicycle_parts(rng)), size)
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


# --------------------------------------------------------------------------------------------------
# Actor placement


def _bev_overlap(a: np.ndarray, b: np.ndarray, margin: float) -> bool:
    """Separating-axis test of two BEV boxes ``(x, y, l, w, yaw)``, each grown by ``margin / 2``."""
    axes, halves = [], []
    for box in (a, b):
        c, s = math.cos(box[4]), math.sin(box[4])
        axes.append((np.array([c, s]), np.array([-s, c])))
        halves.append(((box[2] + margin) / 2, (box[3] + margin) / 2))
    d = np.array([b[0] - a[0], b[1] - a[1]])
    for ax_pair in axes:
        for axis in ax_pair:
            reach = 0.0
            for (ua, va), (hl, hw) in zip(axes, halves, strict=True):
                reach += hl * abs(axis @ ua) + hw * abs(axis @ va)
            if abs(axis @ d) > reach:
                return False
    return True


def _overlaps_any(
    bev: np.ndarray, margin: float, taken: list[np.ndarray], taken_margin: list[float]
) -> bool:
    """Whether ``bev`` overlaps any taken box (bounding circles first, then the exact test)."""
    others = np.asarray(taken)
    margins = np.maximum(margin, np.asarray(taken_margin))
    reach = 0.5 * (np.hypot(bev[2], bev[3]) + np.hypot(others[:, 2], others[:, 3])) + margins
    near = np.hypot(others[:, 0] - bev[0], others[:, 1] - bev[1]) < reach
    return any(_bev_overlap(bev, others[k], margins[k]) for k in np.flatnonzero(near))


EGO_FOOTPRINT = np.array([-0.6, 0.0, 4.6, 1.9, 0.0])
"""The ego vehicle's BEV box ``(x, y, l, w, yaw)`` around the LiDAR (kept free of actors)."""


@dataclass(frozen=True)
class WorldConfig:
    """Ranges of the random world.

    Attributes:
        cars, pedestrians, cyclists: Inclusive ranges of actor counts (placement may drop a few).
        ego_speed: Range of the ego speed along +x (m/s); ``ego_stopped`` is the chance it is 0.
        near_u: Abscissa range where most actors are placed (the annotated area and the camera
            view); ``far_fraction`` of them go to ``far_u`` instead.
        lidar_height: Ground plane at ``z = -lidar_height``.
    """

    cars: tuple[int, int] = (1, 5)
    pedestrians: tuple[int, int] = (3, 9)
    cyclists: tuple[int, int] = (3, 9)
    ego_speed: tuple[float, float] = (0.0, 12.0)
    ego_stopped: float = 0.1
    near_u: tuple[float, float] = (4.0, 50.0)
    far_u: tuple[float, float] = (50.0, 85.0)
    far_fraction: float = 0.15
    lidar_height: float = LIDAR_HEIGHT


@dataclass(frozen=True)
class _Candidate:
    cls: str
    u: float
    s: float
    yaw_offset: float  # relative to the road heading at u
    speed: float
    walking: bool = False


def _car_candidate(road: Road, u: float, rng: np.random.Generator) -> _Candidate:
    r = rng.random()
    parking = [side for side in (road.right, road.left) if side.parking is not None]
    if parking and r < 0.3:
        side = parking[int(rng.integers(0, len(parking)))]
        s = sum(side.parking) / 2 + rng.normal(0, 0.1)
        flip = np.pi if (side.sign > 0) != (rng.random() < 0.15) else 0.0
        return _Candidate("Car", u, s, flip + rng.normal(0, 0.03), 0.0)
    if r < 0.65:
        lane = int(rng.integers(0, len(road.right.lane_centres)))
        if lane == road.ego_lane:
            u = max(u, 8.0)
        speed = 0.0 if rng.random() < 0.1 else rng.uniform(2.0, 15.0)
        s = road.right.lane_centres[lane] + rng.normal(0, 0.15)
        return _Candidate("Car", u, s, rng.normal(0, 0.02), speed)
    lane = int(rng.integers(0, len(road.left.lane_centres)))
    s = road.left.lane_centres[lane] + rng.normal(0, 0.15)
    speed = 0.0 if rng.random() < 0.05 else rng.uniform(2.0, 15.0)
    return _Candidate("Car", u, s, np.pi + rng.normal(0, 0.02), speed)


def _pedestrian_candidate(road: Road, u: float, rng: np.random.Generator) -> _Candidate:
    r = rng.random()
    side = road.right if rng.random() < 0.5 else road.left
    if r < 0.25:  # crossing the carriageway
        s = rng.uniform(road.right.carriageway_edge + 0.5, road.left.carriageway_edge - 0.5)
        yaw = (np.pi / 2 if rng.random() < 0.5 else -np.pi / 2) + rng.normal(0, 0.15)
        return _Candidate("Pedestrian", u, s, yaw, rng.uniform(0.8, 2.0), walking=True)
    s = rng.uniform(side.sidewalk[0] + 0.4, side.sidewalk[1] - 0.4)
    if r < 0.65:  # walking along
        yaw = (0.0 if rng.random() < 0.5 else np.pi) + rng.normal(0, 0.1)
        return _Candidate("Pedestrian", u, s, yaw, rng.uniform(0.6, 2.0), walking=True)
    return _Candidate("Pedestrian", u, s, rng.uniform(-np.pi, np.pi), 0.0)


def _cyclist_candidate(road: Road, u: float, rng: np.random.Generator) -> _Candidate:
    r = rng.random()
    speed = rng.uniform(2.0, 7.0)
    if r < 0.2:  # crossing (junctions, exits)
        s = rng.uniform(road.right.carriageway_edge + 1.0, road.left.carriageway_edge - 1.0)
        yaw = (np.pi / 2 if rng.random() < 0.5 else -np.pi / 2) + rng.normal(0, 0.1)
        return _Candidate("Cyclist", u, s, yaw, min(speed, 5.0))
    side = road.right if rng.random() < 0.6 else road.left
    with_traffic = 0.0 if side.sign < 0 else np.pi
    if side.bike_path is not None:
        a, b = side.bike_path
        s = rng.uniform(a + 0.4, b - 0.4)
        yaw = with_traffic if rng.random() < 0.75 else np.pi - with_traffic
    elif side.cycle_lane is not None:  # on the red cycle lane
        a, b = side.cycle_lane
        s = rng.uniform(a + 0.35, b - 0.35)
        yaw = with_traffic
    else:  # on the road next to the kerb or the parked cars
        edge = (
            side.carriageway_edge
            if side.parking is None
            else side.parking[1 if side.sign < 0 else 0]
        )
        s = edge - side.sign * rng.uniform(0.7, 1.1)
        yaw = with_traffic
    return _Candidate("Cyclist", u, s, yaw + rng.normal(0, 0.05), speed)


_CANDIDATES = {
    "Car": _car_candidate,
    "Pedestrian": _pedestrian_candidate,
    "Cyclist": _cyclist_candidate,
}
_SIZES = {"Car": CAR_SIZE, "Pedestrian": PEDESTRIAN_SIZE, "Cyclist": CYCLIST_SIZE}
_MARGIN = {"Car": 0.8, "Pedestrian": 0.2, "Cyclist": 0.4}


def _actor_mesh(cand: _Candidate, size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    if cand.cls == "Car":
        return car_mesh(size, rng)
    if cand.cls == "Pedestrian":
        return pedestrian_mesh(size, cand.walking, rng)
    return cyclist_mesh(size, rng)


def _rotation_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --------------------------------------------------------------------------------------------------
# The world


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
            parts.append(mesh.with_owner(i).transformed(_rotation_z(actor.box[6]), centre))
        return TaggedMesh.concatenate(parts)

    def ego_position(self, time: float = 0.0) -> np.ndarray:
        """``(3,)`` offset of the ego vehicle (and its sensors) at ``time`` from its ``t = 0`` pose."""
        return np.array([self.ego_speed * time, 0.0, 0.0])

    def boxes(self) -> np.ndarray:
        """``(K, 7)`` boxes of all actors (LiDAR frame)."""
        return np.array([a.box for a in self.actors]).reshape(-1, 7)


def generate_world(
    rng: np.random.Generator, world_id: int = 0, config: WorldConfig = WorldConfig()
) -> World:
    """A random world (see the module docstring); all randomness comes from ``rng``."""
    ground_z = -config.lidar_height
    road = make_road(rng)
    static_parts = [road_mesh(road, ground_z)]
    obstacles: list[Obstacle] = []
    clutter: list[Clutter] = []
    for side in (road.right, road.left):
        static_parts += _frontage(road, side, ground_z, rng)
        parts, obs = _furniture(road, side, ground_z, rng)
        static_parts += parts
        obstacles += obs
    for side in (road.right, road.left):
        parts, items = _street_clutter(road, side, ground_z, obstacles, rng)
        static_parts += parts
        clutter += items

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
                cand = _CANDIDATES[cls](road, u, rng)
                size = np.array([rng.uniform(*r) for r in _SIZES[cls]])
                xy = road.to_xy(cand.u, cand.s)
                yaw = float(road.heading(cand.u)) + cand.yaw_offset
                bev = np.array([xy[0], xy[1], size[0], size[1], yaw])
                margin = _MARGIN[cls]
                if _overlaps_any(bev, margin, taken, taken_margin):
                    continue
                z = ground_z + road.surface_height(cand.s) + size[2] / 2
                yaw = float(np.mod(yaw + np.pi, 2 * np.pi) - np.pi)
                velocity = cand.speed * np.array([math.cos(yaw), math.sin(yaw)])
                box = np.array([xy[0], xy[1], z, *size, yaw])
                actors.append(Actor(len(actors), cls, box, velocity))
                meshes.append(_actor_mesh(cand, size, rng))
                taken.append(bev)
                taken_margin.append(margin)
                break
    ego_speed = 0.0 if rng.random() < config.ego_stopped else rng.uniform(*config.ego_speed)
    return World(
        world_id=world_id,
        road=road,
        lidar_height=config.lidar_height,
        ego_speed=float(ego_speed),
        actors=tuple(actors),
        static_mesh=TaggedMesh.concatenate(static_parts),
        actor_meshes=tuple(meshes),
        clutter=tuple(clutter),
    )


# --------------------------------------------------------------------------------------------------
# Ray casting


@dataclass(frozen=True)
class RayHits:
    """First hits of a batch of ``R`` rays.

    Attributes:
        hit: ``(R,)`` bool.
        distance: ``(R,)`` metres along the unit direction (inf where no hit).
        points: ``(R, 3)`` hit points, LiDAR frame (NaN where no hit).
        cos_incidence: ``(R,)`` ``|cos|`` of the angle between the ray and the face normal.
        material: ``(R,)`` :class:`Mat` value (-1 where no hit).
        owner: ``(R,)`` actor index, -1 for static geometry (and where no hit).
    """

    hit: np.ndarray
    distance: np.ndarray
    points: np.ndarray
    cos_incidence: np.ndarray
    material: np.ndarray
    owner: np.ndarray


class _MeshCaster:
    """First-hit queries on one :class:`TaggedMesh` through trimesh's embree intersector."""

    def __init__(self, mesh: TaggedMesh) -> None:
        self.mesh = mesh
        self.empty = len(mesh.faces) == 0
        if self.empty:
            return
        self.intersector = RayMeshIntersector(mesh.to_trimesh())
        tri = mesh.vertices[mesh.faces]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(normal, axis=1, keepdims=True)
        self.normal = normal / np.where(norm > 0, norm, 1.0)
        self.anchor = tri[:, 0]

    def cast(self, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(R,)`` triangle index (-1 = miss) and distance (inf = miss)."""
        r = len(origins)
        if self.empty or r == 0:
            return np.full(r, -1), np.full(r, np.inf)
        tri = np.asarray(self.intersector.intersects_first(origins, dirs), dtype=np.int64)
        dist = np.full(r, np.inf)
        ok = tri >= 0
        n = self.normal[tri[ok]]
        denom = np.einsum("ij,ij->i", dirs[ok], n)
        num = np.einsum("ij,ij->i", self.anchor[tri[ok]] - origins[ok], n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / denom
        t[~np.isfinite(t) | (np.abs(denom) < 1e-12) | (t < 0)] = np.inf
        dist[ok] = t
        tri[~np.isfinite(dist)] = -1
        return tri, dist


class RayCaster:
    """First-hit ray casting against a :class:`World` at a time offset.

    The static geometry's embree scene is built once; the actors' scene once per queried time
    (actors move, the static world does not).
    """

    def __init__(self, world: World) -> None:
        self.world = world
        self._static = _MeshCaster(world.static_mesh)
        self._actors: dict[float, _MeshCaster] = {}

    @property
    def uses_embree(self) -> bool:
        """True when the intersector is trimesh's embree one (it always is: no fallback)."""
        return self._static.empty or isinstance(self._static.intersector, RayMeshIntersector)

    def _actor_caster(self, time: float) -> _MeshCaster:
        key = round(float(time), 6)
        if key not in self._actors:
            self._actors[key] = _MeshCaster(self.world.actor_mesh_at(key))
        return self._actors[key]

    def cast(self, origins: np.ndarray, dirs: np.ndarray, time: float = 0.0) -> RayHits:
        """Cast rays ``origins (R, 3)`` along unit ``dirs (R, 3)`` (LiDAR frame of ``t = 0``) at
        ``time`` (the actors' positions; the caller places the origins)."""
        origins = np.ascontiguousarray(origins, dtype=np.float64)
        dirs = np.ascontiguousarray(dirs, dtype=np.float64)
        s_tri, s_dist = self._static.cast(origins, dirs)
        dyn = self._actor_caster(time)
        a_tri, a_dist = dyn.cast(origins, dirs)
        use_actor = a_dist < s_dist
        dist = np.where(use_actor, a_dist, s_dist)
        hit = np.isfinite(dist)
        r = len(origins)
        material = np.full(r, -1, np.int64)
        owner = np.full(r, -1, np.int64)
        cos_inc = np.zeros(r)
        sel = hit & ~use_actor
        if sel.any():
            material[sel] = self._static.mesh.material[s_tri[sel]]
            cos_inc[sel] = np.abs(np.einsum("ij,ij->i", dirs[sel], self._static.normal[s_tri[sel]]))
        sel = hit & use_actor
        if sel.any():
            material[sel] = dyn.mesh.material[a_tri[sel]]
            owner[sel] = dyn.mesh.owner[a_tri[sel]]
            cos_inc[sel] = np.abs(np.einsum("ij,ij->i", dirs[sel], dyn.normal[a_tri[sel]]))
        points = origins + dirs * np.where(hit, dist, np.nan)[:, None]
        return RayHits(hit, dist, points, cos_inc, material, owner)
