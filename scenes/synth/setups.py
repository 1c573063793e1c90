"""Sensor set-ups: the one home of issue 38's held-out rigs (``python -m scenes.synth
--sensor-setup NAME``, ``python -m bench.sensor_shift``).

A :class:`SensorSetup` says how a world is sensed: the LiDAR (beam pattern, sampling, pitch,
intensity scale, dropout, range noise: :class:`scenes.synth.lidar.LidarConfig`) and its height
above the ground, the radar (the 4D radar's :class:`scenes.synth.radar.RadarConfig` and its scan
count, or other radars merged in the LiDAR frame), and the street's density
(:class:`scenes.synth.world.config.StreetDensity`). :data:`IN_DOMAIN` is the rig of every
training root (View-of-Delft's, the simulators' defaults); :data:`HELD_OUT` are rigs training
never uses. The world of a seed is the same whatever the set-up (the actors, their boxes and the
ego's speed; a street of another density keeps them and changes only the roadside), so a set-up's
figures and the in-domain ones are on the same actors.

Mounting: the LiDAR moves on the car; the camera and the radar stay where they are. A LiDAR
``dz`` metres higher than VoD's 1.70 m sees the ground ``dz`` further down, and the calibration
written with it (:func:`lidar_calibration_at`) has the camera (and, through it, the radar) ``dz``
lower in the LiDAR frame, so the radar points still land where the radar saw them. A pitched
LiDAR reports its points in its own pitched frame (the ground rises ahead of a sensor pitched nose
down); :meth:`SensorSetup.boxes_in_lidar_frame` gives the actors' boxes in that frame, which
``bench.studies.sensor_shift`` scores against. A root written with such a rig keeps its labels, radar and
camera in the car's level frame at the LiDAR's origin (its calibration does not know the pitch).

The held-out rigs:

* ``nuscenes-lidar``: the 32-beam HDL-32E of ``--sensors nuscenes`` (its pattern, 0.33 degree
  azimuth step, 1.84 m up), with VoD's 4D radar.
* ``lidar-128``: 128 beams from +15 to -25 degrees (a Pandar128-like span; two blocks of 64,
  +15..-4 and -4.3..-25), the HDL-64's 0.08 degree azimuth step (so twice its rays).
* ``lidar-low-pitched``: the HDL-64 mounted 0.3 m lower (1.40 m) and pitched 2 degrees nose down.
* ``intensity-x0.5``, ``intensity-x2``: the HDL-64's intensity scaled by 0.5 and by 2.
* ``radar-1scan``: one radar scan instead of five (the root's ``radar`` tree).
* ``radar-sparse``: the five sparse 2D ARS-408-like radars of ``--sensors nuscenes``
  (:data:`scenes.synth.sensors.NUSCENES`) instead of the 4D radar, five scans each.
* ``streets-sparse``: a third of the buildings, trees and street furniture, a quarter of the
  clutter; ``streets-dense``: twice the buildings, trees and furniture, three times the clutter.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from scenes.geometry.calib import LIDAR_HEIGHT, Calibration
from scenes.synth.lidar import LidarConfig, pitch_rotation
from scenes.synth.radar import RadarConfig
from scenes.synth.sensors import NUSCENES, RadarMount
from scenes.synth.world.config import StreetDensity


@dataclass(frozen=True)
class SensorSetup:
    """How one world is sensed (module docstring).

    Attributes:
        name: The set-up's name (``--sensor-setup``), or ``randomised`` for a drawn one.
        summary: One line for tables and ``--help``.
        lidar: The LiDAR.
        lidar_height: The LiDAR above the ground (m); the ground is ``z = -lidar_height``.
        radar: The 4D radar (used when ``radar_mounts`` is empty).
        radar_mounts: Radars merged into one cloud in the LiDAR frame instead of the 4D radar.
        radar_scans: Accumulated radar scans (the newest first, ``time = -k``).
        street: The roadside's density.
    """

    name: str
    summary: str
    lidar: LidarConfig = field(default_factory=LidarConfig)
    lidar_height: float = LIDAR_HEIGHT
    radar: RadarConfig = field(default_factory=RadarConfig)
    radar_mounts: tuple[RadarMount, ...] = ()
    radar_scans: int = 5
    street: StreetDensity = field(default_factory=StreetDensity)

    def __post_init__(self) -> None:
        if not 0.5 <= self.lidar_height <= 3.0:
            raise ValueError(
                f"{self.name}: lidar_height must be in [0.5, 3] m, got {self.lidar_height}"
            )
        if self.radar_scans < 1:
            raise ValueError(f"{self.name}: radar_scans must be >= 1, got {self.radar_scans}")
        if not 0.0 <= self.lidar.beam_dropout < 1.0:
            raise ValueError(
                f"{self.name}: beam_dropout must be in [0, 1), got {self.lidar.beam_dropout}"
            )

    def boxes_in_lidar_frame(self, boxes: np.ndarray) -> np.ndarray:
        """``(K, 7)`` boxes of the world (the car's level frame at the LiDAR's origin) in the
        LiDAR's own frame: the centres turned by its pitch (yaw and sizes kept: a box stays
        upright, as an annotator labelling in the sensor's frame along the ground would draw it,
        to a fraction of a degree). The boxes themselves without a pitch."""
        out = np.array(boxes, dtype=np.float64, copy=True).reshape(-1, 7)
        if self.lidar.pitch_deg != 0.0 and len(out):
            out[:, :3] = out[:, :3] @ pitch_rotation(self.lidar.pitch_deg)
        return out

    def meta(self) -> dict:
        """What a sample's sidecar records (``extra["sensor_setup"]``)."""
        lid = self.lidar
        return {
            "name": self.name,
            "lidar": {
                "beams": lid.beams,
                "elevation_deg": [
                    lid.upper_block[0],
                    lid.upper_block[1],
                    lid.lower_block[0],
                    lid.lower_block[1],
                ],
                "azimuth_step_deg": lid.azimuth_step_deg,
                "height": round(self.lidar_height, 4),
                "pitch_deg": round(lid.pitch_deg, 4),
                "intensity_scale": round(lid.intensity_scale, 4),
                "dropout": round(lid.dropout, 4),
                "beam_dropout": round(lid.beam_dropout, 4),
                "range_noise": round(lid.range_noise, 4),
            },
            "radar": {
                "kind": "merged" if self.radar_mounts else "4d",
                "channels": [m.channel for m in self.radar_mounts],
                "scans": self.radar_scans,
                "static_prob_scale": round(self.radar.static_prob_scale, 4),
                "clutter_per_scan": round(self.radar.clutter_per_scan, 4),
                "range_std": round(self.radar.range_std, 4),
                "azimuth_std_deg": round(self.radar.azimuth_std_deg, 4),
                "velocity_std": round(self.radar.velocity_std, 4),
            },
            "street": {
                "buildings": self.street.buildings,
                "trees": self.street.trees,
                "clutter": self.street.clutter,
            },
        }


