"""Talk2Radar-style referring prompts whose referents are known exactly.

A prompt is generated from a :class:`Predicate`, a small conjunction over the actors of a frame:

* an optional class (``Car``, ``Pedestrian``, ``Cyclist``; ``None`` = any class, "objects"),
* at most one atom per family: position (:class:`OnSide`), motion state (:class:`MotionState`),
  heading (:class:`HeadingIs`), speed (:class:`SpeedAbout`, :class:`SpeedAbove`,
  :class:`SpeedBelow`) and depth (:class:`DepthAbout`, :class:`DepthBetween`, :class:`DepthWithin`,
  :class:`DepthBeyond`),
* an optional superlative (:class:`Extreme`: nearest, farthest, leftmost, rightmost, fastest) that
  picks one actor among those matching the rest.

:func:`resolve` evaluates the predicate over *all* referable actors, so "the cars moving away from
us" refers to every such car. The sentence is rendered afterwards from the predicate and the size of
the resolved set (singular / plural, stated counts), so a stated count always equals the number of
referents. Count is therefore not a filter: it is said from the resolved set.

Semantics (all in the LiDAR frame, x forward, y left; velocities are ground velocities, ego motion
removed, see :mod:`scenes.actors`):

* **Depth** is the forward distance of the box's nearest point, ``min x`` over its four BEV corners
  (the TPCNet paper's argument: a prompt's distance refers to the object's edge nearest the ego
  vehicle, the anchor of C3D-RECHead). "about D m" = depth in ``[D - 2.5, D + 2.5]``; "between A
  and B m" = ``[A, B]``; "within D m" = ``<= D``; "further than D m" = ``> D``.
* **Position** uses the box centre: left = ``y > 1.5`` m, right = ``y < -1.5`` m (outside a 3 m
  wide ego corridor); "directly ahead" = ``|y| <= 1.5`` m *and* bearing ``|atan2(y, x)| <= 15``
  degrees (a pedestrian beside the bumper is neither ahead nor on a side).
* **Motion state**: moving = ground speed ``> 0.5`` m/s (:data:`scenes.actors.MOVING_SPEED`),
  stationary otherwise; "parked" is the car phrasing of stationary (a stopped car cannot be told
  from a parked one).
* **Heading** relative to the ego vehicle, from the ground radial velocity ``v_r`` (the velocity
  projected on the line of sight to the box centre, :attr:`Actor.radial_velocity`): approaching =
  ``v_r < -0.5`` m/s (the distance shrinks), moving away = ``v_r > 0.5`` m/s, crossing = moving and
  the velocity within 30 degrees of the lateral (y) axis. Crossing may overlap approaching or
  moving away; every statement is literally true of each referent and false of each non-referent.
* **Speed**: "about V" = ``|speed - V| <= max(0.75 m/s, 0.15 V)``; "faster than V" = ``speed > V``;
  "slower than V" = moving and ``speed < V`` (a parked car is not "going slower than 10 km/h").
  Values are said in km/h (multiples of 5) or m/s.
* **Superlatives** rank the actors that match the rest of the predicate: nearest / farthest by
  depth, leftmost / rightmost by centre ``y``, fastest by speed (only if that actor moves).

Referable region and ambiguity. Only actors inside :class:`ReferableRegion` (default: centre
``x`` in ``[0, 50]`` m and ``|bearing| <= 32`` degrees, the View-of-Delft annotated area and camera
field of view) can be referents. An actor outside it but close to it (within ``guard_m`` metres in x
or ``guard_deg`` degrees in bearing) is still visible in the sensors, so a sentence that would also
describe it is ambiguous: :func:`analyse` lists such actors as ``conflicts`` and the generator and
:func:`describe` never emit a predicate with conflicts. Actors far outside (behind the ego vehicle,
well beyond 50 m) are out of the scene the prompt speaks about and are ignored.

Crispness. Besides being exact, generated predicates are *crisp*: the resolved set does not change
when every threshold is moved by a small slack (0.5 m in depth, 0.25 m in y, 1 degree in bearing,
0.2 m/s on the motion thresholds, 0.25 m/s on stated speeds, 5 degrees on the crossing angle), and a
superlative's winner beats the runner-up by a clear margin. This keeps borderline actors (a car
17.4 m away for "about 20 m") from making a true sentence look wrong to a person or a model.

Type tags (``class``, ``depth``, ``velocity``, ``motion``, ``position``, the TPCNet paper's table
III types) follow the predicate, and every phrase is written so that the keyword rules of
:func:`infer_tags` (which also serve real Talk2Radar prompts) give the same tags from the text.
"""

from __future__ import annotations

import enum
import itertools
import math
import re
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from scenes.actors import CLASSES, MOVING_SPEED, Actor

TAGS: tuple[str, ...] = ("class", "depth", "velocity", "motion", "position")
"""Prompt type tags (the TPCNet paper's table III prompt types plus ``class``)."""

LANE_HALF_WIDTH = 1.5
"""Half width (m) of the ego corridor: left / right beyond it, "directly ahead" within it."""

AHEAD_MAX_BEARING_DEG = 15.0
"""Largest bearing (degrees) of an actor that is "directly ahead"."""

HEADING_RADIAL_SPEED = 0.5
"""Ground radial speed (m/s) beyond which an actor is approaching / moving away."""

CROSSING_MAX_ANGLE_DEG = 30.0
"""Largest angle (degrees) between a crossing actor's velocity and the lateral (y) axis."""

ABOUT_DEPTH_TOL = 2.5
"""Half width (m) of the "about D metres" window."""

SPEED_ABOUT_MIN_TOL = 0.75
SPEED_ABOUT_REL_TOL = 0.15
""""About V" speed window: ``max(SPEED_ABOUT_MIN_TOL, SPEED_ABOUT_REL_TOL * V)`` m/s."""

# Threshold shifts per unit of slack (see "Crispness" in the module docstring).
_SLACK_DEPTH = 0.5
_SLACK_Y = 0.25
_SLACK_BEARING = 1.0
_SLACK_MOTION = 0.2
_SLACK_SPEED = 0.25
_SLACK_ANGLE = 5.0
# Smallest winner / runner-up gap of a crisp superlative.
_GAP_DEPTH = 1.0
_GAP_Y = 0.5
_GAP_SPEED = 0.5

_NUMBER_WORDS = (
    "zero",
    "one",
    "two",
    "three",
    "four",
    "five",
    "six",
    "seven",
    "eight",
    "nine",
    "ten",
)


