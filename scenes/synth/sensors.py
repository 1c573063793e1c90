"""The generator's sensor sets: View-of-Delft's (the default) and a nuScenes-like one.

``python -m scenes.synth --sensors vod`` (default) senses each world as View-of-Delft's car does: a
64-beam HDL-64-like LiDAR 1.70 m above the ground, one 4D imaging radar, a 1936 x 1216 camera
(:mod:`scenes.synth.lidar`, :mod:`scenes.synth.radar`, :mod:`scenes.synth.camera` with their
default configs). ``--sensors nuscenes`` uses :data:`NUSCENES`, presets of the same simulators
shaped as nuScenes' sensors (approximate values of the release's ``calibrated_sensor`` table, in
the ego frame: x forward, y left, z up):

* LIDAR_TOP: a Velodyne HDL-32E, 32 beams evenly from +10.67 to -30.67 degrees (4/3 degree apart),
  1.84 m above the ground (ego ``(0.986, 0, 1.84)``), 20 Hz spin (one sweep every 0.05 s; the
  simulated sweep has no motion skew), 0.33 degree azimuth step over the whole turn (about 35,000
  rays, as a nuScenes sweep's ~34,700 points), intensity as :mod:`scenes.synth.lidar` makes it.
* five Continental ARS-408-21-like radars (13 Hz): RADAR_FRONT (ego ``(3.41, 0, 0.50)``, yaw 0)
  with its two fields, near (+-60 degrees, up to 70 m) and far (+-9 degrees, 70-200 m); the corner
  radars RADAR_FRONT_LEFT / RIGHT (``(2.42, +-0.80, 0.78)``, yaw about +-90 degrees) and
  RADAR_BACK_LEFT / RIGHT (``(-0.56, +-0.62, 0.53)``, yaw about +-175 degrees), +-60 degrees, 70
  m. Sparse: about 2 cluster points on a car at 10 m, 1 on a person, static surfaces at a tenth of
  the 4D radar's rate, a few clutter points: tens to a couple of hundred points per sweep in all.
  2D: no elevation measured (``RadarConfig.measures_elevation`` False), so ``z`` is the mounting
  height plus noise. RCS, radial velocity and its ego-compensated form, and the ``time`` channel
  as the scan index (``-k`` for the ``k``-th older sweep, 1/13 s apart), as
  :mod:`scenes.synth.radar` makes them for VoD.
* CAM_FRONT: 1600 x 900, ``fx = fy = 1266.42``, ``cx = 816.27``, ``cy = 491.51``, at ego
  ``(1.70, 0.016, 1.51)``, untilted.

The root written stays a Talk2Radar-layout root: the LiDAR cloud in the LiDAR frame (x forward:
nuScenes' LIDAR_TOP turned 90 degrees about z, the model frame of ``../shared/ARCHITECTURE.md``);
the five radars merged into one ``(M, 7)`` cloud in that same frame, so the radar calibration
written is the LiDAR's (radar frame = LiDAR frame: ``sensor_to_lidar`` is the identity); each
sample's sidecar records the set and every sensor's mounting in ``extra["sensors"]``
(:meth:`SensorSet.meta`), so an exporter can put each radar's points back in its own frame
(``extra["sensors"]["radar_frame"] == "lidar"``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from scenes.geometry.calib import Calibration
from scenes.geometry.projection import scale_calibration
from scenes.synth.lidar import LidarConfig
from scenes.synth.radar import (
    ROAD_USER_SIGNATURES,
    RadarClassModel,
    RadarConfig,
    RadarScan,
    scaled_signatures,
    simulate_radar,
)
from scenes.synth.weather import CLEAR, Weather
from scenes.synth.world import RayCaster

SENSOR_SETS = ("vod", "nuscenes")
"""Values of ``--sensors``."""

_LIDAR_TO_CAM_ROTATION = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
"""Axis change LiDAR (x fwd, y left, z up) -> camera (x right, y down, z fwd), no tilt."""


@dataclass(frozen=True)
class RadarMount:
    """One radar field of a sensor set.

    Attributes:
        channel: nuScenes' channel name (the front radar's two fields share ``RADAR_FRONT``).
        position: Origin in the LiDAR (model) frame, metres.
        yaw_deg: Boresight yaw about z in the LiDAR frame (0: forward, +90: left).
        config: The simulated radar (:class:`scenes.synth.radar.RadarConfig`).
    """

    channel: str
    position: tuple[float, float, float]
    yaw_deg: float
    config: RadarConfig

    def to_lidar(self) -> np.ndarray:
        """``(4, 4)`` radar frame -> LiDAR frame."""
        c, s = np.cos(np.deg2rad(self.yaw_deg)), np.sin(np.deg2rad(self.yaw_deg))
        out = np.eye(4)
        out[:2, :2] = [[c, -s], [s, c]]
        out[:3, 3] = self.position
        return out


@dataclass(frozen=True)
class SensorSet:
    """A nuScenes-like sensor set (module docstring); positions in the LiDAR frame.

    Attributes:
        name: ``nuscenes``.
        lidar: The LiDAR's beams, sampling and noise.
        lidar_height: The LiDAR above the ground (m): the world's ground is ``z = -lidar_height``.
        lidar_spin_hz: Sweeps per second (recorded; one sweep is simulated without skew).
        lidar_in_ego: The LiDAR's origin in the ego frame (m; recorded for exporters).
        radars: The radar fields, merged into one cloud.
        radar_scan_hz: Radar sweeps per second (their ``scan_period`` is its inverse).
        camera_intrinsics: ``fx, fy, cx, cy`` at ``image_size``.
        image_size: ``(width, height)`` of the camera at scale 1.
        camera_in_lidar: The camera's origin in the LiDAR frame (untilted).
    """

    name: str
    lidar: LidarConfig
    lidar_height: float
    lidar_spin_hz: float
    lidar_in_ego: tuple[float, float, float]
    radars: tuple[RadarMount, ...]
    radar_scan_hz: float
    camera_intrinsics: tuple[float, float, float, float]
    image_size: tuple[int, int]
    camera_in_lidar: tuple[float, float, float]

    def calibration(self, scale: float = 1.0) -> Calibration:
        """The LiDAR calibration written (the radar's too): ``P2`` the camera's intrinsics
        (scaled by ``scale`` with the image), ``Tr_velo_to_cam`` LiDAR -> camera."""
        fx, fy, cx, cy = self.camera_intrinsics
        p2 = np.array([[fx, 0.0, cx, 0.0], [0.0, fy, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
        t = -_LIDAR_TO_CAM_ROTATION @ np.asarray(self.camera_in_lidar)
        calib = Calibration(
            P2=p2, R0_rect=np.eye(3), Tr_velo_to_cam=np.c_[_LIDAR_TO_CAM_ROTATION, t]
        )
        return calib if scale == 1.0 else scale_calibration(calib, scale)

    def meta(self) -> dict:
        """What a sample's sidecar records (``extra["sensors"]``)."""
        return {
            "set": self.name,
            "radar_frame": "lidar",
            "lidar": {
                "beams": self.lidar.beams_per_block * 2,
                "elevation_deg": [self.lidar.upper_block[0], self.lidar.lower_block[1]],
                "height": self.lidar_height,
                "spin_hz": self.lidar_spin_hz,
                "in_ego": list(self.lidar_in_ego),
            },
            "radars": [
                {
                    "channel": m.channel,
                    "position": list(m.position),
                    "yaw_deg": m.yaw_deg,
                    "azimuth_half_fov_deg": m.config.azimuth_half_fov_deg,
                    "range": [m.config.min_range, m.config.max_range],
                }
                for m in self.radars
            ],
            "radar_scan_hz": self.radar_scan_hz,
            "camera": {
                "channel": "CAM_FRONT",
                "image_size": list(self.image_size),
                "intrinsics": list(self.camera_intrinsics),
                "position": list(self.camera_in_lidar),
            },
        }


def simulate_radars(
    caster: RayCaster,
    mounts: tuple[RadarMount, ...],
    rng: np.random.Generator,
    weather: Weather = CLEAR,
    scans: int = 5,
) -> RadarScan:
    """Every radar of ``mounts`` (:func:`scenes.synth.radar.simulate_radar`, ``scans`` sweeps
    each), merged into one ``(M, 7)`` cloud in the LiDAR frame, the newest sweep first."""
    parts = [simulate_radar(caster, m.to_lidar(), rng, m.config, weather, scans) for m in mounts]
    points = np.concatenate([p.points for p in parts])
    owner = np.concatenate([p.owner for p in parts])
    order = np.argsort(-points[:, 6], kind="stable")
    return RadarScan(points=points[order], owner=owner[order])


# ---- nuScenes ------------------------------------------------------------------------------------

_NUSC_LIDAR_IN_EGO = (0.986, 0.0, 1.84)
_ARS408_HZ = 13.0
_ARS408 = RadarConfig(
    azimuth_half_fov_deg=60.0,
    elevation_half_fov_deg=10.0,
    min_range=0.2,
    max_range=70.0,
    range_std=0.1,
    azimuth_std_deg=0.5,
    elevation_std_deg=0.5,
    velocity_std=0.1,
    scan_period=1.0 / _ARS408_HZ,
    snr_offset=34.0,
    car=RadarClassModel(0.0, 8.0, 2.0, 0.05),
    pedestrian=RadarClassModel(-13.0, -11.0, 1.0, 0.3),
    cyclist=RadarClassModel(-11.0, -6.0, 1.0, 0.2),
    road_users=scaled_signatures(ROAD_USER_SIGNATURES, 0.2),
    clutter_per_scan=4.0,
    ghost_prob=0.03,
    static_prob_scale=0.05,
    measures_elevation=False,
)
"""An ARS-408-21's near field (module docstring)."""
_ARS408_FAR = replace(
    _ARS408, azimuth_half_fov_deg=9.0, elevation_half_fov_deg=7.0, min_range=70.0, max_range=200.0
)


def _mount(channel: str, ego: tuple[float, float, float], yaw: float, config: RadarConfig):
    lx, ly, lz = _NUSC_LIDAR_IN_EGO
    return RadarMount(channel, (ego[0] - lx, ego[1] - ly, ego[2] - lz), yaw, config)


NUSCENES = SensorSet(
    name="nuscenes",
    lidar=LidarConfig(
        upper_block=(10.67, -9.33),
        lower_block=(-10.67, -30.67),
        beams_per_block=16,
        azimuth_step_deg=0.33,
        azimuth_half_fov_deg=180.0,
        max_range=100.0,
        reference_range=45.0,
    ),
    lidar_height=_NUSC_LIDAR_IN_EGO[2],
    lidar_spin_hz=20.0,
    lidar_in_ego=_NUSC_LIDAR_IN_EGO,
    radars=(
        _mount("RADAR_FRONT", (3.41, 0.0, 0.50), 0.0, _ARS408),
        _mount("RADAR_FRONT", (3.41, 0.0, 0.50), 0.0, _ARS408_FAR),
        _mount("RADAR_FRONT_LEFT", (2.42, 0.80, 0.78), 89.6, _ARS408),
        _mount("RADAR_FRONT_RIGHT", (2.42, -0.80, 0.77), -90.7, _ARS408),
        _mount("RADAR_BACK_LEFT", (-0.56, 0.63, 0.53), 175.3, _ARS408),
        _mount("RADAR_BACK_RIGHT", (-0.56, -0.62, 0.53), -175.2, _ARS408),
    ),
    radar_scan_hz=_ARS408_HZ,
    camera_intrinsics=(1266.417, 1266.417, 816.267, 491.507),
    image_size=(1600, 900),
    camera_in_lidar=(1.70 - _NUSC_LIDAR_IN_EGO[0], 0.016, 1.51 - _NUSC_LIDAR_IN_EGO[2]),
)
"""The nuScenes-like sensor set (module docstring)."""


def sensor_set(name: str) -> SensorSet | None:
    """The preset of ``--sensors name`` (None for ``vod``: the simulators' own defaults).

    Raises:
        ValueError: ``name`` is not one of :data:`SENSOR_SETS`.
    """
    if name == "vod":
        return None
    if name == "nuscenes":
        return NUSCENES
    raise ValueError(f"sensors must be one of {SENSOR_SETS}, got {name!r}")


__all__ = [
    "NUSCENES",
    "SENSOR_SETS",
    "RadarMount",
    "SensorSet",
    "sensor_set",
    "simulate_radars",
]
