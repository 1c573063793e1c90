"""What prompts talk about, per actor, and where an actor can be a referent.

All quantities are in the LiDAR frame (x forward, y left), velocities are ground velocities with
the ego motion removed (see :mod:`scenes.geometry.actors`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from scenes.geometry.actors import Actor


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
        """The features of an :class:`~scenes.geometry.actors.Actor`."""
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


def actor_features(actors: Sequence[Actor]) -> list[ActorFeatures]:
    """The features of every actor, in order.

    Raises:
        ValueError: Two actors share an id.
    """
    feats = [ActorFeatures.of(a) for a in actors]
    seen: set[int] = set()
    for f in feats:
        if f.actor_id in seen:
            raise ValueError(f"actors: duplicate actor_id {f.actor_id}")
        seen.add(f.actor_id)
    return feats


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
        """True when the actor is outside the region but visible close to it (package doc)."""
        f = actor if isinstance(actor, ActorFeatures) else ActorFeatures.of(actor)
        if self.contains(f):
            return False
        in_x = self.x_min - self.guard_m <= f.x <= self.x_max + self.guard_m
        return in_x and abs(f.bearing_deg) <= self.half_fov_deg + self.guard_deg


DEFAULT_REGION = ReferableRegion()