# --------------------------------------------------------------------------------------------
# Left / right flip and keyword type tags
# --------------------------------------------------------------------------------------------

_LR_WORD = re.compile(r"\b(left|right)(most|wards?)?\b", re.IGNORECASE)
_ADVERBIAL_AFTER = re.compile(
    r"\s+(?:in front|ahead|behind|next to|beside|now|away|here|there)\b", re.IGNORECASE
)
_DIRECTION_BEFORE = re.compile(
    r"\b(?:the|our|your|their|his|her|its|my|to|far|and|or|from)\s+$", re.IGNORECASE
)


def _match_case(template: str, word: str) -> str:
    if len(template) > 1 and template.isupper():
        return word.upper()
    if template[:1].isupper():
        return word[:1].upper() + word[1:]
    return word


def flip_left_right(text: str) -> str:
    """Swap the words "left" and "right" in a sentence (for the y -> -y flip augmentation).

    Case is kept ("Left" -> "Right", "LEFT" -> "RIGHT"); whole words only, with the suffixes
    "most" and "ward(s)" ("leftmost" -> "rightmost"); hyphenated forms follow ("left-hand" ->
    "right-hand"). The adverb "right" ("right in front of us", "right ahead", "right behind",
    "right next to") is kept unless a determiner or preposition before it makes it a direction
    ("on the right in front of the bus" flips). The verb "left" ("the car that left") is not
    recognised and would be flipped; no generated prompt uses it.
    """

    def repl(m: re.Match[str]) -> str:
        word, suffix = m.group(1), m.group(2) or ""
        if word.lower() == "right" and not suffix:
            after = text[m.end() :]
            before = text[: m.start()]
            if _ADVERBIAL_AFTER.match(after) and not _DIRECTION_BEFORE.search(before):
                return m.group(0)
        new = "right" if word.lower() == "left" else "left"
        return _match_case(word, new) + suffix

    return _LR_WORD.sub(repl, text)


_EGO_PHRASE = re.compile(r"\bego[- ]?(?:car|vehicle)s?\b|\bour (?:car|vehicle)\b")
_DEPTH_PHRASE = re.compile(
    r"\d+(?:\.\d+)?\s*(?:m|meters?|metres?)\b(?!/)(?:\s+(?:ahead|away))?"
    r"|\d+(?:\.\d+)?\s+(?:ahead|away)\b"
    r"|\bfar away\b"
)
_DEPTH_WORDS = re.compile(
    r"\b(?:meters?|metres?|distance|distant|nearest|closest|farthest|furthest|depth)\b"
)
_VELOCITY_WORDS = re.compile(
    r"km/h|m/s|\bkmh\b|\bkph\b|\bmph\b|\bspeeds?\b|\bvelocit\w*|\bfast\w*|\bslow\w*|\bquick\w*"
    r"|\bper (?:hour|second)\b"
)
_MOTION_WORDS = re.compile(
    r"\bmov(?:e|es|ing)\b|\bstationary\b|\bparked\b|\bparking\b|\bstopped\b|\bstatic\b"
    r"|\bstanding still\b|\bmotion\w*|\bapproach\w*|\btowards?\b|\baway\b|\bcross(?:es|ing)?\b"
    r"|\boncoming\b|\breced\w*|\bleaving\b"
)
_POSITION_WORDS = re.compile(
    r"\bleft\w*|\bright(?:most|wards?)?\b|\bfront\b|\bbehind\b|\bbeside\b|\bnext to\b"
    r"|\bahead\b|\blanes?\b|\bside\b|\bopposite\b"
)
_CLASS_WORDS = re.compile(
    r"\b(?:cars?|vehicles?|trucks?|vans?|bus(?:es)?|pedestrians?|persons?|people|man|men|woman"
    r"|women|child(?:ren)?|kids?|walkers?|cyclists?|bicyclists?|bicycles?|bikes?|riders?"
    r"|motorcyclists?|motorbikes?|scooters?)\b"
)


def infer_tags(text: str) -> frozenset[str]:
    """Prompt type tags from keywords; works on generated and real Talk2Radar prompts.

    Rules, applied to the lower-cased text after "ego car" / "ego vehicle" is removed:

    * depth: a number with a metre unit ("20 m", "15 meters", "10 metres away"), a number followed
      by "ahead"/"away", "far away", or the words metres/distance/nearest/closest/farthest. These
      depth phrases are removed before the rules below, so "20 m away" is not motion and "20 m
      ahead" is not position.
    * velocity: km/h, m/s, kph, mph, speed, velocity, fast*, slow*, quick*, per hour / second.
    * motion: moving, stationary, parked, stopped, static, standing still, motion, approach*,
      towards, away, crossing, oncoming, receding, leaving.
    * position: left*, right, front, behind, beside, next to, ahead (not after a distance), lane,
      side, opposite.
    * class: car, vehicle, truck, van, bus, pedestrian, person, people, cyclist, bicycle, bike,
      rider, ... (the ego vehicle excluded).
    """
    s = _EGO_PHRASE.sub(" ego ", text.lower())
    tags: set[str] = set()
    if _DEPTH_PHRASE.search(s):
        tags.add("depth")
        s = _DEPTH_PHRASE.sub(" ", s)
    if _DEPTH_WORDS.search(s):
        tags.add("depth")
    if _VELOCITY_WORDS.search(s):
        tags.add("velocity")
    if _MOTION_WORDS.search(s):
        tags.add("motion")
    if _POSITION_WORDS.search(s):
        tags.add("position")
    if _CLASS_WORDS.search(s):
        tags.add("class")
    return frozenset(tags)


# --------------------------------------------------------------------------------------------
# Actor features and the referable region
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ActorFeatures:
    """The quantities prompts talk about, for one actor (LiDAR frame, ground velocity).

    Attributes:
        actor_id: The actor's id.
        cls: Its class.
        x, y: Box centre (m).
        depth: Forward distance of the box's nearest point, ``min x`` of its BEV corners (m).
        bearing_deg: ``atan2(y, x)`` of the centre, degrees (positive = left).
        speed: Ground speed (m/s).
        radial_velocity: Ground velocity along the line of sight to the centre (m/s, + = away).
        crossing_angle_deg: Angle between the velocity and the y axis, in ``[0, 90]`` degrees
            (0 = purely lateral; 90 for a stationary actor).
    """

    actor_id: int
    cls: str
    x: float
    y: float
    depth: float
    bearing_deg: float
    speed: float
    radial_velocity: float
    crossing_angle_deg: float

    @staticmethod
    def of(actor: Actor) -> ActorFeatures:
        """The features of an :class:`~scenes.actors.Actor`."""
        x, y, _, length, width, _, yaw = (float(v) for v in actor.box)
        half_extent_x = abs(0.5 * length * math.cos(yaw)) + abs(0.5 * width * math.sin(yaw))
        vx, vy = (float(v) for v in actor.velocity)
        speed = math.hypot(vx, vy)
        angle = math.degrees(math.atan2(abs(vx), abs(vy))) if speed > 1e-9 else 90.0
        return ActorFeatures(
            actor_id=int(actor.actor_id),
            cls=actor.cls,
            x=x,
            y=y,
            depth=x - half_extent_x,
            bearing_deg=math.degrees(math.atan2(y, x)),
            speed=speed,
            radial_velocity=actor.radial_velocity,
            crossing_angle_deg=angle,
        )


