"""The labelled boxes of the served frames, where the root has them ("candidates: labelled boxes").

A View-of-Delft release opened directly has every object of a frame in its own ``label_2``; a
Talk2Radar root (whose ``label_2`` lists only a prompt's referents) has them when the app is given
the release it was made from (``launch.py --scene-labels VOD_ROOT``). With them, the referent stage
can choose among the boxes already drawn instead of the detector's proposals: grounding apart from
detection, and the fastest way to make a pair on a labelled frame.

Family specifics: a View-of-Delft release's full labels are read by
:class:`scenes.talk2radar.scene_labels.SceneLabels`, the Talk2Radar family's (``--scene-labels``
names such a release; no other family has one), imported from its room for that.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from model import LabelledBoxes
from scenes.frame import FrameSource, Sample
from scenes.geometry.classes import VOD, ClassSet
from scenes.talk2radar.scene_labels import SceneLabels


class LabelledFrames:
    """Where the labelled boxes of a frame come from.

    Args:
        root: The served root.
        scene_labels: A View-of-Delft root with the frames' full labels, or None: then a root
            without prompts (a release opened directly) is its own, and a Talk2Radar root has none.
        classes: The served model's class set: the labelled boxes are its classes' (the root
            is read into the same set).
    """

    def __init__(
        self,
        root: FrameSource,
        scene_labels: str | Path | None = None,
        classes: ClassSet = VOD,
    ) -> None:
        self.own = scene_labels is None and not root.has_prompts
        self.classes = classes
        self.labels = SceneLabels(scene_labels, classes) if scene_labels is not None else None

    @property
    def available(self) -> bool:
        """Whether frames have labelled boxes to choose among."""
        return self.own or self.labels is not None

    def source(self) -> Callable[[Sample], LabelledBoxes | None] | None:
        """:meth:`boxes` where frames have labelled boxes (:attr:`available`), else None."""
        return self.boxes if self.available else None

    def boxes(self, sample: Sample) -> LabelledBoxes | None:
        """The labelled boxes of ``sample``'s frame of the served model's classes (None: none
        known).

        Raises:
            scenes.frame.RootError, scenes.frame.kitti.LabelError: a missing or malformed label file.
        """
        if self.labels is not None:
            if not self.labels.has(sample.sample_id):
                return None
            return LabelledBoxes(*self.labels.load(sample.sample_id).metric(), self.classes)
        if self.own:
            names = self.classes.names
            labels = np.array([names.index(c) for c in sample.classes], dtype=np.int64)
            return LabelledBoxes(sample.boxes, labels, self.classes)
        return None


__all__ = ["LabelledFrames"]
