"""What every dataset family's reader offers: :class:`FrameSource`."""

from __future__ import annotations

from pathlib import Path
from typing import Protocol, runtime_checkable

from scenes.frame.sample import Sample

__all__ = ["FrameSource"]


@runtime_checkable
class FrameSource(Protocol):
    """The frames of one root, as training, evaluation, the app and the annotation tools read
    them (a Talk2Radar / View-of-Delft root: :class:`scenes.talk2radar.root.Talk2RadarRoot`; a
    nuScenes root with its Talk2Car commands: :class:`scenes.nuscenes.source.NuScenesSource`).

    A third family is one package whose reader has these members, and one line of
    :func:`scenes.datasets.source.open_source`.
    """

    path: Path
    """The root folder."""
    has_prompts: bool
    """Whether the root's samples carry their own prompts (a Talk2Radar root's ``prompt/``)."""

    def splits(self) -> list[str]:
        """The split names, in order."""

    def ids(self, split: str) -> list[str]:
        """The sample ids of ``split``, in order.

        Raises:
            RootError: an unknown split, or a malformed split list (names the file).
        """

    def load(self, sample_id: str) -> Sample:
        """One sample: points in the LiDAR frame, labelled boxes of the reader's class set.

        Raises:
            RootError: a missing or malformed file of the sample (names it).
        """

    def frame_key(self, sample_id: str) -> tuple[object, ...]:
        """The identity of a sample's frame: samples with equal keys share their sensors."""