@dataclass(frozen=True)
class ReferableRegion:
    """Where actors can be referents, and the visible band around it that makes prompts ambiguous.

    Attributes:
        x_min, x_max: Range of the box centre's forward coordinate (m), VoD's annotated 0..50 m.
        half_fov_deg: Largest ``|bearing|`` of the centre (degrees), VoD's camera half FoV.
        guard_m: Depth band beyond ``[x_min, x_max]`` whose actors are visible but not annotated.
        guard_deg: Bearing band beyond ``half_fov_deg`` likewise.
    """

    x_min: float = 0.0
    x_max: float = 50.0
    half_fov_deg: float = 32.0
    guard_m: float = 5.0
    guard_deg: float = 5.0

    def __post_init__(self) -> None:
        if not self.x_min < self.x_max:
            raise ValueError(f"ReferableRegion: x_min {self.x_min} must be < x_max {self.x_max}")
        if not 0.0 < self.half_fov_deg <= 180.0:
            raise ValueError(f"ReferableRegion: half_fov_deg {self.half_fov_deg} not in (0, 180]")
        if self.guard_m < 0 or self.guard_deg < 0:
            raise ValueError("ReferableRegion: guard_m and guard_deg must be >= 0")

    def contains(self, actor: Actor | ActorFeatures) -> bool:
        """True when the actor can be a referent."""
        f = actor if isinstance(actor, ActorFeatures) else ActorFeatures.of(actor)
        return self.x_min <= f.x <= self.x_max and abs(f.bearing_deg) <= self.half_fov_deg

    def in_guard(self, actor: Actor | ActorFeatures) -> bool:
        """True when the actor is outside the region but visible close to it (see module doc)."""
        f = actor if isinstance(actor, ActorFeatures) else ActorFeatures.of(actor)
        if self.contains(f):
            return False
        in_x = self.x_min - self.guard_m <= f.x <= self.x_max + self.guard_m
        return in_x and abs(f.bearing_deg) <= self.half_fov_deg + self.guard_deg


DEFAULT_REGION = ReferableRegion()


# --------------------------------------------------------------------------------------------
# Rendering context and phrase tables
# --------------------------------------------------------------------------------------------

_NOUNS: dict[str | None, tuple[tuple[str, str], ...]] = {
    "Car": (("car", "cars"), ("car", "cars"), ("vehicle", "vehicles")),
    "Pedestrian": (
        ("pedestrian", "pedestrians"),
        ("pedestrian", "pedestrians"),
        ("person", "people"),
    ),
    "Cyclist": (("cyclist", "cyclists"), ("cyclist", "cyclists"), ("bike rider", "bike riders")),
    None: (("object", "objects"), ("road user", "road users"), ("target", "targets")),
}
_VERBS: dict[str | None, str] = {
    "Car": "driving",
    "Pedestrian": "walking",
    "Cyclist": "riding",
    None: "travelling",
}
_DEPTH_UNITS = ("m", "meters", "metres")


@dataclass(frozen=True)
class _Ctx:
    cls: str | None
    plural: bool
    unit: str

    @property
    def be(self) -> str:
        return "are" if self.plural else "is"

    @property
    def verb(self) -> str:
        return _VERBS[self.cls]


def _num(value: float) -> str:
    """A number as people write it: ``20``, ``2.5``."""
    r = round(float(value), 1)
    return str(int(r)) if r == int(r) else f"{r:g}"


# --------------------------------------------------------------------------------------------
# Atoms
# --------------------------------------------------------------------------------------------


class Atom(ABC):
    """One attribute test of a predicate; concrete atoms are frozen dataclasses.

    ``holds(f, slack)``: the test on an actor's features; ``slack`` > 0 loosens and < 0 tightens
    every threshold by ``slack`` units (see the module docstring), 0 is the exact meaning.
    """

    family: ClassVar[str]
    tag: ClassVar[str]

    @abstractmethod
    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        """Whether the attribute is true of the actor."""

    def flipped(self) -> Atom:
        """The atom after the world's y -> -y flip (only position atoms change)."""
        return self

    @abstractmethod
    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        """Post-noun phrasings (all containing this atom's tag keywords and no others)."""

    def adjectives(self, ctx: _Ctx) -> tuple[str, ...]:
        """Pre-noun phrasings, possibly none."""
        return ()


class Side(enum.Enum):
    """Lateral position classes (see the module docstring)."""

    LEFT = "left"
    RIGHT = "right"
    AHEAD = "ahead"


_LEFT_PHRASES = (
    "on the left",
    "on our left",
    "on the left side",
    "to the left",
    "on the left-hand side",
    "to the left of the ego vehicle",
    "on the left side of the road",
)
_SIDE_PHRASES: dict[Side, tuple[str, ...]] = {
    Side.LEFT: _LEFT_PHRASES,
    Side.RIGHT: tuple(flip_left_right(p) for p in _LEFT_PHRASES),
    Side.AHEAD: (
        "directly ahead",
        "straight ahead",
        "in front of us",
        "directly in front of the ego car",
        "in our lane",
        "in front of the ego vehicle",
    ),
}


@dataclass(frozen=True)
class OnSide(Atom):
    """Left / right of the ego corridor, or directly ahead in it."""

    side: Side
    family: ClassVar[str] = "position"
    tag: ClassVar[str] = "position"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        lane = LANE_HALF_WIDTH - _SLACK_Y * slack
        if self.side is Side.LEFT:
            return f.y > lane
        if self.side is Side.RIGHT:
            return f.y < -lane
        lane = LANE_HALF_WIDTH + _SLACK_Y * slack
        bearing = AHEAD_MAX_BEARING_DEG + _SLACK_BEARING * slack
        return abs(f.y) <= lane and abs(f.bearing_deg) <= bearing

    def flipped(self) -> OnSide:
        swap = {Side.LEFT: Side.RIGHT, Side.RIGHT: Side.LEFT, Side.AHEAD: Side.AHEAD}
        return OnSide(swap[self.side])

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        return _SIDE_PHRASES[self.side]


