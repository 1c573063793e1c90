"""What a frame's labels say is there: :class:`FrameObjects`, and which of them an answer's box
overlaps (:class:`Overlap`).

The *Ground truth* toggle and the answer table compare an answer with **every labelled object of
the frame**, not only with the referents of the frame's own prompt, so that a prompt of one's own
("all pedestrians on the right") can be checked against what the frame holds. Where the objects
come from, in this order (:func:`frame_objects`):

1. the frame's full labels, where the app has them (:class:`app.serving.labelled.LabelledFrames`: a
   View-of-Delft release served directly, or ``launch.py --scene-labels VOD_ROOT``);
2. the sidecar's actors (a synthetic root: every road user of the world, with its class);
3. the referents of the frame's prompt (``label_2`` of a Talk2Radar root without either): the only
   objects labelled there.

A frame with none of them has no labelled objects (:attr:`FrameObjects.empty`): the answer table
then has no overlap column at all (rather than a column of zeros). The objects are numbered from
the nearest (``#1``) in the 3D view's labels and in the table, and each one says whether it is a
referent of the frame's prompt (matched by 3D IoU, :data:`REFERENT_IOU`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from scenes.frame import Sample
from scenes.geometry.boxes import iou3d

log = logging.getLogger(__name__)

REFERENT_IOU = 0.5
"""3D IoU at which a referent of the frame's prompt is taken to be a labelled object."""

LABELS, SIDECAR, REFERENTS = "labels", "sidecar", "referents"
"""Where a frame's objects came from (:attr:`FrameObjects.source`)."""


@dataclass(frozen=True)
class Overlap:
    """The labelled object an answer's box overlaps most.

    Attributes:
        number: The object's number (1-based, nearest first), as its label in the 3D view.
        cls: Its class.
        iou: The 3D IoU of the box with it, in ``(0, 1]``.
        referent: Whether it is a referent of the frame's own prompt.
    """

    number: int
    cls: str
    iou: float
    referent: bool

    def text(self) -> str:
        """The answer table's cell: ``"#3 Car, IoU 0.71"`` (``" (referent)"`` appended for a
        referent of the frame's prompt)."""
        tail = " (referent)" if self.referent else ""
        return f"#{self.number} {self.cls}, IoU {self.iou:.2f}{tail}"


@dataclass(frozen=True)
class FrameObjects:
    """The labelled objects of one frame (see the module docstring).

    Attributes:
        boxes: ``(G, 7)`` float64 LiDAR frame, nearest to the sensor first.
        classes: ``G`` class names.
        referent: ``G`` flags: the object is a referent of the frame's prompt.
        source: :data:`LABELS`, :data:`SIDECAR` or :data:`REFERENTS` (empty: none).
    """

    boxes: np.ndarray
    classes: tuple[str, ...]
    referent: tuple[bool, ...]
    source: str = ""

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 7)
        if not len(boxes) == len(self.classes) == len(self.referent):
            raise ValueError(
                f"FrameObjects: {len(boxes)} boxes, {len(self.classes)} classes, "
                f"{len(self.referent)} referent flags"
            )
        object.__setattr__(self, "boxes", boxes)

    def __len__(self) -> int:
        return len(self.boxes)

    @property
    def empty(self) -> bool:
        """Whether the frame has no labelled object (the answer table has no overlap column)."""
        return len(self.boxes) == 0

    def labels(self) -> list[str]:
        """The 3D view's label of each object: ``"#1 Car"``, ``"#2 Pedestrian (referent)"``."""
        return [
            f"#{i + 1} {cls}" + (" (referent)" if ref else "")
            for i, (cls, ref) in enumerate(zip(self.classes, self.referent, strict=True))
        ]

    def overlaps(self, boxes: np.ndarray) -> tuple[Overlap | None, ...]:
        """For each of ``boxes`` ``(K, 7)`` the labelled object it overlaps most (None: it
        overlaps none, or the frame has no objects)."""
        b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
        if not len(b) or self.empty:
            return tuple(None for _ in range(len(b)))
        ious = np.asarray(iou3d(b, self.boxes))
        out: list[Overlap | None] = []
        for row in ious:
            best = int(np.argmax(row))
            iou = float(row[best])
            out.append(
                Overlap(best + 1, self.classes[best], iou, self.referent[best]) if iou > 0 else None
            )
        return tuple(out)

    def best_ious(self, boxes: np.ndarray) -> np.ndarray:
        """``(K,)`` each box's best 3D IoU with an object (NaN for every box without objects)."""
        overlaps = self.overlaps(boxes)
        if self.empty:
            return np.full(len(overlaps), np.nan)
        return np.array([o.iou if o is not None else 0.0 for o in overlaps], dtype=np.float64)


