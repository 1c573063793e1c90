"""Surface materials of the synthetic world and their sensor-facing properties (LiDAR
reflectivity, dropout and depth jitter; radar RCS and detection probability of static surfaces),
as arrays indexed by :class:`Mat` for the sensor simulators."""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np


class Mat(enum.IntEnum):
    """Surface materials (the integer is the index into :data:`MATERIALS`)."""

    ASPHALT = 0
    MARKING = 1
    BIKE_PATH = 2
    PAVING = 3
    GRASS = 4
    SOIL = 5
    BRICK = 6
    CONCRETE = 7
    GLASS_FACADE = 8
    METAL = 9
    SIGN = 10
    BARK = 11
    FOLIAGE = 12
    PAINT_DARK = 13
    PAINT_LIGHT = 14
    CAR_GLASS = 15
    RUBBER = 16
    CLOTHING = 17
    SKIN = 18
    BIKE_FRAME = 19
    CLOTHING_DARK = 20
    CONE_ORANGE = 21
    WORKS_YELLOW = 22


@dataclass(frozen=True)
class Material:
    """Sensor-facing properties of a surface.

    Attributes:
        reflectivity: LiDAR diffuse reflectivity in ``[0, 1]`` (retro-reflective signs near 1).
        lidar_dropout: Extra probability that a LiDAR return is lost (glass, foliage).
        lidar_depth_jitter: Extra range spread in metres (penetration into foliage).
        radar_rcs: RCS in dBsm of one radar detection on this surface (static clutter).
        radar_prob: Probability that one ray of the radar's visibility grid (0.4 x 1.5 degrees)
            hitting this static surface becomes a detection, before the SNR factor.
    """

    reflectivity: float
    lidar_dropout: float = 0.0
    lidar_depth_jitter: float = 0.0
    radar_rcs: float = -10.0
    radar_prob: float = 0.0


MATERIALS: tuple[Material, ...] = (
    Material(0.25, 0.1, radar_rcs=-28.0, radar_prob=0.012),  # ASPHALT (dark or wet: drops)
    Material(0.80, radar_rcs=-28.0, radar_prob=0.012),  # MARKING
    Material(0.30, radar_rcs=-27.0, radar_prob=0.012),  # BIKE_PATH (red asphalt)
    Material(0.35, radar_rcs=-25.0, radar_prob=0.02),  # PAVING
    Material(0.55, radar_rcs=-26.0, radar_prob=0.015),  # GRASS
    Material(0.30, radar_rcs=-28.0, radar_prob=0.004),  # SOIL
    Material(0.40, radar_rcs=-12.0, radar_prob=0.1),  # BRICK
    Material(0.45, radar_rcs=-10.0, radar_prob=0.1),  # CONCRETE
    Material(0.15, lidar_dropout=0.3, radar_rcs=-8.0, radar_prob=0.12),  # GLASS_FACADE
    Material(0.50, radar_rcs=0.0, radar_prob=0.5),  # METAL (poles, racks)
    Material(0.95, radar_rcs=4.0, radar_prob=0.6),  # SIGN (retro-reflective)
    Material(0.35, radar_rcs=-14.0, radar_prob=0.15),  # BARK
    Material(0.60, 0.25, 0.6, radar_rcs=-22.0, radar_prob=0.04),  # FOLIAGE
    Material(0.20, radar_rcs=-6.0, radar_prob=0.3),  # PAINT_DARK (static: mopeds)
    Material(0.80, radar_rcs=-6.0, radar_prob=0.3),  # PAINT_LIGHT
    Material(0.06, lidar_dropout=0.4),  # CAR_GLASS
    Material(0.08, radar_rcs=-20.0, radar_prob=0.05),  # RUBBER
    Material(0.40, radar_rcs=-20.0, radar_prob=0.05),  # CLOTHING (panniers)
    Material(0.50),  # SKIN
    Material(0.45, radar_rcs=-12.0, radar_prob=0.3),  # BIKE_FRAME (parked bicycles)
    Material(0.12, radar_rcs=-20.0, radar_prob=0.05),  # CLOTHING_DARK (dark coats, jeans)
    Material(0.45, radar_rcs=-22.0, radar_prob=0.05),  # CONE_ORANGE (cones, plastic barriers)
    Material(0.60, radar_rcs=-6.0, radar_prob=0.3),  # WORKS_YELLOW (construction vehicles)
)
"""Material properties indexed by :class:`Mat`."""

REFLECTIVITY = np.array([m.reflectivity for m in MATERIALS])
LIDAR_DROPOUT = np.array([m.lidar_dropout for m in MATERIALS])
LIDAR_DEPTH_JITTER = np.array([m.lidar_depth_jitter for m in MATERIALS])
RADAR_RCS = np.array([m.radar_rcs for m in MATERIALS])
RADAR_PROB = np.array([m.radar_prob for m in MATERIALS])