@dataclass(frozen=True)
class MotionState(Atom):
    """Moving (ground speed above :data:`~scenes.actors.MOVING_SPEED`) or stationary."""

    moving: bool
    family: ClassVar[str] = "motion"
    tag: ClassVar[str] = "motion"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        if self.moving:
            return f.speed > MOVING_SPEED - _SLACK_MOTION * slack
        return f.speed <= MOVING_SPEED + _SLACK_MOTION * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        if self.moving:
            return ("moving", f"that {ctx.be} moving", "in motion")
        extra = {
            "Car": ("parked", f"that {ctx.be} parked", "parked by the road"),
            "Pedestrian": ("standing still", f"that {ctx.be} standing still"),
            "Cyclist": ("stopped", "standing still"),
            None: (),
        }[ctx.cls]
        return ("stationary", f"that {ctx.be} stationary", "not moving", *extra)

    def adjectives(self, ctx: _Ctx) -> tuple[str, ...]:
        if self.moving:
            return ("moving",)
        extra = {"Car": ("parked", "parked"), "Cyclist": ("stopped",)}.get(ctx.cls or "", ())
        return ("stationary", "static", *extra)


class Heading(enum.Enum):
    """Motion relative to the ego vehicle (see the module docstring)."""

    APPROACHING = "approaching"
    AWAY = "away"
    CROSSING = "crossing"


@dataclass(frozen=True)
class HeadingIs(Atom):
    """Approaching, moving away from, or crossing in front of the ego vehicle."""

    heading: Heading
    family: ClassVar[str] = "heading"
    tag: ClassVar[str] = "motion"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        if self.heading is Heading.APPROACHING:
            return f.radial_velocity < -(HEADING_RADIAL_SPEED - _SLACK_MOTION * slack)
        if self.heading is Heading.AWAY:
            return f.radial_velocity > HEADING_RADIAL_SPEED - _SLACK_MOTION * slack
        return (
            f.speed > MOVING_SPEED - _SLACK_MOTION * slack
            and f.crossing_angle_deg <= CROSSING_MAX_ANGLE_DEG + _SLACK_ANGLE * slack
        )

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        if self.heading is Heading.APPROACHING:
            return (
                "approaching us",
                "approaching the ego vehicle",
                f"{ctx.verb} towards us",
                f"{ctx.verb} towards the ego car",
                "heading towards the ego vehicle",
                "moving toward us",
                "coming towards us",
                f"that {ctx.be} approaching",
            )
        if self.heading is Heading.AWAY:
            return (
                "moving away from us",
                f"{ctx.verb} away from the ego vehicle",
                "heading away from us",
                "moving away from the ego car",
                f"that {ctx.be} moving away",
                f"{ctx.verb} away",
            )
        return (
            "crossing the road",
            "crossing our path",
            f"that {ctx.be} crossing the road",
            "crossing the street",
        )

    def adjectives(self, ctx: _Ctx) -> tuple[str, ...]:
        if self.heading is Heading.APPROACHING:
            return ("approaching", "oncoming") if ctx.cls == "Car" else ("approaching",)
        if self.heading is Heading.CROSSING:
            return ("crossing",)
        return ()


class SpeedUnit(enum.Enum):
    """The unit a speed is said in."""

    KMH = "km/h"
    MPS = "m/s"

    @property
    def to_mps(self) -> float:
        """Factor from this unit to m/s."""
        return 1.0 / 3.6 if self is SpeedUnit.KMH else 1.0


@dataclass(frozen=True)
class SpeedAbout(Atom):
    """Ground speed about ``value`` (in ``unit``)."""

    value: float
    unit: SpeedUnit
    family: ClassVar[str] = "speed"
    tag: ClassVar[str] = "velocity"

    @property
    def tol_mps(self) -> float:
        """Half width of the window (m/s)."""
        return max(SPEED_ABOUT_MIN_TOL, SPEED_ABOUT_REL_TOL * self.value * self.unit.to_mps)

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        v = self.value * self.unit.to_mps
        return abs(f.speed - v) <= self.tol_mps + _SLACK_SPEED * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        v, u = _num(self.value), self.unit.value
        return (
            f"at about {v} {u}",
            f"travelling at roughly {v} {u}",
            f"at a speed of about {v} {u}",
            f"{ctx.verb} at around {v} {u}",
            f"going about {v} {u}",
        )


@dataclass(frozen=True)
class SpeedAbove(Atom):
    """Ground speed above ``value`` (in ``unit``)."""

    value: float
    unit: SpeedUnit
    family: ClassVar[str] = "speed"
    tag: ClassVar[str] = "velocity"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.speed > self.value * self.unit.to_mps - _SLACK_SPEED * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        v, u = _num(self.value), self.unit.value
        return (
            f"faster than {v} {u}",
            f"at more than {v} {u}",
            f"{ctx.verb} faster than {v} {u}",
            f"at a speed above {v} {u}",
            f"going over {v} {u}",
        )


@dataclass(frozen=True)
class SpeedBelow(Atom):
    """Moving, with a ground speed below ``value`` (in ``unit``)."""

    value: float
    unit: SpeedUnit
    family: ClassVar[str] = "speed"
    tag: ClassVar[str] = "velocity"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        moving = f.speed > MOVING_SPEED - _SLACK_MOTION * slack
        return moving and f.speed < self.value * self.unit.to_mps + _SLACK_SPEED * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        v, u = _num(self.value), self.unit.value
        return (
            f"slower than {v} {u}",
            f"at less than {v} {u}",
            f"{ctx.verb} slower than {v} {u}",
            f"at a speed below {v} {u}",
            f"going under {v} {u}",
        )


@dataclass(frozen=True)
class DepthAbout(Atom):
    """Nearest-edge forward distance within ``metres +- tol``."""

    metres: float
    tol: float = ABOUT_DEPTH_TOL
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return abs(f.depth - self.metres) <= self.tol + _SLACK_DEPTH * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        d, u = _num(self.metres), ctx.unit
        return (
            f"about {d} {u} ahead",
            f"roughly {d} {u} ahead",
            f"around {d} {u} away",
            f"approximately {d} {u} from us",
            f"at a distance of about {d} {u}",
            f"about {d} {u} away from the ego vehicle",
        )


