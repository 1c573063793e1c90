"""The data domain: frames, boxes, calibration, Talk2Radar / VoD IO, the synthetic world, prompts.

``scenes`` imports neither ``model``, ``annotate`` nor ``app``.
"""

from scenes.geometry.actors import CLASSES, Actor
from scenes.geometry.calib import (
    Calibration,
    read_calib,
    vod_lidar_calibration,
    vod_radar_calibration,
)
from scenes.talk2radar.kitti import ObjectLabel, read_label_file, write_label_file
from scenes.talk2radar.root import (
    RootError,
    Sample,
    SampleMeta,
    SensorFiles,
    Talk2RadarRoot,
    Talk2RadarWriter,
    format_id,
)

__all__ = [
    "CLASSES",
    "Actor",
    "Calibration",
    "ObjectLabel",
    "RootError",
    "Sample",
    "SampleMeta",
    "SensorFiles",
    "Talk2RadarRoot",
    "Talk2RadarWriter",
    "format_id",
    "read_calib",
    "read_label_file",
    "vod_lidar_calibration",
    "vod_radar_calibration",
    "write_label_file",
]
