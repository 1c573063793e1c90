"""The drives of a split: runs of consecutive 10 Hz frames, found from the pose files.

View-of-Delft and ``python -m scenes.synth --sequence-length N`` roots list the frames of a
drive one after the other, each with a pose file (:mod:`scenes.talk2radar.poses`). :func:`find_drives` walks
a split's sample ids in order: samples that show the same frame
(:meth:`scenes.talk2radar.root.Talk2RadarRoot.frame_key`: several prompts on one frame) are one frame, and
two frames are consecutive when both have poses and :func:`scenes.talk2radar.poses.consecutive` holds (a
sample without a pose file, or a jump to another drive, ends the drive). A single frame is a
drive of length 1.

Only file metadata and pose files are read (never a sidecar, never the points).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from scenes.talk2radar.poses import Pose, consecutive, read_pose
from scenes.talk2radar.root import Talk2RadarRoot


@dataclass(frozen=True)
class DriveFrame:
    """One frame of a drive.

    Attributes:
        positions: Positions in the split's id list of the samples that show it (in order).
        pose: Its pose (None: the sample has no pose file, a drive of its own).
    """

    positions: tuple[int, ...]
    pose: Pose | None

    @property
    def first(self) -> int:
        """The split position that stands for the frame (its first sample)."""
        return self.positions[0]


@dataclass(frozen=True)
class Drive:
    """Consecutive frames of one drive, in time order."""

    frames: tuple[DriveFrame, ...]

    def __len__(self) -> int:
        return len(self.frames)

    def index_of(self, position: int) -> int | None:
        """The frame (0-based) of the sample at split ``position`` (None: not in this drive)."""
        for k, frame in enumerate(self.frames):
            if position in frame.positions:
                return k
        return None


@dataclass(frozen=True)
class Drives:
    """The drives of one split, and which drive holds each split position."""

    drives: tuple[Drive, ...]

    def find(self, position: int) -> tuple[Drive, int] | None:
        """``(drive, frame index)`` of the sample at split ``position``, or None."""
        for drive in self.drives:
            k = drive.index_of(position)
            if k is not None:
                return drive, k
        return None

    @property
    def longest(self) -> int:
        """Frames of the longest drive (0 for an empty split)."""
        return max((len(d) for d in self.drives), default=0)


def find_drives(root: Talk2RadarRoot, ids: Sequence[str]) -> Drives:
    """The drives of the samples ``ids`` (a split's list, in order; see the module docstring).

    Raises:
        scenes.frame.RootError: a pose file is malformed, or a sample's sensor files are missing.
    """
    drives: list[Drive] = []
    frames: list[DriveFrame] = []
    last_key: object = None
    for position, sid in enumerate(ids):
        key = root.frame_key(sid)
        if frames and key == last_key:
            head = frames[-1]
            frames[-1] = DriveFrame((*head.positions, position), head.pose)
            continue
        last_key = key
        pose = read_pose(root.lidar_dir, sid)
        previous = frames[-1].pose if frames else None
        if frames and (pose is None or previous is None or not consecutive(previous, pose)):
            drives.append(Drive(tuple(frames)))
            frames = []
        frames.append(DriveFrame((position,), pose))
    if frames:
        drives.append(Drive(tuple(frames)))
    return Drives(tuple(drives))