@dataclass(frozen=True)
class DepthBetween(Atom):
    """Nearest-edge forward distance in ``[lo, hi]``."""

    lo: float
    hi: float
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def __post_init__(self) -> None:
        if not self.lo < self.hi:
            raise ValueError(f"DepthBetween: lo {self.lo} must be < hi {self.hi}")

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        s = _SLACK_DEPTH * slack
        return self.lo - s <= f.depth <= self.hi + s

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        lo, hi, u = _num(self.lo), _num(self.hi), ctx.unit
        return (
            f"between {lo} and {hi} {u} ahead",
            f"{lo} to {hi} {u} ahead",
            f"between {lo} and {hi} {u} away",
            f"at a distance of {lo} to {hi} {u}",
        )


@dataclass(frozen=True)
class DepthWithin(Atom):
    """Nearest-edge forward distance at most ``metres``."""

    metres: float
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.depth <= self.metres + _SLACK_DEPTH * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        d, u = _num(self.metres), ctx.unit
        return (
            f"within {d} {u}",
            f"less than {d} {u} ahead",
            f"closer than {d} {u}",
            f"within {d} {u} of us",
            f"no more than {d} {u} away",
        )


@dataclass(frozen=True)
class DepthBeyond(Atom):
    """Nearest-edge forward distance greater than ``metres``."""

    metres: float
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.depth > self.metres - _SLACK_DEPTH * slack

    def phrases(self, ctx: _Ctx) -> tuple[str, ...]:
        d, u = _num(self.metres), ctx.unit
        return (
            f"further than {d} {u}",
            f"more than {d} {u} ahead",
            f"beyond {d} {u}",
            f"farther than {d} {u} away",
        )


class Extreme(enum.Enum):
    """Superlatives: pick the one actor that ranks first among the predicate's matches."""

    NEAREST = "nearest"
    FARTHEST = "farthest"
    LEFTMOST = "leftmost"
    RIGHTMOST = "rightmost"
    FASTEST = "fastest"

    @property
    def tag(self) -> str:
        """The prompt type tag of this superlative."""
        if self in (Extreme.NEAREST, Extreme.FARTHEST):
            return "depth"
        if self is Extreme.FASTEST:
            return "velocity"
        return "position"

    def key(self, f: ActorFeatures) -> float:
        """Ranking score, larger wins."""
        return {
            Extreme.NEAREST: -f.depth,
            Extreme.FARTHEST: f.depth,
            Extreme.LEFTMOST: f.y,
            Extreme.RIGHTMOST: -f.y,
            Extreme.FASTEST: f.speed,
        }[self]

    @property
    def gap(self) -> float:
        """Smallest winner / runner-up score gap of a crisp superlative."""
        if self in (Extreme.NEAREST, Extreme.FARTHEST):
            return _GAP_DEPTH
        return _GAP_SPEED if self is Extreme.FASTEST else _GAP_Y

    def flipped(self) -> Extreme:
        """The superlative after the y -> -y flip."""
        swap = {Extreme.LEFTMOST: Extreme.RIGHTMOST, Extreme.RIGHTMOST: Extreme.LEFTMOST}
        return swap.get(self, self)

    @property
    def adjectives(self) -> tuple[str, ...]:
        """Pre-noun phrasings."""
        return {
            Extreme.NEAREST: ("nearest", "closest"),
            Extreme.FARTHEST: ("farthest", "furthest"),
            Extreme.LEFTMOST: ("leftmost",),
            Extreme.RIGHTMOST: ("rightmost",),
            Extreme.FASTEST: ("fastest",),
        }[self]


_FAMILY_ORDER = ("position", "motion", "heading", "speed", "depth")


# --------------------------------------------------------------------------------------------
# Predicates and resolution
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Predicate:
    """A conjunction: optional class, at most one atom per family, optional superlative.

    Atoms are stored in a canonical order, so equal predicates compare and hash equal.
    """

    cls: str | None = None
    atoms: tuple[Atom, ...] = ()
    extreme: Extreme | None = None

    def __post_init__(self) -> None:
        if self.cls is not None and self.cls not in CLASSES:
            raise ValueError(f"Predicate: class {self.cls!r} is not one of {CLASSES}")
        atoms = tuple(self.atoms)
        for a in atoms:
            if not isinstance(a, Atom):
                raise ValueError(f"Predicate: {a!r} is not an Atom")
        families = [a.family for a in atoms]
        if len(set(families)) != len(families):
            raise ValueError(f"Predicate: at most one atom per family, got {families}")
        atoms = tuple(sorted(atoms, key=lambda a: _FAMILY_ORDER.index(a.family)))
        object.__setattr__(self, "atoms", atoms)

    @property
    def tags(self) -> frozenset[str]:
        """The prompt type tags of any sentence rendered from this predicate."""
        tags = {a.tag for a in self.atoms}
        if self.cls is not None:
            tags.add("class")
        if self.extreme is not None:
            tags.add(self.extreme.tag)
        return frozenset(tags)

    def flipped(self) -> Predicate:
        """The predicate that says the same of the world flipped y -> -y (left <-> right)."""
        extreme = self.extreme.flipped() if self.extreme is not None else None
        return Predicate(self.cls, tuple(a.flipped() for a in self.atoms), extreme)

    def matches(self, actor: Actor | ActorFeatures, slack: float = 0.0) -> bool:
        """Class and atoms (not the superlative) hold for the actor."""
        f = actor if isinstance(actor, ActorFeatures) else ActorFeatures.of(actor)
        if self.cls is not None and f.cls != self.cls:
            return False
        return all(a.holds(f, slack) for a in self.atoms)


@dataclass(frozen=True)
class Resolution:
    """What a predicate refers to in a scene.

    Attributes:
        ids: Referent actor ids (referable actors satisfying it), ascending.
        conflicts: Ids of visible but non-referable actors (the region's guard band) it also
            describes; a non-empty tuple makes the sentence ambiguous.
        crisp: The referents do not change under small threshold slack (module docstring).
    """

    ids: tuple[int, ...]
    conflicts: tuple[int, ...]
    crisp: bool

    @property
    def usable(self) -> bool:
        """Refers to something, unambiguously."""
        return bool(self.ids) and not self.conflicts


def _features(actors: Sequence[Actor]) -> list[ActorFeatures]:
    feats = [ActorFeatures.of(a) for a in actors]
    seen: set[int] = set()
    for f in feats:
        if f.actor_id in seen:
            raise ValueError(f"actors: duplicate actor_id {f.actor_id}")
        seen.add(f.actor_id)
    return feats


