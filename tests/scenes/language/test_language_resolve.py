"""scenes.language.query and scenes.language.resolve: each operator on hand-built scenes, the
borderline refusals, and the query reader's errors. The expected referents are worked out by hand
in the comments (LiDAR frame, x forward, y left)."""

from __future__ import annotations

import math

import pytest

from scenes.geometry.actors import Actor
from scenes.geometry.classes import NUSCENES
from scenes.language.query import QueryError, parse_query
from scenes.language.resolve import resolve

CAR = (4.0, 2.0, 1.5)
PED = (0.6, 0.6, 1.7)
CYC = (1.8, 0.6, 1.7)
SIZES = {"Car": CAR, "Pedestrian": PED, "Cyclist": CYC}


def actor(i: int, cls: str, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> Actor:
    size = SIZES[cls]
    return Actor(i, cls, [x, y, size[2] / 2, *size, 0.0], [vx, vy])


def ids(query: dict, actors: list[Actor]) -> tuple[int, ...] | None:
    """The referents, or None when refused."""
    res = resolve(parse_query(query), actors)
    return None if res.refused is not None else res.ids


# Cars: 0 parked left at depth 8 (x 10), 1 driving away ahead at 25 km/h, 2 approaching on the
# right, 3 parked far right at depth 38. Pedestrians: 10 crossing (vy = 1.4), 11 standing left.
# Cyclists: 20 away at 5 m/s ahead-left, 21 behind the ego (outside the area), 22 at 80 m.
SCENE = [
    actor(0, "Car", 10.0, 4.0),
    actor(1, "Car", 20.0, 0.0, vx=25 / 3.6),
    actor(2, "Car", 30.0, -5.0, vx=-4.5),
    actor(3, "Car", 40.0, -8.0),
    actor(10, "Pedestrian", 15.0, -3.0, vy=1.4),
    actor(11, "Pedestrian", 25.0, 6.0),
    actor(20, "Cyclist", 35.0, 2.5, vx=5.0),
    actor(21, "Cyclist", -8.0, 0.0, vx=3.0),
    actor(22, "Cyclist", 80.0, 0.0, vx=3.0),
]
STILL = {"op": "not", "cond": {"op": "moving"}}


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        ({"class": "Car"}, (0, 1, 2, 3)),
        ({"class": "Car", "where": [STILL]}, (0, 3)),
        ({"class": "Car", "where": [{"op": "moving"}]}, (1, 2)),
        ({"class": "Car", "where": [{"op": "side", "side": "left"}]}, (0,)),
        ({"class": "Car", "where": [{"op": "side", "side": "right"}]}, (2, 3)),
        ({"class": "Car", "where": [{"op": "side", "side": "ahead"}]}, (1,)),
        ({"class": "Car", "where": [{"op": "heading", "heading": "away"}]}, (1,)),
        ({"class": "Car", "where": [{"op": "heading", "heading": "approaching"}]}, (2,)),
        ({"class": "Pedestrian", "where": [{"op": "heading", "heading": "crossing"}]}, (10,)),
        # depth = x - 2 for a car (half of 4 m), x - 0.9 for a cyclist
        ({"class": "Car", "where": [{"op": "depth_about", "m": 18}]}, (1,)),
        ({"class": "Car", "where": [{"op": "depth_beyond", "m": 20}]}, (2, 3)),
        ({"class": "Car", "where": [{"op": "depth_within", "m": 12}]}, (0,)),
        ({"class": "Car", "where": [{"op": "depth_between", "m": [15, 30]}]}, (1, 2)),
        ({"class": "Car", "where": [{"op": "speed_above", "value": 20, "unit": "kmh"}]}, (1,)),
        ({"class": "Car", "where": [{"op": "speed_below", "value": 4, "unit": "mps"}]}, ()),
        ({"class": "Car", "where": [{"op": "speed_about", "value": 25, "unit": "kmh"}]}, (1,)),
        ({"class": "Cyclist"}, (20,)),  # 21 is behind us, 22 beyond 50 m and its edge band
        (
            {"class": "Car", "where": [{"op": "not", "cond": {"op": "side", "side": "right"}}]},
            (0, 1),
        ),
        ({"where": [STILL]}, (0, 3, 11)),
        ({"out_of_class": "bus"}, ()),
    ],
)
def test_conditions(query: dict, expected: tuple[int, ...]) -> None:
    assert ids(query, SCENE) == expected


