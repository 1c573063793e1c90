"""Worlds of actors and sentence readers for the prompt tests (test_prompts, test_prompt_phrasing).

The readers (plural nouns, numbers in digits or words, counts) are written here independently of
``scenes.language.prompts``' own patterns, so the tests check the generator against a second reading.
"""

from __future__ import annotations

import math
import re

import numpy as np

from scenes.geometry.actors import Actor
from scenes.geometry.classes import NUSCENES
from scenes.language.prompts.phrasing.slots import SLOTS

CAR = (4.5, 1.8, 1.6)
PED = (0.6, 0.6, 1.7)
CYC = (1.8, 0.6, 1.7)


def make_actor(i, cls, x, y, yaw, v, size) -> Actor:
    """An actor standing on the ground (z = half its height)."""
    return Actor(i, cls, [x, y, size[2] / 2, *size, yaw], v)


def hand_world() -> list[Actor]:
    """3 cars, 2 pedestrians and 1 cyclist in view, plus 3 actors outside the annotated area.

    Hand-computed (depth = nearest-edge forward distance, v_r = ground radial velocity):
      0 Car   (20, 3.5)  yaw 0   v (10, 0)     depth 17.75  v_r +9.85  left   36 km/h
      1 Car   (30,-3.5)  yaw pi  v (-8, 0)     depth 27.75  v_r -7.95  right  28.8 km/h
      2 Car   (12,-5)    yaw 0   parked        depth  9.75             right
      3 Ped   (8, 2.5)   yaw -pi/2 v (0,-1.4)  depth  7.7   v_r -0.42  left   crossing
      4 Ped   (15, 0.5)  yaw 0   standing      depth 14.7              ahead
      5 Cyc   (25, 1.0)  yaw 0   v (5, 0)      depth 24.1   v_r +5.0   ahead  18 km/h
      6 Car   (60, 0)    moving away, beyond 50 m and the 5 m guard band
      7 Car   (-10, 0)   moving away, behind the ego vehicle
      8 Ped   (10, -12)  moving away, bearing -50 deg, outside the FoV and its guard band
    """
    return [
        make_actor(0, "Car", 20.0, 3.5, 0.0, (10.0, 0.0), CAR),
        make_actor(1, "Car", 30.0, -3.5, math.pi, (-8.0, 0.0), CAR),
        make_actor(2, "Car", 12.0, -5.0, 0.0, (0.0, 0.0), CAR),
        make_actor(3, "Pedestrian", 8.0, 2.5, -math.pi / 2, (0.0, -1.4), PED),
        make_actor(4, "Pedestrian", 15.0, 0.5, 0.0, (0.0, 0.0), PED),
        make_actor(5, "Cyclist", 25.0, 1.0, 0.0, (5.0, 0.0), CYC),
        make_actor(6, "Car", 60.0, 0.0, 0.0, (10.0, 0.0), CAR),
        make_actor(7, "Car", -10.0, 0.0, math.pi, (-10.0, 0.0), CAR),
        make_actor(8, "Pedestrian", 10.0, -12.0, -math.pi / 2, (0.0, -1.5), PED),
    ]


def random_world(rng: np.random.Generator, n: int) -> list[Actor]:
    """Actors on a few lanes and sidewalks, some parked, some outside the annotated area."""
    actors = []
    for i in range(n):
        cls = str(rng.choice(["Car", "Car", "Pedestrian", "Cyclist"]))
        size = {"Car": CAR, "Pedestrian": PED, "Cyclist": CYC}[cls]
        x = float(rng.uniform(-5.0, 62.0))
        if cls == "Pedestrian":
            y = float(rng.choice([-7.0, 7.0]) + rng.normal(0, 1.0))
        else:
            y = float(rng.choice([-5.25, -1.75, 1.75, 5.25]) + rng.normal(0, 0.3))
        if rng.random() < 0.1:
            y = float(rng.uniform(-25, 25))
        yaw = float(rng.choice([0.0, math.pi]) + rng.normal(0, 0.1))
        if cls == "Pedestrian" and rng.random() < 0.4:
            yaw = float(rng.choice([-math.pi / 2, math.pi / 2]))
        speed = {"Car": (2, 16), "Pedestrian": (0.8, 2.0), "Cyclist": (2.0, 7.0)}[cls]
        s = 0.0 if rng.random() < 0.35 else float(rng.uniform(*speed))
        actors.append(make_actor(i, cls, x, y, yaw, (s * math.cos(yaw), s * math.sin(yaw)), size))
    return actors