def _select(pred: Predicate, inside: Sequence[ActorFeatures], slack: float) -> tuple[int, ...]:
    cands = [f for f in inside if pred.matches(f, slack)]
    if pred.extreme is None:
        return tuple(sorted(f.actor_id for f in cands))
    if not cands:
        return ()
    best = max(cands, key=lambda f: (pred.extreme.key(f), -f.actor_id))
    if pred.extreme is Extreme.FASTEST and best.speed <= MOVING_SPEED:
        return ()
    return (best.actor_id,)


def _analyse(
    pred: Predicate, feats: Sequence[ActorFeatures], region: ReferableRegion
) -> Resolution:
    inside = [f for f in feats if region.contains(f)]
    ids = _select(pred, inside, 0.0)
    crisp = _select(pred, inside, -1.0) == ids == _select(pred, inside, 1.0)
    if crisp and pred.extreme is not None:
        scores = sorted((pred.extreme.key(f) for f in inside if pred.matches(f)), reverse=True)
        crisp = len(scores) < 2 or scores[0] - scores[1] >= pred.extreme.gap
        if pred.extreme is Extreme.FASTEST and scores:
            crisp = crisp and scores[0] > MOVING_SPEED + _SLACK_MOTION
    conflicts = tuple(
        sorted(f.actor_id for f in feats if region.in_guard(f) and pred.matches(f, 1.0))
    )
    return Resolution(ids=ids, conflicts=conflicts, crisp=crisp)


def analyse(
    predicate: Predicate, actors: Sequence[Actor], region: ReferableRegion = DEFAULT_REGION
) -> Resolution:
    """Referents, ambiguity conflicts and crispness of a predicate over a scene's actors."""
    return _analyse(predicate, _features(actors), region)


def resolve(
    predicate: Predicate, actors: Sequence[Actor], region: ReferableRegion = DEFAULT_REGION
) -> tuple[int, ...]:
    """Ids (ascending) of the referable actors the predicate refers to, evaluated over all actors."""
    return analyse(predicate, actors, region).ids


# --------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Prompt:
    """A referring sentence with its referents.

    Attributes:
        text: The sentence.
        referent_ids: Ids of the actors it refers to, ascending (empty for real prompts whose
            actors are unknown).
        tags: Type tags, a subset of :data:`TAGS`.
        predicate: The predicate it was rendered from (None for real / typed prompts).
    """

    text: str
    referent_ids: tuple[int, ...]
    tags: frozenset[str]
    predicate: Predicate | None = field(default=None, repr=False)

    @staticmethod
    def from_text(text: str, referent_ids: Sequence[int] = ()) -> Prompt:
        """A prompt from free text (real Talk2Radar, typed), tags from :func:`infer_tags`."""
        return Prompt(text, tuple(sorted(int(i) for i in referent_ids)), infer_tags(text))

    def flipped(self) -> Prompt:
        """The prompt for the world flipped y -> -y: left/right swapped in text and predicate."""
        pred = self.predicate.flipped() if self.predicate is not None else None
        return Prompt(flip_left_right(self.text), self.referent_ids, self.tags, pred)


def _pick(rng: np.random.Generator, options: Sequence[str]) -> str:
    return options[int(rng.integers(len(options)))]


def _repeats(text: str) -> bool:
    words = re.findall(r"[a-z]+", text.lower())
    return words.count("away") > 1 or words.count("ahead") + words.count("front") > 1


def render(
    predicate: Predicate,
    n_referents: int,
    rng: np.random.Generator,
    *,
    p_count_word: float = 0.4,
    p_adjective: float = 0.35,
    max_words: int = 22,
) -> str:
    """A Talk2Radar-style sentence for a predicate that resolves to ``n_referents`` actors.

    Singular / plural agree with ``n_referents``; a stated count ("two pedestrians", "both",
    "the three cars") equals it. Phrasings are drawn with ``rng``; a draw that repeats "away", says
    "ahead" / "in front" twice or runs past ``max_words`` words is redrawn (up to 8 times).

    Raises:
        ValueError: ``n_referents < 1``, or a superlative predicate with ``n_referents != 1``.
    """
    if n_referents < 1:
        raise ValueError(f"render: a prompt must refer to something, got n_referents={n_referents}")
    if predicate.extreme is not None and n_referents != 1:
        raise ValueError("render: a superlative refers to exactly one actor")
    plural = n_referents > 1
    singular_noun, plural_noun = _NOUNS[predicate.cls][int(rng.integers(3))]
    noun = plural_noun if plural else singular_noun
    ctx = _Ctx(cls=predicate.cls, plural=plural, unit=_pick(rng, _DEPTH_UNITS))
    text = ""
    for _ in range(8):
        atoms = list(predicate.atoms)
        adjective = None
        if predicate.extreme is not None:
            adjective = _pick(rng, predicate.extreme.adjectives)
        elif rng.random() < p_adjective:
            with_adj = [a for a in atoms if a.adjectives(ctx)]
            if with_adj:
                chosen = with_adj[int(rng.integers(len(with_adj)))]
                adjective = _pick(rng, chosen.adjectives(ctx))
                atoms.remove(chosen)
        # Motion words right after the noun ("the cyclist stopped between 40 and 45 m ahead"),
        # the other phrases after them in random order.
        first = [a for a in atoms if a.family in ("motion", "heading")]
        rest = [a for a in atoms if a.family not in ("motion", "heading")]
        ordered = first + [rest[int(i)] for i in rng.permutation(len(rest))]
        post = [_pick(rng, a.phrases(ctx)) for a in ordered]
        if not plural:
            det = "the"
        elif n_referents < len(_NUMBER_WORDS) and rng.random() < p_count_word:
            word = _NUMBER_WORDS[n_referents]
            forms = ("two", "the two", "both") if n_referents == 2 else (word, f"the {word}")
            det = _pick(rng, (*forms, f"all {word}") if n_referents > 2 else forms)
        else:
            det = _pick(rng, ("the", "the", "all the", "all of the"))
        words = [det, *([adjective] if adjective else []), noun, *post]
        text = " ".join(words)
        text = text[:1].upper() + text[1:] + "."
        if not _repeats(text) and len(text.split()) <= max_words:
            break
    return text


