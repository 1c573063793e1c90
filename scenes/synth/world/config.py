"""The ranges a random world is drawn from (:class:`WorldConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from scenes.geometry.calib import LIDAR_HEIGHT
from scenes.geometry.classes import PRESETS

MAX_STREET_DENSITY = 3.0
"""Largest factor of :class:`StreetDensity` (three layers of the roadside)."""


@dataclass(frozen=True)
class StreetDensity:
    """How much roadside a street has, as factors on what :func:`generate_world` draws by default
    (:mod:`scenes.synth.world.street`; issue 38's held-out streets).

    A factor ``f < 1`` keeps each drawn item with probability ``f``; ``f > 1`` adds ``f - 1``
    further layers of the same kind (the last one partly), drawn after the actors and never on
    them. The actors and the ego's speed are drawn before any of it, so a street of another
    density has the same actors as the default one of the same seed.

    Attributes:
        buildings: Buildings, walls and hedges beyond the building lines.
        trees: The verges' trees, street lights, signs and bollards.
        clutter: Parked bicycles, bicycle racks and mopeds.
    """

    buildings: float = 1.0
    trees: float = 1.0
    clutter: float = 1.0

    def __post_init__(self) -> None:
        for name in ("buildings", "trees", "clutter"):
            value = getattr(self, name)
            if not 0.0 <= value <= MAX_STREET_DENSITY:
                raise ValueError(
                    f"StreetDensity.{name} must be in [0, {MAX_STREET_DENSITY}], got {value}"
                )

    @property
    def is_default(self) -> bool:
        """Whether every factor is 1 (the generator's own streets)."""
        return self.buildings == self.trees == self.clutter == 1.0


@dataclass(frozen=True)
class WorldConfig:
    """Ranges of the random world.

    Attributes:
        cars, pedestrians, cyclists: Inclusive ranges of actor counts (placement may drop a few).
        ego_speed: Range of the ego speed along +x (m/s); ``ego_stopped`` is the chance it is 0.
        near_u: Abscissa range where most actors are placed (the annotated area and the camera
            view); ``far_fraction`` of them go to ``far_u`` instead.
        lidar_height: Ground plane at ``z = -lidar_height``.
        classes: The class set the world is populated for (``vod``: cars, pedestrians and
            cyclists, the counts above; ``nuscenes``: every road user of
            :data:`scenes.synth.world.road_users.NUSCENES_PLAN`, whose counts are its own).
        street: The roadside's density (default: the generator's own).
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
    classes: str = "vod"
    street: StreetDensity = field(default_factory=StreetDensity)

    def __post_init__(self) -> None:
        if self.classes not in PRESETS:
            raise ValueError(
                f"WorldConfig: classes {self.classes!r} is not one of {tuple(PRESETS)}"
            )
