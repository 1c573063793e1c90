"""Actors of a driving scene: the objects a prompt can refer to.

An :class:`Actor` is one traffic participant at the frame's time stamp, described in the LiDAR frame
(x forward, y left, z up, metres). Its velocity is the *ground* velocity (ego motion removed), i.e.
what a radar's ``v_r_compensated`` measures along the line of sight. Motion words in prompts
("moving away", "approaching", "stationary") are defined on this ground velocity, so a parked car is
stationary even while the ego vehicle drives past it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenes.geometry.classes import ALL_CLASSES, VOD

CLASSES: tuple[str, ...] = VOD.names
"""The Talk2Radar metric classes (the ``vod`` class set), in the order of its heatmap channels."""

MOVING_SPEED = 0.5
"""Ground speed (m/s) above which an actor counts as moving."""


@dataclass(frozen=True)
class Actor:
    """One traffic participant.

    Attributes:
        actor_id: Unique id within the scene.
        cls: A class name of some class set (:data:`scenes.geometry.classes.ALL_CLASSES`).
        box: ``(7,)`` float64 ``x, y, z, l, w, h, yaw`` in the LiDAR frame, z at the geometric centre.
        velocity: ``(2,)`` float64 ground velocity ``(vx, vy)`` in m/s, LiDAR-frame axes.
    """

    actor_id: int
    cls: str
    box: np.ndarray = field(repr=False)
    velocity: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        if self.cls not in ALL_CLASSES:
            raise ValueError(
                f"Actor {self.actor_id}: class {self.cls!r} is not one of {ALL_CLASSES}"
            )
        box = np.asarray(self.box, dtype=np.float64).reshape(7)
        vel = np.asarray(self.velocity, dtype=np.float64).reshape(2)
        if not (np.all(np.isfinite(box)) and np.all(np.isfinite(vel))):
            raise ValueError(f"Actor {self.actor_id}: non-finite box or velocity")
        if np.any(box[3:6] <= 0):
            raise ValueError(f"Actor {self.actor_id}: box size must be positive, got {box[3:6]}")
        object.__setattr__(self, "box", box)
        object.__setattr__(self, "velocity", vel)

    @property
    def speed(self) -> float:
        """Ground speed in m/s."""
        return float(np.hypot(self.velocity[0], self.velocity[1]))

    @property
    def is_moving(self) -> bool:
        """True when the ground speed exceeds :data:`MOVING_SPEED`."""
        return self.speed > MOVING_SPEED

    @property
    def radial_velocity(self) -> float:
        """Ground velocity projected on the line of sight from the LiDAR origin to the box centre (m/s).

        Positive = moving away (receding), negative = approaching; the sign convention of VoD's
        ``v_r_compensated``.
        """
        centre = self.box[:2]
        norm = float(np.hypot(centre[0], centre[1]))
        if norm < 1e-9:
            return 0.0
        return float(np.dot(self.velocity, centre) / norm)

    def to_json(self) -> dict:
        """A JSON-serialisable dict (used by the sample sidecar)."""
        return {
            "actor_id": int(self.actor_id),
            "cls": self.cls,
            "box": [float(v) for v in self.box],
            "velocity": [float(v) for v in self.velocity],
        }

    @staticmethod
    def from_json(data: dict) -> Actor:
        """Inverse of :meth:`to_json`."""
        return Actor(int(data["actor_id"]), str(data["cls"]), data["box"], data["velocity"])
