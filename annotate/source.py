"""The frame a new pair is annotated on: :class:`SourceFrame`, and its sensors written once.

A frame read from a Talk2Radar root is linked, not rewritten (its sensor files are hard-linked or
copied into the pair's sample); a frame held only in memory gets its sensors written once under
``<root>/sources/<key>-<hash>/`` (:func:`write_source`), reused by every pair made on it.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from annotate.tree import RootFiles
from scenes.calib import vod_radar_calibration
from scenes.root import Sample, SensorFiles, Talk2RadarRoot, Talk2RadarWriter, format_id


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
        """A frame of a Talk2Radar root; its sensor files are linked, not rewritten.

        ``sample`` is the frame already loaded from that root (read again when None).
        """
        r = root if isinstance(root, Talk2RadarRoot) else Talk2RadarRoot(root)
        sid = format_id(sample_id)
        sample = sample if sample is not None else r.load(sid)
        files = None
        if r.radar_dir is not None:
            path = RootFiles.sample_file
            files = SensorFiles(
                folder=r.path,
                lidar_bin=path(r.lidar_dir, "velodyne", sid, "bin"),
                radar_bin=path(r.radar_dir, "velodyne", sid, "bin"),
                lidar_calib=path(r.lidar_dir, "calib", sid),
                radar_calib=path(r.radar_dir, "calib", sid),
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
    """Write an in-memory frame's sensors under ``<root>/sources/`` once (reused when present)."""
    sample = source.sample
    radar_calib = sample.radar_calib if sample.radar_calib is not None else vod_radar_calibration()
    digest = hashlib.sha1(usedforsecurity=False)
    digest.update(np.ascontiguousarray(sample.lidar, dtype="<f4").tobytes())
    digest.update(np.ascontiguousarray(sample.radar, dtype="<f4").tobytes())
    digest.update(sample.calib.to_text().encode())
    digest.update(radar_calib.to_text().encode())
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", source.key).strip("._")[:60] or "frame"
    key = f"{safe}-{digest.hexdigest()[:10]}"
    folder = writer.root / "sources" / key
    names = ("lidar.bin", "radar.bin", "lidar_calib.txt", "radar_calib.txt")
    if all((folder / n).is_file() for n in names):
        return SensorFiles(folder, *(folder / n for n in names))
    return writer.write_sensors(key, sample.lidar, sample.radar, sample.calib, radar_calib)


__all__ = ["SourceFrame", "write_source"]
