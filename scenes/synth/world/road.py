"""The street layout: a curved or straight centreline with a lateral profile of bands (lanes,
markings, parking, cycle lanes, kerbs, verges, bike paths, sidewalks, yards), and its mesh in the
LiDAR frame (the carriageway at ground level, everything beyond the kerbs raised)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenes.synth.world.materials import Mat
from scenes.synth.world.meshes import TaggedMesh, box_part


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
