"""Which road users a world holds, per class set, and where the ones beyond cars, pedestrians and
cyclists go: the world facts of the ``nuscenes`` class set (size spreads, speeds, placement rules,
clearance margins, shapes); the class facts (names, nouns, mean sizes) are
:mod:`scenes.geometry.classes`'.

A world is populated by a *plan*: an ordered tuple of :class:`Placement` (what it places, how many
per world, and a function drawing one group of :class:`~scenes.synth.world.placement.Candidate`
at an abscissa). :func:`plan` gives the ``vod`` plan (cars, pedestrians, cyclists, as the world
always had, draw for draw) or the ``nuscenes`` one:

=====================  =======================================================================
placement              what it places
=====================  =======================================================================
road works             a lane closed for works: a taper and a line of traffic cones along the
                       lane's inner marking, a barrier across the lane at each end, and (70 %)
                       a construction vehicle inside, standing or creeping; in the ego lane
                       ahead half the time ("the cones in our lane")
bus                    at a stop by the kerb (45 %: standing, or pulling away at 0.6-2.5 m/s)
                       or in a lane (3-12 m/s, either direction)
truck                  parked at the kerb (35 %), moving in a lane (40 %), or a tractor unit
                       towing a semi-trailer (25 %: the ``Trailer`` right behind it, same speed)
trailer                a semi-trailer parked at the kerb on its landing legs
car, pedestrian        as in the ``vod`` world
motorcycle             ridden in a lane (60 %, 3-14 m/s) or parked at the kerb or on the
                       sidewalk
bicycle                ridden, where the ``vod`` world's cyclists ride (the ``nuscenes`` set's
                       ``Bicycle`` box holds the bicycle and its rider, as nuScenes boxes it)
=====================  =======================================================================

In a ``nuscenes`` world the street clutter's parked bicycles and mopeds are road users too
(``Bicycle`` and ``Motorcycle`` actors, parked: nuScenes labels them; :func:`clutter_actors`);
bicycle racks stay clutter.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from scenes.geometry.classes import NUSCENES, PRESETS
from scenes.synth.world.actor_meshes import CYCLIST_SIZE, cyclist_mesh
from scenes.synth.world.clutter import Clutter
from scenes.synth.world.meshes import TaggedMesh, rotation_z
from scenes.synth.world.placement import (
    CANDIDATES,
    EGO_FRONT,
    LEAD_CAR_GAP,
    MARGIN,
    SIZES,
    Candidate,
    actor_mesh,
)
from scenes.synth.world.road import Road, Side
from scenes.synth.world.road_user_meshes import (
    barrier_mesh,
    bus_mesh,
    cone_mesh,
    construction_vehicle_mesh,
    motorcycle_mesh,
    trailer_mesh,
    truck_mesh,
)

__all__ = [
    "CLASS_SETS",
    "NUSCENES_PLAN",
    "RANGES",
    "ROAD_USER_MARGIN",
    "Placement",
    "clutter_actors",
    "margin_of",
    "plan",
    "road_user_mesh",
]

Ranges = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
PlaceFn = Callable[[Road, float, np.random.Generator], list[Candidate]]


@dataclass(frozen=True)
class Placement:
    """One line of a world's plan.

    Attributes:
        name: What it places (a class name, or ``works`` for a road-works group).
        counts: Inclusive range of groups per world (placement may drop some in a crowded world).
        place: ``(road, u, rng) -> candidates``: one group at abscissa ``u``, placed all or none.
    """

    name: str
    counts: tuple[int, int]
    place: PlaceFn


def _around(cls: str, spread: tuple[float, float, float]) -> Ranges:
    """``(l, w, h)`` ranges of +-``spread`` (shares) around the class's nuScenes mean size."""
    mean = NUSCENES.get(cls).mean_size
    lo_hi = [
        (round(m * (1 - s), 2), round(m * (1 + s), 2)) for m, s in zip(mean, spread, strict=True)
    ]
    return lo_hi[0], lo_hi[1], lo_hi[2]


