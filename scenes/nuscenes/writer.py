"""The writer of a nuScenes root: records of the 13 tables gathered, then written as the release
has them (``v1.0-<version>/<table>.json``, ``maps/*.png``); tokens are 32 hex characters made
from a name (:func:`token`), so an export is the same byte for byte each time. The sensor files
themselves are :mod:`scenes.nuscenes.sensorfiles`'; what goes into the records is
:mod:`scenes.nuscenes.export`'s."""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np
from PIL import Image

from scenes.nuscenes.classes import ATTRIBUTES, CATEGORIES
from scenes.nuscenes.tables import TABLES
from scenes.utils.durable import atomic_write_bytes, atomic_write_text

__all__ = ["CHANNEL_MODALITY", "VISIBILITY", "TableWriter", "token"]

CHANNEL_MODALITY: dict[str, str] = {
    "CAM_FRONT": "camera",
    "CAM_FRONT_RIGHT": "camera",
    "CAM_BACK_RIGHT": "camera",
    "CAM_BACK": "camera",
    "CAM_BACK_LEFT": "camera",
    "CAM_FRONT_LEFT": "camera",
    "LIDAR_TOP": "lidar",
    "RADAR_FRONT": "radar",
    "RADAR_FRONT_LEFT": "radar",
    "RADAR_FRONT_RIGHT": "radar",
    "RADAR_BACK_LEFT": "radar",
    "RADAR_BACK_RIGHT": "radar",
}
"""The 12 sensors of nuScenes' vehicles and their modality."""
VISIBILITY = (("1", "v0-40"), ("2", "v40-60"), ("3", "v60-80"), ("4", "v80-100"))
"""nuScenes' visibility levels (token, level)."""


def token(*parts: object) -> str:
    """A 32-hex-character token made from ``parts`` (the same parts give the same token)."""
    return hashlib.md5("/".join(str(p) for p in parts).encode()).hexdigest()


class TableWriter:
    """The records of one version folder, gathered then written by :meth:`write`.

    The static tables (category: the 23, attribute: the 8, visibility, sensor: the 12) are
    filled on construction; ``records[name]`` is a list per table, appended to by the export.
    """

    def __init__(self) -> None:
        self.records: dict[str, list[dict]] = {name: [] for name in TABLES}
        for name in CATEGORIES:
            self.records["category"].append(
                {
                    "token": token("category", name),
                    "name": name,
                    "description": name,
                    "index": len(self.records["category"]),
                }
            )
        for name in ATTRIBUTES:
            self.records["attribute"].append(
                {"token": token("attribute", name), "name": name, "description": name}
            )
        for tok, level in VISIBILITY:
            self.records["visibility"].append(
                {
                    "token": tok,
                    "level": level,
                    "description": f"visibility of whole object is between {level[1:]} %",
                }
            )
        for channel, modality in CHANNEL_MODALITY.items():
            self.records["sensor"].append(
                {"token": token("sensor", channel), "channel": channel, "modality": modality}
            )

    def add(self, table: str, record: dict) -> dict:
        """Append a record (it must carry its token) and return it."""
        self.records[table].append(record)
        return record

    def write(self, root: Path, version: str) -> Path:
        """Write the 13 tables into ``root/version/`` and a small map mask per ``map`` record
        (the devkit opens them on load); returns the version folder."""
        folder = root / version
        folder.mkdir(parents=True, exist_ok=True)
        for name in TABLES:
            atomic_write_text(
                folder / f"{name}.json", json.dumps(self.records[name], indent=1) + "\n"
            )
        for rec in self.records["map"]:
            path = root / rec["filename"]
            path.parent.mkdir(parents=True, exist_ok=True)
            buffer = io.BytesIO()
            Image.fromarray(np.zeros((20, 20), dtype=np.uint8)).save(buffer, format="PNG")
            atomic_write_bytes(path, buffer.getvalue())
        return folder