def test_ranks_and_their_gaps() -> None:
    # ranges: car 0 10.8, car 1 20.0, car 2 30.4, car 3 40.8
    assert ids({"class": "Car", "rank": {"by": "nearest", "index": 2}}, SCENE) == (1,)
    assert ids({"class": "Car", "rank": {"by": "farthest", "index": 2}}, SCENE) == (2,)
    assert ids({"class": "Car", "rank": {"by": "leftmost", "index": 1}}, SCENE) == (0,)
    assert ids({"class": "Car", "rank": {"by": "rightmost", "index": 2}}, SCENE) == (2,)
    assert ids({"class": "Car", "rank": {"by": "fastest", "index": 2}}, SCENE) == (2,)
    # slowest: cars 0 and 3 stand still, so "the slowest car" could be either: refused
    assert ids({"class": "Car", "rank": {"by": "slowest", "index": 1}}, SCENE) is None
    moving = {"class": "Car", "where": [{"op": "moving"}], "rank": {"by": "slowest", "index": 1}}
    assert ids(moving, SCENE) == (2,)
    assert ids({"class": "Car", "rank": {"by": "nearest", "index": 5}}, SCENE) is None
    # two pedestrians 1 m apart in range: too close to tell the second nearest
    close = [actor(0, "Pedestrian", 10.0, 0.5), actor(1, "Pedestrian", 11.0, -0.5)]
    assert ids({"class": "Pedestrian", "rank": {"by": "nearest", "index": 2}}, close) is None
    # range and nearest-point depth disagree: an 8 m long car at 16 m (depth 12) and a pedestrian
    # at (13, 6): range 14.3, nearer than the car's 16, but depth 12.7, farther than 12
    long_car = Actor(0, "Car", [16.0, 0.0, 0.75, 8.0, 2.0, 1.5, 0.0], [0.0, 0.0])
    readings = [long_car, actor(1, "Pedestrian", 13.0, 6.0)]
    assert ids({"rank": {"by": "nearest"}}, readings) is None
    assert ids({"rank": {"by": "farthest"}}, readings) is None


def test_exclusion() -> None:
    # nearest car is 0; the rest are 1, 2, 3
    assert ids({"class": "Car", "except": {"rank": {"by": "nearest"}}}, SCENE) == (1, 2, 3)
    assert ids({"class": "Car", "except": {"where": [STILL]}}, SCENE) == (1, 2)
    # one pedestrian: "all except the nearest" leaves nothing, refused
    lone = [actor(0, "Pedestrian", 10.0, 0.0)]
    assert ids({"class": "Pedestrian", "except": {"rank": {"by": "nearest"}}}, lone) is None
    # nothing to remove ("all cars except the ones behind us"): refused too
    behind = {"where": [{"op": "depth_within", "m": -10}]}
    assert ids({"class": "Car", "except": behind}, SCENE) is None


def test_relations() -> None:
    nearest_car = {"class": "Car", "rank": {"by": "nearest"}}
    scene = [
        actor(0, "Car", 12.0, 0.0),
        actor(1, "Pedestrian", 11.5, 3.0),  # 3 m from the car, left of it
        actor(2, "Pedestrian", 33.0, 0.5),  # behind the car, on our line of sight to it
        actor(3, "Pedestrian", 6.0, -0.3),  # in front of it
        actor(4, "Cyclist", 24.0, 0.0),
        actor(5, "Car", 35.0, -6.0),
    ]
    assert ids({"class": "Pedestrian", "where": [{"op": "near", "of": nearest_car}]}, scene) == (1,)
    assert ids({"class": "Pedestrian", "where": [{"op": "behind", "of": nearest_car}]}, scene) == (
        2,
    )
    assert ids(
        {"class": "Pedestrian", "where": [{"op": "in_front_of", "of": nearest_car}]}, scene
    ) == (3,)
    assert ids({"class": "Pedestrian", "where": [{"op": "left_of", "of": nearest_car}]}, scene) == (
        1,
    )
    assert (
        ids({"class": "Pedestrian", "where": [{"op": "right_of", "of": nearest_car}]}, scene) == ()
    )
    between = {"op": "between", "of": [nearest_car, {"class": "Cyclist"}]}
    assert ids({"class": "Pedestrian", "where": [between]}, scene) == ()
    scene.append(actor(6, "Pedestrian", 18.0, 0.8))
    assert ids({"class": "Pedestrian", "where": [between]}, scene) == (6,)
    closest = {
        "class": "Pedestrian",
        "rank": {"by": "nearest_to", "index": 1, "of": {"class": "Cyclist"}},
    }
    assert ids(closest, scene) == (6,)
    # "the car" with two cars is an ambiguous reference object: refused
    assert (
        ids({"class": "Pedestrian", "where": [{"op": "near", "of": {"class": "Car"}}]}, scene)
        is None
    )
    # never related to itself: the car nearest to the nearest car is the other one
    assert ids(
        {"class": "Car", "rank": {"by": "nearest_to", "index": 1, "of": nearest_car}}, scene
    ) == (5,)