RANGES: dict[tuple[str, str], Ranges] = {
    ("Truck", ""): _around("Truck", (0.25, 0.05, 0.15)),
    ("Truck", "tractor"): ((5.6, 6.8), (2.4, 2.6), (3.0, 3.8)),
    ("Bus", ""): _around("Bus", (0.15, 0.06, 0.1)),
    ("Trailer", ""): _around("Trailer", (0.12, 0.05, 0.08)),
    ("ConstructionVehicle", ""): _around("ConstructionVehicle", (0.15, 0.1, 0.12)),
    ("Motorcycle", "ridden"): ((1.9, 2.35), (0.7, 0.95), (1.45, 1.75)),
    ("Motorcycle", "parked"): ((1.65, 2.2), (0.6, 0.85), (1.05, 1.3)),
    ("Bicycle", "ridden"): CYCLIST_SIZE,
    ("TrafficCone", ""): _around("TrafficCone", (0.2, 0.2, 0.3)),
    ("Barrier", ""): _around("Barrier", (0.3, 0.25, 0.15)),
}
"""``(l, w, h)`` ranges (m) per class and shape variant: around the class's mean size (nuScenes'
training-set means, :data:`scenes.geometry.classes.NUSCENES`), narrower where the variant is
(a tractor unit, a ridden or a parked motorcycle, a ridden bicycle: the ``vod`` cyclist's)."""

ROAD_USER_MARGIN: dict[str, float] = {
    "Truck": 0.8,
    "Bus": 0.8,
    "Trailer": 0.6,
    "ConstructionVehicle": 0.6,
    "Motorcycle": 0.4,
    "Bicycle": 0.4,
    "TrafficCone": 0.1,
    "Barrier": 0.1,
}
"""Clearance (m) kept around each new class's box (:data:`scenes.synth.world.placement.MARGIN`
for the ``vod`` classes)."""


def margin_of(cls: str) -> float:
    """The clearance margin of a class (m)."""
    return MARGIN[cls] if cls in MARGIN else ROAD_USER_MARGIN[cls]


def _size(cls: str, rng: np.random.Generator, kind: str = "") -> tuple[float, float, float]:
    l, w, h = (float(rng.uniform(*r)) for r in RANGES[(cls, kind)])
    return l, w, h


def _with_traffic(side: Side) -> float:
    """Heading offset of traffic on ``side`` (right-hand traffic: the right side goes +u)."""
    return 0.0 if side.sign < 0 else np.pi


def _pick_side(road: Road, rng: np.random.Generator, p_right: float) -> Side:
    return road.right if rng.random() < p_right else road.left


def _lane_centre(side: Side, rng: np.random.Generator) -> float:
    return side.lane_centres[int(rng.integers(0, len(side.lane_centres)))]


def _kerb_s(side: Side, width: float) -> float:
    """Lateral offset of a vehicle of ``width`` standing by the kerb (in the parking strip when the
    side has one)."""
    if side.parking is not None:
        return sum(side.parking) / 2
    return side.carriageway_edge - side.sign * (width / 2 + 0.25)


def _vehicle(cls: str, road: Road, u: float, rng: np.random.Generator, kind: str = "") -> Candidate:
    """A vehicle in a lane, moving with the traffic (10 % stopped in it); one drawn in the ego
    lane with its rear closer than a bumper-to-bumper gap of ``LEAD_CAR_GAP`` is moved to such
    a gap ahead of the ego, as the lead car is."""
    size = _size(cls, rng, kind)
    side = _pick_side(road, rng, 0.55)
    lane = int(rng.integers(0, len(side.lane_centres)))
    s = side.lane_centres[lane] + rng.normal(0, 0.12)
    if (
        side is road.right
        and lane == road.ego_lane
        and u - size[0] / 2 < EGO_FRONT + LEAD_CAR_GAP[0]
    ):
        u = EGO_FRONT + size[0] / 2 + rng.uniform(*LEAD_CAR_GAP)
    speed = 0.0 if rng.random() < 0.1 else rng.uniform(3.0, 12.0)
    return Candidate(
        cls, u, s, _with_traffic(side) + rng.normal(0, 0.02), speed, size=size, kind=kind
    )


def _parked(cls: str, road: Road, u: float, rng: np.random.Generator, kind: str = "") -> Candidate:
    """A vehicle parked by the kerb, mostly facing the traffic's way."""
    size = _size(cls, rng, kind)
    side = _pick_side(road, rng, 0.6)
    s = _kerb_s(side, size[1]) + rng.normal(0, 0.08)
    flip = np.pi if rng.random() < 0.15 else 0.0
    return Candidate(
        cls, u, s, _with_traffic(side) + flip + rng.normal(0, 0.03), 0.0, size=size, kind=kind
    )


def _bus(road: Road, u: float, rng: np.random.Generator) -> list[Candidate]:
    if rng.random() < 0.45:  # at a stop by the kerb, standing or pulling away
        size = _size("Bus", rng)
        side = _pick_side(road, rng, 0.7)
        s = _kerb_s(side, size[1]) + rng.normal(0, 0.05)
        speed = 0.0 if rng.random() < 0.65 else rng.uniform(0.6, 2.5)
        return [Candidate("Bus", u, s, _with_traffic(side) + rng.normal(0, 0.02), speed, size=size)]
    return [_vehicle("Bus", road, u, rng)]


