"""The ranges a random world is drawn from (:class:`WorldConfig`)."""

from __future__ import annotations

from dataclasses import dataclass

from scenes.geometry.calib import LIDAR_HEIGHT
from scenes.geometry.classes import PRESETS


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

    def __post_init__(self) -> None:
        if self.classes not in PRESETS:
            raise ValueError(
                f"WorldConfig: classes {self.classes!r} is not one of {tuple(PRESETS)}"
            )
