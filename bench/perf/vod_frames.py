"""Real-size View-of-Delft frames for :mod:`bench.perf.floor`: written in the release layout, read back.

A View-of-Delft frame as researchers download it holds one full HDL-64 spin (167k-189k LiDAR
points, most of them outside a model's grid) and a single radar scan (240-350 points); the
generator's default LiDAR casts only the forward half (about 110k-135k points) and its default
radar accumulates 5 scans. The frames here are the generator's worlds sensed as such a frame:

- LiDAR: :data:`FULL_SPIN`, the generator's HDL-64 over the whole turn (``|azimuth| <= 180``) at a
  0.11 degree step, which puts the point counts of its worlds in VoD's range;
- radar: one scan (``radar_scans=1``);
- only worlds whose counts fall in :data:`LIDAR_POINTS` and :data:`RADAR_POINTS` (the issue's
  ranges) and that have prompts are kept, in world order.

Each kept frame is written by :class:`scenes.talk2radar.vod_writer.VodWriter` (the one writer of the VoD
layout, as the tests' fixtures write theirs: radar stored in the radar frame, a ``radar`` tree for
the single scan, label_2 with the world's actors) into a folder, and read back through
:class:`scenes.talk2radar.root.Talk2RadarRoot`, as the app and ``model.evaluate`` read a VoD root. The
prompts come from the generator (a VoD root has none).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.frame.kitti import boxes_to_labels
from scenes.geometry.calib import sensor_to_lidar, vod_lidar_calibration, vod_radar_calibration
from scenes.synth.frame import SynthSettings, synthesize
from scenes.synth.lidar import LidarConfig
from scenes.talk2radar.root import Talk2RadarRoot, format_id
from scenes.talk2radar.vod_writer import VodWriter

LIDAR_POINTS = (167_000, 189_000)
"""LiDAR points per frame (inclusive) of View-of-Delft's frames (issue 20)."""
RADAR_POINTS = (240, 350)
"""Radar points of a single VoD scan (inclusive)."""
FULL_SPIN = LidarConfig(azimuth_half_fov_deg=180.0, azimuth_step_deg=0.11)
"""The generator's HDL-64 over a whole turn, at the step that gives VoD's point counts."""
RADAR_TREE = "radar"
"""The single-scan radar tree of a VoD root."""


@dataclass(frozen=True)
class VodFrame:
    """One real-size frame as read back from its VoD-layout files.

    Attributes:
        sample_id: 5-digit id (the world index).
        lidar: ``(N, 4)`` float32, LiDAR frame.
        radar: ``(M, 7)`` float32, LiDAR frame (read from the radar frame with the calibration).
        prompts: The generator's prompts about the world's sensed actors.
    """

    sample_id: str
    lidar: np.ndarray
    radar: np.ndarray
    prompts: tuple[str, ...]


def _in_range(n: int, bounds: tuple[int, int]) -> bool:
    return bounds[0] <= n <= bounds[1]


def vod_frames(
    out: str | Path, count: int, seed: int = 0, prompts: int = 4, max_worlds: int = 400
) -> list[VodFrame]:
    """``count`` real-size frames (see the module docstring) written under ``out`` and read back.

    Args:
        out: An empty or new folder (a VoD root is written there).
        count: Frames wanted.
        seed: The generator's base seed.
        prompts: Prompts drawn per world.
        max_worlds: Worlds tried at most.

    Raises:
        RuntimeError: fewer than ``count`` worlds of ``max_worlds`` have VoD's point counts.
    """
    lidar_calib, radar_calib = vod_lidar_calibration(), vod_radar_calibration()
    radar_to_lidar = sensor_to_lidar(lidar_calib, radar_calib)
    settings = SynthSettings(
        seed=seed, radar_scans=1, prompts_per_world=prompts, camera=None, lidar=FULL_SPIN
    )
    writer = VodWriter(out, (RADAR_TREE,))
    kept: dict[str, tuple[str, ...]] = {}
    for index in range(max_worlds):
        if len(kept) == count:
            break
        frame = synthesize(settings, index, radar_to_lidar)
        lidar, radar = frame.lidar.points, frame.radar.points
        if not frame.prompts or not (
            _in_range(len(lidar), LIDAR_POINTS) and _in_range(len(radar), RADAR_POINTS)
        ):
            continue
        actors = frame.world.actors
        boxes = np.array([a.box for a in actors], dtype=np.float64).reshape(-1, 7)
        writer.write_sensors(index, lidar, {RADAR_TREE: radar}, lidar_calib, radar_calib)
        writer.write_labels(index, boxes_to_labels(boxes, [a.cls for a in actors], lidar_calib))
        kept[format_id(index)] = tuple(p.text for p in frame.prompts)
    if len(kept) < count:
        raise RuntimeError(
            f"only {len(kept)} of the first {max_worlds} worlds have VoD's point counts "
            f"(LiDAR {LIDAR_POINTS}, radar {RADAR_POINTS}); {count} were asked for"
        )
    writer.write_image_sets({"val": list(kept)})
    root = Talk2RadarRoot(out, radar=RADAR_TREE)
    frames = []
    for sid, texts in kept.items():
        sample = root.load(sid)
        frames.append(VodFrame(sid, sample.lidar, sample.radar, texts))
    return frames