def _truck(road: Road, u: float, rng: np.random.Generator) -> list[Candidate]:
    r = rng.random()
    if r < 0.35:
        return [_parked("Truck", road, u, rng)]
    if r < 0.75:
        return [_vehicle("Truck", road, u, rng)]
    tractor = (
        _vehicle("Truck", road, u, rng, "tractor")
        if rng.random() < 0.6
        else _parked("Truck", road, u, rng, "tractor")
    )
    size = _size("Trailer", rng)
    tractor_length = tractor.size[0] if tractor.size is not None else 0.0  # always drawn above
    back = tractor_length / 2 + size[0] / 2 + 0.2
    heading = float(np.cos(tractor.yaw_offset))  # +1 along +u, -1 against
    trailer = replace(
        tractor, cls="Trailer", u=tractor.u - np.sign(heading) * back, size=size, kind=""
    )
    return [tractor, trailer]


def _trailer(road: Road, u: float, rng: np.random.Generator) -> list[Candidate]:
    return [_parked("Trailer", road, u, rng)]


def _works(road: Road, u: float, rng: np.random.Generator) -> list[Candidate]:
    """A lane closed for works (module docstring); the group starts at ``u`` on the right side
    (the traffic's approach end) and ends there on the left."""
    side = _pick_side(road, rng, 0.65)
    lane = _lane_centre(side, rng)
    lw = road.lane_width
    inner = lane - side.sign * lw / 2  # the lane's marking towards the centreline
    outer = lane + side.sign * (lw / 2 - 0.35)
    length = rng.uniform(14.0, 26.0)
    along = 1.0 if side.sign < 0 else -1.0  # the direction the traffic on this side goes
    start = u if along > 0 else u + length
    out: list[Candidate] = []

    def cone(cu: float, cs: float) -> None:
        out.append(
            Candidate(
                "TrafficCone", cu, cs, rng.normal(0, 0.3), 0.0, size=_size("TrafficCone", rng)
            )
        )

    for k in range(3):  # the taper, from the kerb side to the marking, before the closure
        t = k / 2
        cone(start + along * (-5.0 + 2.5 * k), outer + (inner - outer) * t)
    for end in (start + along * 1.0, start + along * (length - 0.5)):
        size = _size("Barrier", rng)
        size = (size[0], min(size[1], lw - 0.8), size[2])
        out.append(
            Candidate("Barrier", end, lane + side.sign * 0.15, rng.normal(0, 0.03), 0.0, size=size)
        )
    d = 3.0
    step = rng.uniform(2.5, 4.0)
    while d < length - 1.5:
        cone(start + along * d, inner + rng.normal(0, 0.04))
        d += step
    if rng.random() < 0.7:
        l, w, h = _size("ConstructionVehicle", rng)
        w = min(w, lw - 0.7)
        l = min(l, length - 5.0)
        speed = 0.0 if rng.random() < 0.7 else rng.uniform(0.6, 1.5)
        yaw = (0.0 if rng.random() < 0.5 else np.pi) + rng.normal(0, 0.05)
        mid = start + along * length / 2
        out.append(
            Candidate(
                "ConstructionVehicle", mid, lane + side.sign * 0.1, yaw, speed, size=(l, w, h)
            )
        )
    return out


def _motorcycle(road: Road, u: float, rng: np.random.Generator) -> list[Candidate]:
    if rng.random() < 0.6:
        size = _size("Motorcycle", rng, "ridden")
        side = _pick_side(road, rng, 0.55)
        s = _lane_centre(side, rng) + rng.normal(0, 0.4)
        speed = 0.0 if rng.random() < 0.08 else rng.uniform(3.0, 14.0)
        yaw = _with_traffic(side) + rng.normal(0, 0.04)
        return [Candidate("Motorcycle", u, s, yaw, speed, size=size, kind="ridden")]
    size = _size("Motorcycle", rng, "parked")
    side = _pick_side(road, rng, 0.5)
    if rng.random() < 0.5:
        a, b = side.sidewalk
        s = rng.uniform(a + size[1], b - size[1])
    else:
        s = side.carriageway_edge - side.sign * (size[1] / 2 + 0.3)
    yaw = (0.0 if rng.random() < 0.5 else np.pi) + rng.normal(0, 0.2)
    return [Candidate("Motorcycle", u, s, yaw, 0.0, size=size, kind="parked")]


def _bicycle(road: Road, u: float, rng: np.random.Generator) -> list[Candidate]:
    cand = CANDIDATES["Cyclist"](road, u, rng)
    return [replace(cand, cls="Bicycle", size=_size("Bicycle", rng, "ridden"), kind="ridden")]