# --------------------------------------------------------------------------------------------
# Generation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PromptConfig:
    """Sampling settings of :func:`generate_prompts` (the semantics are fixed module constants).

    Attributes:
        attribute_weights: Probabilities of 0, 1, 2, 3 non-class attributes.
        p_class: Probability of naming the class (always named when no attribute is drawn).
        p_extreme: Probability of a superlative.
        p_count_word: Probability of stating the count of a plural referent set.
        p_adjective: Probability of saying one attribute before the noun ("the parked cars").
        max_words: Longest sentence in words (Talk2Radar's text encoder keeps 30 tokens).
        require_crisp: Only emit crisp predicates (module docstring).
        plural_bias: Probability of redrawing a predicate that refers to a single actor, to come
            closer to Talk2Radar's mix (about 2.4 referred objects per prompt).
        tries_per_prompt: Sampling attempts per requested prompt before giving up.
    """

    attribute_weights: tuple[float, float, float, float] = (0.1, 0.4, 0.35, 0.15)
    p_class: float = 0.9
    p_extreme: float = 0.1
    p_count_word: float = 0.4
    p_adjective: float = 0.35
    max_words: int = 22
    require_crisp: bool = True
    plural_bias: float = 0.5
    tries_per_prompt: int = 40

    def __post_init__(self) -> None:
        w = self.attribute_weights
        if len(w) != 4 or min(w) < 0 or not math.isclose(sum(w), 1.0, abs_tol=1e-6):
            raise ValueError(f"PromptConfig: attribute_weights must be 4 probabilities, got {w}")
        for name in ("p_class", "p_extreme", "p_count_word", "p_adjective", "plural_bias"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"PromptConfig: {name}={p} is not a probability")


def _depth_atom(f: ActorFeatures, rng: np.random.Generator) -> Atom | None:
    d = f.depth
    kind = int(rng.integers(4))
    if kind == 0:
        value = round(d) if rng.random() < 0.5 else 5 * round(d / 5)
        return DepthAbout(float(max(value, 3)))
    if kind == 1:
        lo = 5 * math.floor((d - 1.0) / 5)
        hi = lo + 5 if lo + 5 >= d + 1.0 else lo + 10
        return DepthBetween(float(lo), float(hi)) if lo > 0 else DepthWithin(float(hi))
    if kind == 2:
        return DepthWithin(float(5 * math.ceil((d + 1.0) / 5)))
    lo = 5 * math.floor((d - 1.0) / 5)
    return DepthBeyond(float(lo)) if lo >= 5 else None


def _speed_atom(f: ActorFeatures, rng: np.random.Generator) -> Atom | None:
    kmh = f.speed * 3.6
    use_kmh = rng.random() < 0.5 and kmh >= 10.0
    kind = int(rng.integers(3))
    if kind == 0:
        if use_kmh:
            return SpeedAbout(float(5 * round(kmh / 5)), SpeedUnit.KMH)
        value = round(f.speed) if f.speed >= 1.5 else round(f.speed * 2) / 2
        return SpeedAbout(float(value), SpeedUnit.MPS) if value > 0 else None
    if kind == 1:
        if use_kmh:
            v = 5 * math.floor((kmh - 3.0) / 5)
            return SpeedAbove(float(v), SpeedUnit.KMH) if v >= 5 else None
        v = math.floor(f.speed - 0.6)
        return SpeedAbove(float(v), SpeedUnit.MPS) if v >= 1 else None
    if use_kmh:
        return SpeedBelow(float(5 * math.ceil((kmh + 3.0) / 5)), SpeedUnit.KMH)
    return SpeedBelow(float(math.ceil(f.speed + 0.6)), SpeedUnit.MPS)


def _side_of(f: ActorFeatures) -> Side | None:
    for side in Side:
        if OnSide(side).holds(f):
            return side
    return None


def _sample_predicate(
    f: ActorFeatures, rng: np.random.Generator, cfg: PromptConfig
) -> Predicate | None:
    moving = f.speed > MOVING_SPEED
    families = ["depth", "motion"]
    side = _side_of(f)
    if side is not None:
        families.append("position")
    if moving and f.speed > 1.0:
        families.append("speed")
    k = min(int(rng.choice(4, p=cfg.attribute_weights)), len(families))
    chosen = [families[int(i)] for i in rng.permutation(len(families))[:k]]
    atoms: list[Atom] = []
    for fam in chosen:
        atom: Atom | None
        if fam == "depth":
            atom = _depth_atom(f, rng)
        elif fam == "position":
            atom = OnSide(side) if side is not None else None
        elif fam == "speed":
            atom = _speed_atom(f, rng)
        elif moving:
            headings = [h for h in Heading if HeadingIs(h).holds(f, -1.0)]
            if headings and (rng.random() < 0.75 or "speed" in chosen):
                atom = HeadingIs(headings[int(rng.integers(len(headings)))])
            else:
                atom = None if "speed" in chosen else MotionState(True)
        else:
            atom = MotionState(False)
        if atom is not None:
            atoms.append(atom)
    cls = f.cls if (rng.random() < cfg.p_class or not atoms) else None
    extreme = None
    if rng.random() < cfg.p_extreme:
        kinds = [e for e in Extreme if e is not Extreme.FASTEST or moving]
        extreme = kinds[int(rng.integers(len(kinds)))]
    if cls is None and not atoms and extreme is None:
        return None
    return Predicate(cls, tuple(atoms), extreme)


def generate_prompts(
    actors: Sequence[Actor],
    rng: np.random.Generator,
    n: int,
    *,
    region: ReferableRegion = DEFAULT_REGION,
    config: PromptConfig | None = None,
) -> list[Prompt]:
    """Up to ``n`` distinct prompts about the scene, each with its exact referent set.

    Each attempt draws an anchor among the referable actors, attributes true of it (class, depth,
    position, motion or heading, speed; 0-3 of them plus the class, sometimes a superlative),
    resolves the predicate over all actors and keeps it when it refers to something, has no
    conflicts, is crisp (unless ``config.require_crisp`` is False) and neither the predicate nor
    the text was emitted before. Fewer than ``n`` prompts come back when the scene does not admit
    ``n`` (none when no actor is referable). Deterministic for a given ``rng`` state.
    ``config`` defaults to :class:`PromptConfig()`.

    Raises:
        ValueError: ``n < 0`` or duplicate actor ids.
    """
    if n < 0:
        raise ValueError(f"generate_prompts: n must be >= 0, got {n}")
    config = config if config is not None else PromptConfig()
    feats = _features(actors)
    inside = [f for f in feats if region.contains(f)]
    out: list[Prompt] = []
    if not inside or n == 0:
        return out
    seen_pred: set[Predicate] = set()
    seen_text: set[str] = set()
    for _ in range(n * config.tries_per_prompt):
        if len(out) >= n:
            break
        anchor = inside[int(rng.integers(len(inside)))]
        pred = _sample_predicate(anchor, rng, config)
        if pred is None or pred in seen_pred:
            continue
        res = _analyse(pred, feats, region)
        if not res.usable or (config.require_crisp and not res.crisp):
            continue
        if len(res.ids) == 1 and rng.random() < config.plural_bias:
            continue
        seen_pred.add(pred)
        text = render(
            pred,
            len(res.ids),
            rng,
            p_count_word=config.p_count_word,
            p_adjective=config.p_adjective,
            max_words=config.max_words,
        )
        if text.lower() in seen_text or len(text.split()) > config.max_words:
            continue
        seen_text.add(text.lower())
        out.append(Prompt(text, res.ids, pred.tags, pred))
    return out