def lidar_calibration_at(calib: Calibration, lidar_height: float) -> Calibration:
    """``calib`` (a LiDAR -> camera calibration of a LiDAR at :data:`LIDAR_HEIGHT`) for the same
    LiDAR moved on the car to ``lidar_height`` (camera and radar where they were): a point ``dz``
    higher in the old LiDAR frame is at the same place in the new one, so the translation gains
    ``dz * R[:, 2]``. Returns ``calib`` itself at :data:`LIDAR_HEIGHT`."""
    dz = lidar_height - LIDAR_HEIGHT
    if dz == 0.0:
        return calib
    tr = np.array(calib.Tr_velo_to_cam, dtype=np.float64, copy=True)
    tr[:, 3] += dz * tr[:, 2]
    return replace(calib, Tr_velo_to_cam=tr)


IN_DOMAIN = SensorSetup("vod", "in domain: VoD's HDL-64 (1.70 m), 4D radar, 5 scans")
"""The rig every training root is sensed with (the simulators' defaults)."""

_HDL64 = LidarConfig()

HELD_OUT: tuple[SensorSetup, ...] = (
    SensorSetup(
        "nuscenes-lidar",
        "nuScenes' 32-beam HDL-32E pattern, 1.84 m up",
        lidar=NUSCENES.lidar,
        lidar_height=NUSCENES.lidar_height,
    ),
    SensorSetup(
        "lidar-128",
        "128-beam LiDAR, +15 to -25 degrees",
        lidar=replace(
            _HDL64, upper_block=(15.0, -4.0), lower_block=(-4.3, -25.0), beams_per_block=64
        ),
    ),
    SensorSetup(
        "lidar-low-pitched",
        "HDL-64 0.3 m lower, pitched 2 degrees down",
        lidar=replace(_HDL64, pitch_deg=2.0),
        lidar_height=LIDAR_HEIGHT - 0.3,
    ),
    SensorSetup(
        "intensity-x0.5", "HDL-64 intensity x0.5", lidar=replace(_HDL64, intensity_scale=0.5)
    ),
    SensorSetup("intensity-x2", "HDL-64 intensity x2", lidar=replace(_HDL64, intensity_scale=2.0)),
    SensorSetup("radar-1scan", "one radar scan instead of five", radar_scans=1),
    SensorSetup(
        "radar-sparse",
        "five sparse 2D ARS-408-like radars instead of the 4D radar",
        radar_mounts=NUSCENES.radars,
    ),
    SensorSetup(
        "streets-sparse",
        "a third of the buildings and trees, a quarter of the clutter",
        street=StreetDensity(buildings=1 / 3, trees=1 / 3, clutter=0.25),
    ),
    SensorSetup(
        "streets-dense",
        "twice the buildings and trees, three times the clutter",
        street=StreetDensity(buildings=2.0, trees=2.0, clutter=3.0),
    ),
)
"""The held-out rigs (module docstring), in table order."""

SETUPS: dict[str, SensorSetup] = {s.name: s for s in (IN_DOMAIN, *HELD_OUT)}
"""Every named set-up by name (``--sensor-setup``)."""


def sensor_setup(name: str) -> SensorSetup:
    """The named set-up.

    Raises:
        ValueError: no set-up of that name (the message lists them).
    """
    try:
        return SETUPS[name]
    except KeyError:
        raise ValueError(f"sensor setup must be one of {list(SETUPS)}, got {name!r}") from None


__all__ = [
    "HELD_OUT",
    "IN_DOMAIN",
    "SETUPS",
    "SensorSetup",
    "lidar_calibration_at",
    "sensor_setup",
]