def _single(cls: str) -> PlaceFn:
    """The ``vod`` placement of ``cls`` as a group of one."""
    candidate = CANDIDATES[cls]
    return lambda road, u, rng: [candidate(road, u, rng)]


NUSCENES_PLAN: tuple[Placement, ...] = (
    Placement("works", (0, 2), _works),
    Placement("Bus", (0, 1), _bus),
    Placement("Truck", (0, 2), _truck),
    Placement("Trailer", (0, 1), _trailer),
    Placement("Car", (1, 4), _single("Car")),
    Placement("Motorcycle", (0, 2), _motorcycle),
    Placement("Bicycle", (1, 5), _bicycle),
    Placement("Pedestrian", (3, 8), _single("Pedestrian")),
)
"""The ``nuscenes`` world's plan (module docstring), in placement order: the large and grouped
road users first, so that the rest find room around them."""

CLASS_SETS = tuple(PRESETS)
"""The class sets a world can be populated for (``WorldConfig.classes``)."""


def plan(classes: str, counts: dict[str, tuple[int, int]] | None = None) -> tuple[Placement, ...]:
    """The plan of a world for the class set ``classes``; ``counts``: the ``vod`` plan's ranges
    per class (``WorldConfig``'s cars, pedestrians, cyclists). ValueError for another set."""
    if classes == "vod":
        counts = counts or {}
        return tuple(Placement(c, counts[c], _single(c)) for c in ("Car", "Pedestrian", "Cyclist"))
    if classes == "nuscenes":
        return NUSCENES_PLAN
    raise ValueError(f"unknown class set {classes!r}: one of {CLASS_SETS}")


def default_size(cand: Candidate, rng: np.random.Generator) -> np.ndarray:
    """The candidate's size: its own, or drawn from :data:`scenes.synth.world.placement.SIZES`."""
    if cand.size is not None:
        return np.array(cand.size, dtype=np.float64)
    return np.array([rng.uniform(*r) for r in SIZES[cand.cls]])


_MESHES: dict[str, Callable[[Candidate, np.ndarray, np.random.Generator], TaggedMesh]] = {
    "Truck": lambda c, size, rng: truck_mesh(size, c.kind == "tractor", rng),
    "Bus": lambda c, size, rng: bus_mesh(size, rng),
    "Trailer": lambda c, size, rng: trailer_mesh(size, rng),
    "ConstructionVehicle": lambda c, size, rng: construction_vehicle_mesh(size, rng),
    "Motorcycle": lambda c, size, rng: motorcycle_mesh(size, c.kind != "parked", rng),
    "Bicycle": lambda c, size, rng: cyclist_mesh(size, rng),
    "TrafficCone": lambda c, size, rng: cone_mesh(size, rng),
    "Barrier": lambda c, size, rng: barrier_mesh(size, rng),
}
"""The shape of each new class (box frame, bounds = its size)."""


def road_user_mesh(cand: Candidate, size: np.ndarray, rng: np.random.Generator) -> TaggedMesh:
    """The mesh of any candidate (box frame, centre at the origin, bounds ``size``)."""
    if cand.cls in _MESHES:
        return _MESHES[cand.cls](cand, size, rng)
    return actor_mesh(cand, size, rng)


PARKED_CLUTTER = {"bicycle": "Bicycle", "moped_scooter": "Motorcycle"}
"""The street clutter that is a road user of the ``nuscenes`` class set (parked)."""


def clutter_actors(
    parts: list[TaggedMesh], items: list[Clutter]
) -> tuple[list[TaggedMesh], list[Clutter], list[tuple[str, np.ndarray, TaggedMesh]]]:
    """Split street clutter (``parts[i]`` is ``items[i]``'s mesh in the LiDAR frame) into what
    stays clutter and the parked road users of :data:`PARKED_CLUTTER`: ``(class, box (7,), mesh
    in its box frame)`` each."""
    keep_parts, keep_items, users = [], [], []
    for part, item in zip(parts, items, strict=True):
        if item.cls not in PARKED_CLUTTER:
            keep_parts.append(part)
            keep_items.append(item)
            continue
        box = np.asarray(item.box, dtype=np.float64)
        bottom = np.array([box[0], box[1], box[2] - box[5] / 2])
        local = part.transformed(np.eye(3), -bottom).transformed(
            rotation_z(-float(box[6])), [0.0, 0.0, -box[5] / 2]
        )
        users.append((PARKED_CLUTTER[item.cls], box, local))
    return keep_parts, keep_items, users
