"""Where actors go: per-class candidate positions, headings and speeds on the road layout (cars in
lanes or parked, pedestrians on sidewalks or crossing, cyclists on bike paths, cycle lanes or the
road), their size ranges and clearance margins, and their meshes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.synth.world.actor_meshes import (
    CAR_SIZE,
    CYCLIST_SIZE,
    PEDESTRIAN_SIZE,
    car_mesh,
    cyclist_mesh,
    pedestrian_mesh,
)
from scenes.synth.world.meshes import TaggedMesh
from scenes.synth.world.road import Road

EGO_FOOTPRINT = np.array([-0.6, 0.0, 4.6, 1.9, 0.0])
"""The ego vehicle's BEV box ``(x, y, l, w, yaw)`` around the LiDAR (kept free of actors)."""
EGO_FRONT = EGO_FOOTPRINT[0] + EGO_FOOTPRINT[2] / 2
"""x (m) of the ego's front bumper."""
LEAD_CAR_MIN_U = 8.0
LEAD_CAR_GAP = (1.5, 6.0)
"""A car drawn in the ego lane closer than ``LEAD_CAR_MIN_U`` is moved to a bumper-to-bumper gap
drawn from ``LEAD_CAR_GAP`` (m) ahead of the ego."""


@dataclass(frozen=True)
class Candidate:
    """Where one actor goes, in road coordinates, before its overlap test.

    Attributes:
        cls: Its class name.
        u, s: Abscissa and lateral offset (m, left +) of its box centre.
        yaw_offset: Heading relative to the road heading at ``u`` (rad).
        speed: Ground speed along the heading (m/s).
        walking: A pedestrian in stride.
        size: ``(l, w, h)`` when the placement drew it (groups whose members' positions depend on
            their sizes); None: drawn afterwards from :data:`SIZES`.
        kind: The shape variant for the mesh (``"ridden"``, ``"parked"``, ``"tractor"``; ``""``).
    """

    cls: str
    u: float
    s: float
    yaw_offset: float  # relative to the road heading at u
    speed: float
    walking: bool = False
    size: tuple[float, float, float] | None = None
    kind: str = ""


def _car_candidate(road: Road, u: float, rng: np.random.Generator) -> Candidate:
    r = rng.random()
    parking = [side for side in (road.right, road.left) if side.parking is not None]
    if parking and r < 0.3:
        side = parking[int(rng.integers(0, len(parking)))]
        s = sum(side.parking) / 2 + rng.normal(0, 0.1)
        flip = np.pi if (side.sign > 0) != (rng.random() < 0.15) else 0.0
        return Candidate("Car", u, s, flip + rng.normal(0, 0.03), 0.0)
    if r < 0.65:
        lane = int(rng.integers(0, len(road.right.lane_centres)))
        if lane == road.ego_lane and u < LEAD_CAR_MIN_U:
            # The car ahead in the ego lane: its centre is the ego's front bumper, half a car and a
            # bumper-to-bumper gap ahead (queues at lights and slow city traffic: 1.5-6 m).
            u = EGO_FRONT + 2.2 + rng.uniform(*LEAD_CAR_GAP)
        speed = 0.0 if rng.random() < 0.1 else rng.uniform(2.0, 15.0)
        s = road.right.lane_centres[lane] + rng.normal(0, 0.15)
        return Candidate("Car", u, s, rng.normal(0, 0.02), speed)
    lane = int(rng.integers(0, len(road.left.lane_centres)))
    s = road.left.lane_centres[lane] + rng.normal(0, 0.15)
    speed = 0.0 if rng.random() < 0.05 else rng.uniform(2.0, 15.0)
    return Candidate("Car", u, s, np.pi + rng.normal(0, 0.02), speed)


def _pedestrian_candidate(road: Road, u: float, rng: np.random.Generator) -> Candidate:
    r = rng.random()
    side = road.right if rng.random() < 0.5 else road.left
    if r < 0.25:  # crossing the carriageway
        s = rng.uniform(road.right.carriageway_edge + 0.5, road.left.carriageway_edge - 0.5)
        yaw = (np.pi / 2 if rng.random() < 0.5 else -np.pi / 2) + rng.normal(0, 0.15)
        return Candidate("Pedestrian", u, s, yaw, rng.uniform(0.8, 2.0), walking=True)
    s = rng.uniform(side.sidewalk[0] + 0.4, side.sidewalk[1] - 0.4)
    if r < 0.65:  # walking along
        yaw = (0.0 if rng.random() < 0.5 else np.pi) + rng.normal(0, 0.1)
        return Candidate("Pedestrian", u, s, yaw, rng.uniform(0.6, 2.0), walking=True)
    return Candidate("Pedestrian", u, s, rng.uniform(-np.pi, np.pi), 0.0)


def _cyclist_candidate(road: Road, u: float, rng: np.random.Generator) -> Candidate:
    r = rng.random()
    speed = rng.uniform(2.0, 7.0)
    if r < 0.25:  # crossing (junctions, exits)
        s = rng.uniform(road.right.carriageway_edge + 1.0, road.left.carriageway_edge - 1.0)
        yaw = (np.pi / 2 if rng.random() < 0.5 else -np.pi / 2) + rng.normal(0, 0.1)
        return Candidate("Cyclist", u, s, yaw, min(speed, 5.0))
    side = road.right if rng.random() < 0.6 else road.left
    with_traffic = 0.0 if side.sign < 0 else np.pi
    if r < 0.35:  # turning in or out at a junction, obliquely across the carriageway's edge
        s = side.carriageway_edge - side.sign * rng.uniform(0.8, 2.5)
        turn = rng.uniform(0.4, 1.1) * (1.0 if rng.random() < 0.5 else -1.0)
        return Candidate("Cyclist", u, s, with_traffic + turn, min(speed, 5.0))
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
    return Candidate("Cyclist", u, s, yaw + rng.normal(0, 0.05), speed)


CANDIDATES = {
    "Car": _car_candidate,
    "Pedestrian": _pedestrian_candidate,
    "Cyclist": _cyclist_candidate,
}
SIZES = {"Car": CAR_SIZE, "Pedestrian": PEDESTRIAN_SIZE, "Cyclist": CYCLIST_SIZE}
MARGIN = {"Car": 0.8, "Pedestrian": 0.2, "Cyclist": 0.4}


def actor_mesh(cand: Candidate, size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """The mesh of a car, pedestrian or cyclist candidate (box frame, bounds ``size``)."""
    if cand.cls == "Car":
        return car_mesh(size, rng)
    if cand.cls == "Pedestrian":
        return pedestrian_mesh(size, cand.walking, rng)
    return cyclist_mesh(size, rng)