def test_borderline_refusals() -> None:
    # moving threshold 0.5 m/s, slack 0.2: 0.6 m/s is borderline, 0.8 is clear
    for speed, expected in ((0.6, None), (0.8, (0,)), (0.35, None), (0.25, ())):
        scene = [actor(0, "Pedestrian", 10.0, 0.0, vx=speed)]
        assert ids({"class": "Pedestrian", "where": [{"op": "moving"}]}, scene) == expected
    # left = y > 1.5, slack 0.3: y = 1.6 is borderline
    assert (
        ids(
            {"class": "Car", "where": [{"op": "side", "side": "left"}]},
            [actor(0, "Car", 20.0, 1.6)],
        )
        is None
    )
    # an actor at x = 52 m (edge band) that would match makes the set ambiguous
    edge = [actor(0, "Car", 20.0, 0.0), actor(1, "Car", 52.0, 0.0)]
    assert ids({"class": "Car"}, edge) is None
    # ... but not the nearest car, which it cannot be
    assert ids({"class": "Car", "rank": {"by": "nearest"}}, edge) == (0,)
    # "the" presumes one
    two = [actor(0, "Car", 20.0, 3.0), actor(1, "Car", 30.0, 4.0)]
    assert ids({"class": "Car", "one": True}, two) is None
    assert ids({"class": "Car", "one": True}, two[:1]) == (0,)


def test_crossing_angle_and_bearing() -> None:
    # velocity 45 degrees off the y axis: not crossing (limit 30, slack 5)
    v = 2.0 / math.sqrt(2)
    diagonal = [actor(0, "Pedestrian", 10.0, 0.0, vx=v, vy=v)]
    assert (
        ids({"class": "Pedestrian", "where": [{"op": "heading", "heading": "crossing"}]}, diagonal)
        == ()
    )
    # bearing 40 degrees: outside the annotated area and its 5 degree band, so not counted
    wide = [actor(0, "Car", 10.0, 10.0 * math.tan(math.radians(40)))]
    assert ids({"class": "Car"}, wide) == ()


# Road users of the nuscenes class set: trucks 30 (parked left at x 15) and 31 (left at x 30,
# driving away), 32 (right); cones 40, 41 in our lane and 42 on the right; a bus 50 pulling away
# ahead-right; a motorcycle 60 riding away ahead, 61 parked on the right.
def road_user(i: int, cls: str, x: float, y: float, vx: float = 0.0) -> Actor:
    size = NUSCENES.get(cls).mean_size
    return Actor(i, cls, [x, y, size[2] / 2, *size, 0.0], [vx, 0.0])


ROAD_USERS = [
    road_user(30, "Truck", 15.0, 5.0),
    road_user(31, "Truck", 30.0, 5.5, vx=8.0),
    road_user(32, "Truck", 25.0, -6.0),
    road_user(40, "TrafficCone", 12.0, 0.3),
    road_user(41, "TrafficCone", 15.0, -0.2),
    road_user(42, "TrafficCone", 15.0, -4.0),
    road_user(50, "Bus", 40.0, -4.5, vx=1.5),
    road_user(60, "Motorcycle", 22.0, 0.0, vx=6.0),
    road_user(61, "Motorcycle", 18.0, -5.0),
]


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        ({"class": "TrafficCone", "where": [{"op": "side", "side": "ahead"}]}, (40, 41)),
        ({"class": "Truck", "where": [{"op": "side", "side": "left"}]}, (30, 31)),
        (
            {
                "class": "Truck",
                "where": [{"op": "side", "side": "left"}],
                "rank": {"by": "nearest", "index": 2},
            },
            (31,),
        ),
        ({"class": "Truck", "where": [STILL, {"op": "side", "side": "right"}]}, (32,)),
        ({"class": "Motorcycle", "where": [{"op": "heading", "heading": "away"}]}, (60,)),
        ({"class": "Bus", "one": True}, (50,)),
        ({"class": "Barrier"}, ()),
    ],
)
def test_queries_over_the_road_users_of_the_nuscenes_set(query: dict, expected: tuple) -> None:
    """'the cones in our lane', 'the trucks on the left', 'the second truck on the left', 'the
    parked truck on the right', 'the motorcycle moving away from us', 'the bus'."""
    assert ids(query, ROAD_USERS) == expected


@pytest.mark.parametrize(
    ("query", "field"),
    [
        ({"class": "Tram"}, "query.class"),  # a Bus is a class (of the nuscenes set)
        ({"where": [{"op": "fly"}]}, "query.where[0]"),
        ({"where": [{"op": "side", "side": "up"}]}, "query.where[0].side"),
        ({"rank": {"by": "nearest", "index": 0}}, "query.rank.index"),
        ({"rank": {"by": "nearest_to"}}, "query.rank"),
        ({"out_of_class": "bus", "class": "Car"}, "query"),
        ({"colour": "red"}, "query"),
        ({"where": [{"op": "depth_between", "m": [20, 10]}]}, "query.where[0].m"),
        ({"where": [{"op": "speed_above", "value": 5, "unit": "mph"}]}, "query.where[0].unit"),
    ],
)
def test_query_errors_name_the_field(query: dict, field: str) -> None:
    with pytest.raises(QueryError) as info:
        parse_query(query)
    assert str(info.value).startswith(field + ":")
