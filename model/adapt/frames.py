"""The frames an adaptation run learns from: a root's sensor files and nothing else.

A root is a Talk2Radar or View-of-Delft layout root (``lidar/training/{velodyne,calib}`` and
optionally a radar tree); it needs no ``label_2/``, ``prompt/``, ``ImageSets/`` or ``meta/``, and
where they exist they are never read: frames come from
:meth:`scenes.datasets.source.Talk2RadarRoot.load_sensors` with ``sidecar=False`` (the
Talk2Radar reader itself: a sensor-only read is that family's, not every
:class:`~scenes.frame.FrameSource`'s). Without
``--split`` every frame of the LiDAR folder is used (as a recording comes); samples sharing their
sensor files (several prompts on one frame, :meth:`Talk2RadarRoot.frame_key`) are one frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from model.adapt.config import AdaptError
from scenes.datasets.family_files import point_folder, split_list_file
from scenes.datasets.source import Talk2RadarRoot
from scenes.frame import RootError
from scenes.geometry.ground import level_clouds


@dataclass(frozen=True)
class SensorFrame:
    """One frame's sensors.

    Attributes:
        sample_id: Its 5-digit id.
        lidar: ``(N, 4)`` float32 ``x, y, z, intensity``, LiDAR frame.
        radar: ``(M, 7)`` float32, LiDAR frame (``(0, 7)`` without a radar tree).
    """

    sample_id: str
    lidar: np.ndarray
    radar: np.ndarray


class UnlabelledFrames:
    """The distinct frames of a root's sensor files (module docstring).

    Args:
        path: The root.
        radar: Radar tree (``auto``: the first present; ``none``: no radar).
        split: An ImageSets list name, or ``""`` for every frame of the LiDAR folder.
        max_frames: The first N frames only (0: all).
        ground_height: Given: each frame's clouds with heights above the ground estimated from its
            LiDAR cloud, that ground this far below the origin (a checkpoint whose
            ``PillarConfig.ground`` is ``estimated`` sees its frames so,
            :mod:`scenes.geometry.ground`); None: as they are.

    Raises:
        AdaptError: not a root, no frame (naming the split list when ``split`` is given and its
            list is empty, else the LiDAR folder), or a split list that is missing or malformed
            (one line naming the path).
    """

    def __init__(
        self,
        path: str | Path,
        radar: str = "auto",
        split: str = "",
        max_frames: int = 0,
        ground_height: float | None = None,
    ):
        self.ground_height = ground_height
        try:
            self.root = Talk2RadarRoot(
                path, radar=None if radar == "none" else radar, sidecar=False
            )
            ids = self.root.ids(split) if split else self.root.frame_ids()
            distinct: dict[tuple[object, ...], str] = {}
            for sid in ids:
                distinct.setdefault(self.root.frame_key(sid), sid)
        except RootError as exc:
            raise AdaptError(f"--data: {exc}") from exc
        self.ids = list(distinct.values())
        if max_frames:
            self.ids = self.ids[:max_frames]
        if not self.ids:
            listed = split_list_file(self.root, split)
            if split and listed is not None and listed.is_file():
                raise AdaptError(f"--split {split}: no frame to adapt on ({listed} lists no frame)")
            folder = point_folder(self.root)
            raise AdaptError(f"--data {path}: no frame to adapt on (no .bin file in {folder})")

    def __len__(self) -> int:
        return len(self.ids)

    def __getitem__(self, index: int) -> SensorFrame:
        sid = self.ids[index]
        try:
            sample = self.root.load_sensors(sid)
        except (RootError, ValueError, OSError) as exc:
            raise AdaptError(f"--data: {exc}") from exc
        lidar, radar = sample.lidar, sample.radar
        if self.ground_height is not None:
            _, lidar, radar = level_clouds(lidar, radar, self.ground_height)
        return SensorFrame(sid, lidar, radar)


__all__ = ["SensorFrame", "UnlabelledFrames"]