def random_road_user_world(rng: np.random.Generator, n: int) -> list[Actor]:
    """Actors of the ``nuscenes`` class set (every class about as often, its mean size; cones
    and barriers never move) on a few lanes and sidewalks, some parked."""
    actors = []
    for i in range(n):
        obj = NUSCENES.classes[int(rng.integers(len(NUSCENES)))]
        x = float(rng.uniform(-5.0, 62.0))
        y = float(rng.choice([-7.0, -5.25, -1.75, 1.75, 5.25, 7.0]) + rng.normal(0, 0.3))
        yaw = float(rng.choice([0.0, math.pi]) + rng.normal(0, 0.1))
        still = obj.name in ("TrafficCone", "Barrier") or rng.random() < 0.35
        s = 0.0 if still else float(rng.uniform(1.0, 12.0))
        v = (s * math.cos(yaw), s * math.sin(yaw))
        actors.append(make_actor(i, obj.name, x, y, yaw, v, obj.mean_size))
    return actors


def random_worlds(seed: int, count: int, classes: str = "vod") -> list[list[Actor]]:
    """``count`` random worlds of 2..15 actors (of the ``vod`` or the ``nuscenes`` class set)."""
    rng = np.random.default_rng(seed)
    draw = random_world if classes == "vod" else random_road_user_world
    return [draw(rng, int(rng.integers(2, 16))) for _ in range(count)]


def flip_world(actors: list[Actor]) -> list[Actor]:
    """The world mirrored y -> -y (velocities and yaws follow)."""
    out = []
    for a in actors:
        box = a.box.copy()
        box[1], box[6] = -box[1], -box[6]
        out.append(Actor(a.actor_id, a.cls, box, [a.velocity[0], -a.velocity[1]]))
    return out


# ---------------------------------------------------------------------------------------------
# Reading sentences
# ---------------------------------------------------------------------------------------------

NOUN_FORMS = [
    t.split("|") for k, s in SLOTS.items() if k.startswith("noun.") for t in s.core + s.more
]
PLURAL_NOUNS = {plural for _, plural in NOUN_FORMS}
SINGULAR_NOUNS = {singular for singular, _ in NOUN_FORMS}

_ONES = "zero one two three four five six seven eight nine ten eleven twelve thirteen fourteen"
_ONES += " fifteen sixteen seventeen eighteen nineteen"
_TENS = "twenty thirty forty fifty sixty seventy eighty ninety"
WORD_VALUES = {w: i for i, w in enumerate(_ONES.split())}
WORD_VALUES |= {w: 20 + 10 * i for i, w in enumerate(_TENS.split())}
_W = r"\b(?:" + "|".join(sorted(WORD_VALUES, key=len, reverse=True)) + r")\b"
NUMBER = rf"(?:\d+(?:\.\d+)?|\bhalf an?\b|{_W}(?:[- ]{_W})?(?: and a half| point {_W})?)"
_UNIT = (
    r"(?:m\b(?!/)|met(?:er|re)s? per second|meters?\b|metres?\b|km/h|kph\b|kmh\b"
    r"|kilomet(?:er|re)s? (?:per|an) hour|km per hour|m/s|mps\b)"
)
_QUANTITY = re.compile(rf"({NUMBER})\s*{_UNIT}", re.IGNORECASE)
_RANGE_LOW = re.compile(rf"({NUMBER}) (?:and|to) (?={NUMBER}\s*{_UNIT})", re.IGNORECASE)
_NUMBER = re.compile(NUMBER, re.IGNORECASE)


def has_phrase(text: str, phrase: str) -> bool:
    """``phrase`` occurs in ``text`` as whole words (case-insensitive)."""
    return re.search(rf"\b{re.escape(phrase)}\b", text.lower()) is not None


def is_plural(text: str) -> bool:
    """A plural noun of the generator's noun tables occurs in ``text``."""
    return any(has_phrase(text, w) for w in PLURAL_NOUNS)


def parse_number(words: str) -> float:
    """The value of a number in digits or words ("twenty-five", "two and a half", "half a")."""
    s = words.lower().strip()
    if re.fullmatch(r"\d+(?:\.\d+)?", s):
        return float(s)
    if re.fullmatch(r"half an?", s):
        return 0.5
    if s.endswith(" and a half"):
        return parse_number(s[: -len(" and a half")]) + 0.5
    if " point " in s:
        whole, tenth = s.split(" point ")
        return parse_number(whole) + WORD_VALUES[tenth] / 10
    return float(sum(WORD_VALUES[p] for p in re.split(r"[- ]", s)))


def read_numbers(text: str) -> tuple[list[float], list[float]]:
    """``(quantities, counts)`` in a sentence: numbers with a unit (or the low end of a range
    "between 10 and 15 m"), and the other numbers ("both" = 2)."""
    quantities = [parse_number(m.group(1)) for m in _RANGE_LOW.finditer(text)]
    rest = _RANGE_LOW.sub(" ", text)
    quantities += [parse_number(m.group(1)) for m in _QUANTITY.finditer(rest)]
    rest = _QUANTITY.sub(" ", rest)
    counts = [parse_number(m.group(0)) for m in _NUMBER.finditer(rest)]
    counts += [2.0] * len(re.findall(r"\bboth\b", rest, re.IGNORECASE))
    return quantities, counts
