"""The labelled boxes of a frame, as the Annotate tab uses them (:class:`Labelled`).

Where the app has labelled boxes and a referent-path model
(:attr:`app.session.SessionOptions.labelled_boxes`: a View-of-Delft root served directly, or
``launch.py --scene-labels VOD_ROOT``), the frame's labelled boxes of the metric classes are the
Annotate tab's ready-made boxes and the candidates the referent stage picks a sentence's referents
among (:mod:`app.annotate_tab.referents`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.session import SessionOptions
from scenes.frame import Sample
from scenes.geometry.boxes import wrap_yaw

MATCH = 1e-6
"""Largest difference (m, rad) between a draft box and a labelled box that is the same box."""


@dataclass(frozen=True)
class Labelled:
    """The labelled boxes of a frame: ``boxes (L, 7)`` LiDAR frame, their class names."""

    boxes: np.ndarray
    classes: tuple[str, ...]

    def index_of(self, box: np.ndarray | tuple[float, ...]) -> int | None:
        """The labelled box equal to ``box`` (None: a box of the annotator's own)."""
        if not len(self.boxes):
            return None
        diff = np.abs(self.boxes - np.asarray(box, dtype=np.float64).reshape(1, 7))
        diff[:, 6] = np.abs(wrap_yaw(diff[:, 6]))  # -pi and pi are one heading
        diff = diff.max(axis=1)
        best = int(np.argmin(diff))
        return best if diff[best] <= MATCH else None


def frame_labelled(options: SessionOptions, sample: Sample) -> Labelled | None:
    """The labelled boxes of ``sample``'s frame the referent stage can choose among (None: the
    app has no labelled boxes, or no referent model, or the frame has none).

    Raises:
        scenes.frame.RootError, scenes.frame.kitti.LabelError: a missing or malformed label file.
    """
    source = options.labelled_boxes
    if source is None:
        return None
    found = source(sample)
    if found is None or not len(found):
        return None
    boxes = np.asarray(found.boxes, dtype=np.float64).reshape(-1, 7)  # type: ignore[attr-defined]
    names = found.classes.names  # type: ignore[attr-defined]
    classes = tuple(names[int(i)] for i in found.labels)  # type: ignore[attr-defined]
    return Labelled(boxes, classes)
