"""The data domain: frames, boxes, calibration, Talk2Radar / VoD IO, the synthetic world, prompts.

``scenes`` imports neither ``model``, ``annotate`` nor ``app``. Its rooms and their layer order:
docs/DESIGN.md. The names below are the ones other packages use most; those of the heavier rooms
(the generator, the datasets) are loaded on first use (PEP 562), so that ``import scenes`` costs
no more than the formats.
"""

from scenes.frame import RootError, Sample
from scenes.frame.kitti import ObjectLabel, read_label_file, write_label_file
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.actors import CLASSES, Actor
from scenes.geometry.calib import (
    Calibration,
    read_calib,
    vod_lidar_calibration,
    vod_radar_calibration,
)
from scenes.talk2radar.root import SensorFiles, Talk2RadarRoot, Talk2RadarWriter, format_id
from scenes.utils.lazy import lazy_exports

_LAZY = {
    "LRUCache": "scenes.utils.lru",
    "atomic_write_text": "scenes.utils.durable",
    "clean_text": "scenes.utils.text_policy",
    "bev_iou": "scenes.geometry.boxes",
    "wrap_yaw": "scenes.geometry.boxes",
    "SynthSettings": "scenes.synth.generate",
    "generate_root": "scenes.synth.generate",
    "FrameDataset": "scenes.datasets.frames",
    "GroundingDataset": "scenes.datasets.grounding",
}
"""Exported name -> the module that defines it (loaded on first use)."""


__getattr__ = lazy_exports(__name__, _LAZY)


__all__ = [
    "CLASSES",
    "Actor",
    "Calibration",
    "FrameDataset",
    "GroundingDataset",
    "LRUCache",
    "ObjectLabel",
    "RootError",
    "Sample",
    "SampleMeta",
    "SensorFiles",
    "SynthSettings",
    "Talk2RadarRoot",
    "Talk2RadarWriter",
    "atomic_write_text",
    "bev_iou",
    "clean_text",
    "format_id",
    "generate_root",
    "read_calib",
    "read_label_file",
    "vod_lidar_calibration",
    "vod_radar_calibration",
    "wrap_yaw",
    "write_label_file",
]