# --------------------------------------------------------------------------------------------
# Describing a given set (the annotation tool's suggester)
# --------------------------------------------------------------------------------------------


def _candidate_atoms(subset: Sequence[ActorFeatures]) -> list[Atom]:
    """Atoms true of every actor in ``subset``, simplest / roundest first."""
    cands: list[Atom] = [OnSide(s) for s in Side]
    cands += [MotionState(True), MotionState(False)]
    cands += [HeadingIs(h) for h in Heading]
    dmin = min(f.depth for f in subset)
    dmax = max(f.depth for f in subset)
    if dmax - dmin <= 2 * ABOUT_DEPTH_TOL - 1.0:
        centre = (dmin + dmax) / 2
        cands += [DepthAbout(float(v)) for v in (5 * round(centre / 5), round(centre)) if v >= 3]
    lo5, hi5 = 5 * math.floor((dmin - 0.5) / 5), 5 * math.ceil((dmax + 0.5) / 5)
    lo1, hi1 = math.floor(dmin - 0.5), math.ceil(dmax + 0.5)
    cands += [DepthWithin(float(hi5)), DepthWithin(float(hi1))]
    cands += [DepthBeyond(float(v)) for v in (lo5, lo1) if v >= 1]
    cands += [DepthBetween(float(lo), float(hi)) for lo, hi in ((lo5, hi5), (lo1, hi1)) if lo >= 1]
    smin = min(f.speed for f in subset)
    smax = max(f.speed for f in subset)
    if smin > MOVING_SPEED:
        kmh_mid = 3.6 * (smin + smax) / 2
        cands.append(SpeedAbout(float(5 * round(kmh_mid / 5)), SpeedUnit.KMH))
        if round((smin + smax) / 2) >= 1:
            cands.append(SpeedAbout(float(round((smin + smax) / 2)), SpeedUnit.MPS))
        cands += [
            SpeedAbove(float(v), SpeedUnit.KMH)
            for v in (5 * math.floor((3.6 * smin - 3.0) / 5),)
            if v >= 5
        ]
        cands += [SpeedAbove(float(v), SpeedUnit.MPS) for v in (math.floor(smin - 0.5),) if v >= 1]
        cands.append(SpeedBelow(float(5 * math.ceil((3.6 * smax + 3.0) / 5)), SpeedUnit.KMH))
        cands.append(SpeedBelow(float(math.ceil(smax + 0.5)), SpeedUnit.MPS))
    unique: list[Atom] = []
    for a in cands:
        if a not in unique and all(a.holds(f) for f in subset):
            unique.append(a)
    return unique


def describe_predicate(
    actors_subset: Sequence[Actor],
    all_actors: Sequence[Actor],
    region: ReferableRegion = DEFAULT_REGION,
) -> Predicate | None:
    """The simplest predicate that refers to exactly ``actors_subset`` (see :func:`describe`)."""
    feats = _features(all_actors)
    by_id = {f.actor_id: f for f in feats}
    want_ids = sorted({int(a.actor_id) for a in actors_subset})
    if not want_ids or any(i not in by_id for i in want_ids):
        return None
    subset = [by_id[i] for i in want_ids]
    if not all(region.contains(f) for f in subset):
        return None
    want = tuple(want_ids)
    classes = {f.cls for f in subset}
    cls_options: list[str | None] = [next(iter(classes)), None] if len(classes) == 1 else [None]
    extremes: list[Extreme | None] = [None]
    if len(subset) == 1:
        extremes += list(Extreme)
    atoms = _candidate_atoms(subset)
    fallback: Predicate | None = None
    for k in range(4):
        for combo in itertools.combinations(atoms, k):
            if len({a.family for a in combo}) != k:
                continue
            for extreme in extremes if k <= 1 else [None]:
                for cls in cls_options:
                    try:
                        pred = Predicate(cls, combo, extreme)
                    except ValueError:
                        continue
                    res = _analyse(pred, feats, region)
                    if res.ids != want or res.conflicts:
                        continue
                    if res.crisp:
                        return pred
                    if fallback is None:
                        fallback = pred
    return fallback


def describe(
    actors_subset: Sequence[Actor],
    all_actors: Sequence[Actor],
    rng: np.random.Generator,
    *,
    region: ReferableRegion = DEFAULT_REGION,
    max_words: int = 22,
) -> Prompt | None:
    """A sentence whose predicate selects exactly ``actors_subset`` among ``all_actors``.

    Predicates are tried from simple to complex (class alone; then 1, 2, 3 attributes true of
    every member; a superlative for a single actor), the first crisp one wins, else the first
    exact one that is not crisp. None when the subset is empty, holds an actor that is not
    referable or not in ``all_actors``, or no predicate of the language selects exactly it (for
    example two of three parked cars side by side). The sentence follows :func:`render`.
    """
    pred = describe_predicate(actors_subset, all_actors, region)
    if pred is None:
        return None
    ids = tuple(sorted({int(a.actor_id) for a in actors_subset}))
    return Prompt(render(pred, len(ids), rng, max_words=max_words), ids, pred.tags, pred)


__all__ = [
    "ABOUT_DEPTH_TOL",
    "DEFAULT_REGION",
    "TAGS",
    "ActorFeatures",
    "Atom",
    "DepthAbout",
    "DepthBetween",
    "DepthBeyond",
    "DepthWithin",
    "Extreme",
    "Heading",
    "HeadingIs",
    "MotionState",
    "OnSide",
    "Predicate",
    "Prompt",
    "PromptConfig",
    "ReferableRegion",
    "Resolution",
    "Side",
    "SpeedAbout",
    "SpeedAbove",
    "SpeedBelow",
    "SpeedUnit",
    "analyse",
    "describe",
    "describe_predicate",
    "flip_left_right",
    "generate_prompts",
    "infer_tags",
    "render",
    "resolve",
]