NO_OBJECTS = FrameObjects(np.zeros((0, 7)), (), ())
"""A frame without labelled objects."""


def labelled_objects(
    boxes: np.ndarray,
    classes: Sequence[str],
    referents: np.ndarray,
    referent_classes: Sequence[str],
    source: str,
) -> FrameObjects:
    """The objects ``boxes`` / ``classes`` with the referents of the prompt marked, nearest first;
    a referent that matches no object (by :data:`REFERENT_IOU`) is added as an object itself, so
    that nothing the prompt refers to goes unshown."""
    objs = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    names = list(classes)
    refs = np.asarray(referents, dtype=np.float64).reshape(-1, 7)
    flags = [False] * len(objs)
    extra: list[int] = []
    if len(refs):
        ious = np.asarray(iou3d(refs, objs)) if len(objs) else np.zeros((len(refs), 0))
        for r in range(len(refs)):
            best = int(np.argmax(ious[r])) if ious.shape[1] else -1
            if best >= 0 and ious[r, best] >= REFERENT_IOU:
                flags[best] = True
            else:
                extra.append(r)
    objs = np.concatenate([objs, refs[extra]]) if extra else objs
    names += [referent_classes[r] for r in extra]
    flags += [True] * len(extra)
    order = np.argsort(np.hypot(objs[:, 0], objs[:, 1]), kind="stable")
    return FrameObjects(
        objs[order],
        tuple(names[i] for i in order),
        tuple(flags[i] for i in order),
        source if len(objs) else "",
    )


def frame_objects(
    sample: Sample, labelled: Callable[[Sample], object | None] | None = None
) -> FrameObjects:
    """The labelled objects of ``sample``'s frame (see the module docstring for the sources).

    Args:
        sample: The frame.
        labelled: The frame's full labels (:meth:`app.serving.labelled.LabelledFrames.boxes`, a
            ``model.LabelledBoxes`` or None), or None where the app has none. A label file that
            cannot be read is logged and the next source used.
    """
    label_2 = np.asarray(sample.boxes, dtype=np.float64).reshape(-1, 7), tuple(sample.classes)
    no_prompt = sample.prompt is None  # a release as it comes: label_2 lists every object
    refs, ref_classes = (np.zeros((0, 7)), ()) if no_prompt else label_2
    if labelled is not None:
        try:
            found = labelled(sample)
        except Exception as exc:  # a malformed label file: the frame is still shown
            log.error("labelled objects of sample %s: %s", sample.sample_id, exc)
            found = None
        if found is not None:
            names = found.classes.names  # type: ignore[attr-defined]
            classes = [names[int(i)] for i in found.labels]  # type: ignore[attr-defined]
            return labelled_objects(found.boxes, classes, refs, ref_classes, LABELS)  # type: ignore[attr-defined]
    meta = sample.meta
    if meta is not None and meta.actors:
        boxes = np.array([a.box for a in meta.actors], dtype=np.float64)
        classes = [a.cls for a in meta.actors]
        return labelled_objects(boxes, classes, refs, ref_classes, SIDECAR)
    if no_prompt:
        return labelled_objects(*label_2, refs, ref_classes, LABELS)
    return labelled_objects(np.zeros((0, 7)), [], refs, ref_classes, REFERENTS)


__all__ = [
    "NO_OBJECTS",
    "FrameObjects",
    "Overlap",
    "frame_objects",
    "labelled_objects",
]
