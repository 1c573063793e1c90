"""The attribute tests a prompt is built from, and superlatives: their exact meaning.

Semantics (LiDAR frame, x forward, y left; ground velocities, ego motion removed):

* **Depth** is the forward distance of the box's nearest point, ``min x`` over its four BEV corners
  (the TPCNet paper's argument: a prompt's distance refers to the object's edge nearest the ego
  vehicle, the anchor of C3D-RECHead). "about D m" = depth in ``[D - 2.5, D + 2.5]``; "between A
  and B m" = ``[A, B]``; "within D m" = ``<= D``; "further than D m" = ``> D``.
* **Position** uses the box centre: left = ``y > 1.5`` m, right = ``y < -1.5`` m (outside a 3 m
  wide ego corridor); "directly ahead" = ``|y| <= 1.5`` m *and* bearing ``|atan2(y, x)| <= 15``
  degrees (a pedestrian beside the bumper is neither ahead nor on a side).
* **Motion state**: moving = ground speed ``> 0.5`` m/s (:data:`scenes.geometry.actors.MOVING_SPEED`),
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

Slack. ``Atom.holds(f, slack)`` moves every threshold by ``slack`` units (0.5 m in depth, 0.25 m in
y, 1 degree in bearing, 0.2 m/s on the motion thresholds, 0.25 m/s on stated speeds, 5 degrees on
the crossing angle); > 0 loosens, < 0 tightens. :mod:`scenes.language.prompts.predicate` uses it to call a
predicate *crisp* when its referents do not change within one unit of slack.
"""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

from scenes.geometry.actors import MOVING_SPEED
from scenes.language.prompts.features import ActorFeatures

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

# Threshold shifts per unit of slack (module docstring).
SLACK_DEPTH = 0.5
SLACK_Y = 0.25
SLACK_BEARING = 1.0
SLACK_MOTION = 0.2
SLACK_SPEED = 0.25
SLACK_ANGLE = 5.0
# Smallest winner / runner-up gap of a crisp superlative.
GAP_DEPTH = 1.0
GAP_Y = 0.5
GAP_SPEED = 0.5


class Atom(ABC):
    """One attribute test of a predicate; concrete atoms are frozen dataclasses.

    ``holds(f, slack)``: the test on an actor's features; ``slack`` > 0 loosens and < 0 tightens
    every threshold by ``slack`` units (module docstring), 0 is the exact meaning. ``family``:
    a predicate holds at most one atom per family; ``tag``: the prompt type tag it gives.
    """

    family: ClassVar[str]
    tag: ClassVar[str]

    @abstractmethod
    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        """Whether the attribute is true of the actor."""

    def flipped(self) -> Atom:
        """The atom after the world's y -> -y flip (only position atoms change)."""
        return self


class Side(enum.Enum):
    """Lateral position classes (module docstring)."""

    LEFT = "left"
    RIGHT = "right"
    AHEAD = "ahead"


@dataclass(frozen=True)
class OnSide(Atom):
    """Left / right of the ego corridor, or directly ahead in it."""

    side: Side
    family: ClassVar[str] = "position"
    tag: ClassVar[str] = "position"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        lane = LANE_HALF_WIDTH - SLACK_Y * slack
        if self.side is Side.LEFT:
            return f.y > lane
        if self.side is Side.RIGHT:
            return f.y < -lane
        lane = LANE_HALF_WIDTH + SLACK_Y * slack
        bearing = AHEAD_MAX_BEARING_DEG + SLACK_BEARING * slack
        return abs(f.y) <= lane and abs(f.bearing_deg) <= bearing

    def flipped(self) -> OnSide:
        swap = {Side.LEFT: Side.RIGHT, Side.RIGHT: Side.LEFT, Side.AHEAD: Side.AHEAD}
        return OnSide(swap[self.side])


@dataclass(frozen=True)
class MotionState(Atom):
    """Moving (ground speed above :data:`~scenes.geometry.actors.MOVING_SPEED`) or stationary."""

    moving: bool
    family: ClassVar[str] = "motion"
    tag: ClassVar[str] = "motion"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        if self.moving:
            return f.speed > MOVING_SPEED - SLACK_MOTION * slack
        return f.speed <= MOVING_SPEED + SLACK_MOTION * slack


class Heading(enum.Enum):
    """Motion relative to the ego vehicle (module docstring)."""

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
            return f.radial_velocity < -(HEADING_RADIAL_SPEED - SLACK_MOTION * slack)
        if self.heading is Heading.AWAY:
            return f.radial_velocity > HEADING_RADIAL_SPEED - SLACK_MOTION * slack
        return (
            f.speed > MOVING_SPEED - SLACK_MOTION * slack
            and f.crossing_angle_deg <= CROSSING_MAX_ANGLE_DEG + SLACK_ANGLE * slack
        )


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
        return abs(f.speed - v) <= self.tol_mps + SLACK_SPEED * slack


