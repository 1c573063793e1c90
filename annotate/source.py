"""The frame a new pair is annotated on: :class:`SourceFrame`, and its sensors written once.

A frame read from a Talk2Radar root is linked, not rewritten (its sensor files and its camera image
are hard-linked or copied into the pair's sample); a frame held only in memory gets its sensors
written once under ``<root>/sources/<key>-<hash>/`` (:func:`write_source`), reused by every pair
made on it. Paths come from :mod:`scenes.talk2radar.layout`.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scenes.frame import Sample
from scenes.geometry.calib import vod_radar_calibration
from scenes.talk2radar.layout import (
    CALIB,
    SOURCE_IMAGE,
    SOURCE_SENSORS,
    VELODYNE,
    format_id,
    sample_file,
    source_dir,
)
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.writer import SensorFiles, Talk2RadarWriter
from scenes.utils.durable import link_or_copy


@dataclass(frozen=True)
class SourceFrame:
    """The frame a new pair is annotated on.

    Attributes:
        key: A readable name of the frame (recorded in the manifest; names the ``sources/``
            folder when the sensors must be written).
        sample: Its sensors (LiDAR frame), calibrations and sidecar.
        files: Sensor files on disk to hard-link (or copy); None writes ``sample``'s arrays under
            ``<root>/sources/`` once and links those.
        root: The root the frame was read from, if any.
        sample_id: Its id there, if any.
    """

    key: str
    sample: Sample
    files: SensorFiles | None = None
    root: str | None = None
    sample_id: str | None = None

    @staticmethod
    def from_root(
        root: Talk2RadarRoot | str | Path, sample_id: str | int, sample: Sample | None = None
    ) -> SourceFrame:
        """A frame of a Talk2Radar root; its sensor files (and its camera image
        ``image_2/<id>.jpg`` or ``.png``, where it has one) are linked, not rewritten.

        ``sample`` is the frame already loaded from that root (read again when None).
        """
        r = root if isinstance(root, Talk2RadarRoot) else Talk2RadarRoot(root)
        sid = format_id(sample_id)
        sample = sample if sample is not None else r.load(sid)
        files = None
        if r.radar_dir is not None:
            files = SensorFiles(
                folder=r.path,
                lidar_bin=sample_file(r.lidar_dir, VELODYNE, sid),
                radar_bin=sample_file(r.radar_dir, VELODYNE, sid),
                lidar_calib=sample_file(r.lidar_dir, CALIB, sid),
                radar_calib=sample_file(r.radar_dir, CALIB, sid),
                image=r.image_path(sid),
            )
        return SourceFrame(f"{r.path.name}/{sid}", sample, files, str(r.path.resolve()), sid)

    @staticmethod
    def from_sample(sample: Sample, key: str | None = None) -> SourceFrame:
        """A frame held in memory (e.g. generated on the fly); its sensors get written once."""
        return SourceFrame(key or f"frame-{sample.sample_id}", sample, None, None, sample.sample_id)

    def describe(self) -> dict:
        """The manifest's ``source`` field."""
        return {"key": self.key, "root": self.root, "sample_id": self.sample_id}


def write_source(writer: Talk2RadarWriter, source: SourceFrame) -> SensorFiles:
    """Write an in-memory frame's sensors under ``<root>/sources/`` once (reused when present);
    its camera image file, where it has one, is linked there too."""
    sample = source.sample
    radar_calib = sample.radar_calib if sample.radar_calib is not None else vod_radar_calibration()
    digest = hashlib.sha1(usedforsecurity=False)
    digest.update(np.ascontiguousarray(sample.lidar, dtype="<f4").tobytes())
    digest.update(np.ascontiguousarray(sample.radar, dtype="<f4").tobytes())
    digest.update(sample.calib.to_text().encode())
    digest.update(radar_calib.to_text().encode())
    if sample.image_path is not None:
        digest.update(sample.image_path.read_bytes())
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", source.key).strip("._")[:60] or "frame"
    key = f"{safe}-{digest.hexdigest()[:10]}"
    folder = source_dir(writer.root, key)
    if all((folder / name).is_file() for name in SOURCE_SENSORS):
        files = SensorFiles.in_folder(folder)
    else:
        files = writer.write_sensors(key, sample.lidar, sample.radar, sample.calib, radar_calib)
    if sample.image_path is None:
        return files
    image = folder / f"{Path(SOURCE_IMAGE).stem}{sample.image_path.suffix}"
    if not image.is_file():
        link_or_copy(sample.image_path, image)
    return replace(files, image=image)


__all__ = ["SourceFrame", "write_source"]