@dataclass(frozen=True)
class SpeedAbove(Atom):
    """Ground speed above ``value`` (in ``unit``)."""

    value: float
    unit: SpeedUnit
    family: ClassVar[str] = "speed"
    tag: ClassVar[str] = "velocity"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.speed > self.value * self.unit.to_mps - SLACK_SPEED * slack


@dataclass(frozen=True)
class SpeedBelow(Atom):
    """Moving, with a ground speed below ``value`` (in ``unit``)."""

    value: float
    unit: SpeedUnit
    family: ClassVar[str] = "speed"
    tag: ClassVar[str] = "velocity"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        moving = f.speed > MOVING_SPEED - SLACK_MOTION * slack
        return moving and f.speed < self.value * self.unit.to_mps + SLACK_SPEED * slack


@dataclass(frozen=True)
class DepthAbout(Atom):
    """Nearest-edge forward distance within ``metres +- tol``."""

    metres: float
    tol: float = ABOUT_DEPTH_TOL
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return abs(f.depth - self.metres) <= self.tol + SLACK_DEPTH * slack


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
        s = SLACK_DEPTH * slack
        return self.lo - s <= f.depth <= self.hi + s


@dataclass(frozen=True)
class DepthWithin(Atom):
    """Nearest-edge forward distance at most ``metres``."""

    metres: float
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.depth <= self.metres + SLACK_DEPTH * slack


@dataclass(frozen=True)
class DepthBeyond(Atom):
    """Nearest-edge forward distance greater than ``metres``."""

    metres: float
    family: ClassVar[str] = "depth"
    tag: ClassVar[str] = "depth"

    def holds(self, f: ActorFeatures, slack: float = 0.0) -> bool:
        return f.depth > self.metres - SLACK_DEPTH * slack


class Extreme(enum.Enum):
    """Superlatives: pick the one actor that ranks first among the predicate's matches.

    ``SLOWEST`` ranks the moving matches only (speed above :data:`~scenes.geometry.actors.MOVING_SPEED`,
    :meth:`ranks`): "the slowest cyclist" is the slowest of the cyclists that ride, and it is
    crisp only when every match clearly moves (a standing actor might be said to be the slowest).
    ``FASTEST`` ranks every match but names nobody when its winner stands, and is crisp only when
    the winner clearly moves. ``SLOWEST`` is the extended language's (:data:`BASE_EXTREMES` are the
    base generator's, whose prompts stay byte-identical).
    """

    NEAREST = "nearest"
    FARTHEST = "farthest"
    LEFTMOST = "leftmost"
    RIGHTMOST = "rightmost"
    FASTEST = "fastest"
    SLOWEST = "slowest"

    @property
    def tag(self) -> str:
        """The prompt type tag of this superlative."""
        if self in (Extreme.NEAREST, Extreme.FARTHEST):
            return "depth"
        if self in (Extreme.FASTEST, Extreme.SLOWEST):
            return "velocity"
        return "position"

    def key(self, f: ActorFeatures) -> float:
        """Ranking score, larger wins."""
        if self is Extreme.NEAREST:
            return -f.depth
        if self is Extreme.FARTHEST:
            return f.depth
        if self is Extreme.LEFTMOST:
            return f.y
        if self is Extreme.RIGHTMOST:
            return -f.y
        if self is Extreme.SLOWEST:
            return -f.speed
        return f.speed

    @property
    def gap(self) -> float:
        """Smallest winner / runner-up score gap of a crisp superlative."""
        if self in (Extreme.NEAREST, Extreme.FARTHEST):
            return GAP_DEPTH
        return GAP_SPEED if self.by_speed else GAP_Y

    def ranks(self, f: ActorFeatures) -> bool:
        """Whether ``f`` takes part in this superlative's ranking (``SLOWEST``: the moving only)."""
        return self is not Extreme.SLOWEST or f.speed > MOVING_SPEED

    @property
    def by_speed(self) -> bool:
        """Ranks by speed (class docstring)."""
        return self in (Extreme.FASTEST, Extreme.SLOWEST)

    def flipped(self) -> Extreme:
        """The superlative after the y -> -y flip."""
        swap = {Extreme.LEFTMOST: Extreme.RIGHTMOST, Extreme.RIGHTMOST: Extreme.LEFTMOST}
        return swap.get(self, self)


BASE_EXTREMES = (
    Extreme.NEAREST,
    Extreme.FARTHEST,
    Extreme.LEFTMOST,
    Extreme.RIGHTMOST,
    Extreme.FASTEST,
)
"""The base generator's superlatives (:class:`Extreme`)."""


FAMILY_ORDER = ("position", "motion", "heading", "speed", "depth")
"""Canonical order of the atom families in a :class:`~scenes.language.prompts.predicate.Predicate`."""
