"""What View-of-Delft labels in a frame, applied to a synthetic frame: its class names for the
synthetic world's objects, its annotated area, and the ``label_2`` lines of a frame.

View-of-Delft (its devkit's ``docs/ANNOTATION.md``) annotates every object of its 13 classes
within 50 m of the LiDAR that is partly or fully inside the camera's field of view, in KITTI
format in the camera frame; the 2D box is computed from the 3D box; the ``truncated`` field is
not used (written ``0`` here); ``occluded`` is 0, 1 or 2 (``0`` here: the generator does not
measure occlusion); every line ends with a 16th field, the score ``1``.

The synthetic world's objects and the VoD class each is labelled as (:data:`CLUTTER_CLASSES`):

=================================  ========================================================
synthetic object                   VoD label
=================================  ========================================================
actor ``Car``, ``Pedestrian``      ``Car``, ``Pedestrian``
actor ``Cyclist``                  ``Cyclist`` (bicycle and rider in one box) and ``rider``
                                   (the person on it, also labelled on its own by VoD:
                                   :func:`scenes.synth.world.rider_boxes`)
clutter: parked bicycle            ``bicycle`` (VoD's "unused bicycle")
clutter: bicycle rack              ``bicycle_rack``
clutter: parked moped or scooter   ``moped_scooter``
buildings, walls, hedges, street   not labelled (not VoD classes)
lights, signs, bollards, trees
=================================  ========================================================

VoD's other classes (:data:`ABSENT_CLASSES`: ``motor``, ``truck``, ``ride_other``,
``vehicle_other``, ``human_depiction``, ``ride_uncertain``) have no object in the synthetic world,
so they are never written; nor is ``DontCare``, which VoD does not use. An actor no sensor sees
(the sidecar's ``extra["unsensed_actor_ids"]``) is not labelled: annotators label what the point
clouds and the image show.

A root of another class set (``python -m scenes.synth --classes nuscenes``) labels its actors
with that set's names as :mod:`scenes.geometry.classes` writes them (``Truck``, ``Bus``,
``Motorcycle``, ``Bicycle`` with its rider in the box, ``TrafficCone``, ...), not with VoD's
names; its parked bicycles and mopeds are such actors, so only bicycle racks stay clutter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.frame.kitti import ObjectLabel, boxes_to_labels
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.actors import CLASSES
from scenes.geometry.calib import IMAGE_SIZE, Calibration
from scenes.geometry.projection import in_annotated_area
from scenes.synth.world.actor_meshes import rider_boxes

RIDER = "rider"
"""VoD's class of the person riding a bicycle (or a moped, a motorbike), labelled on its own too."""
CLUTTER_CLASSES = {
    "bicycle": "bicycle",
    "bicycle_rack": "bicycle_rack",
    "moped_scooter": "moped_scooter",
}
"""VoD class of each kind of street clutter (:class:`scenes.synth.world.Clutter`)."""
ABSENT_CLASSES = (
    "motor",
    "truck",
    "ride_other",
    "vehicle_other",
    "human_depiction",
    "ride_uncertain",
)
"""VoD classes of which the synthetic world has no object (never written)."""
VOD_CLASSES = (*CLASSES, RIDER, *CLUTTER_CLASSES.values(), *ABSENT_CLASSES)
"""View-of-Delft's 13 classes."""


@dataclass(frozen=True)
class VodObjects:
    """The objects of a frame that VoD labels wherever they are, LiDAR frame.

    Attributes:
        boxes: ``(K, 7)`` ``x, y, z, l, w, h, yaw`` (z at the geometric centre).
        names: ``K`` VoD class names.
    """

    boxes: np.ndarray
    names: tuple[str, ...]


def frame_objects(meta: SampleMeta, source: str = "<meta>") -> VodObjects:
    """Every object of a synthetic frame that VoD would label, wherever it is, with its VoD class
    name (see the module docstring), from the frame's sidecar.

    Raises:
        ValueError: a clutter entry of a kind without a VoD class, or a malformed box (names
            ``source``).
    """
    unsensed = {int(i) for i in meta.extra.get("unsensed_actor_ids", [])}
    actors = [a for a in meta.actors if a.actor_id not in unsensed]
    boxes = [a.box for a in actors]
    names = [a.cls for a in actors]
    cyclists = np.array([a.box for a in actors if a.cls == "Cyclist"]).reshape(-1, 7)
    boxes += list(rider_boxes(cyclists))
    names += [RIDER] * len(cyclists)
    for k, item in enumerate(meta.extra.get("clutter", [])):
        kind = str(item.get("cls")) if isinstance(item, dict) else None
        if kind not in CLUTTER_CLASSES:
            raise ValueError(
                f"{source}: clutter {k} is a {kind!r}, which has no View-of-Delft class "
                f"(known: {', '.join(CLUTTER_CLASSES)})"
            )
        box = np.asarray(item["box"], dtype=np.float64)
        if box.shape != (7,) or not np.all(np.isfinite(box)) or np.any(box[3:6] <= 0):
            raise ValueError(f"{source}: clutter {k} has a malformed box {item['box']!r}")
        boxes.append(box)
        names.append(CLUTTER_CLASSES[kind])
    return VodObjects(
        boxes=np.array(boxes, dtype=np.float64).reshape(-1, 7),
        names=tuple(names),
    )


def frame_labels(
    objects: VodObjects, calib: Calibration, image_size: tuple[int, int] = IMAGE_SIZE
) -> list[ObjectLabel]:
    """The ``label_2`` lines VoD would write for ``objects``: those in its annotated area
    (:func:`in_annotated_area`; a rider at the image's edge may be out of it while its cyclist is
    in), in order, as ground truth (``truncated = occluded = 0``, score 1) with 2D boxes clipped
    to ``image_size``."""
    kept = in_annotated_area(objects.boxes, calib, image_size)
    names = [n for n, k in zip(objects.names, kept, strict=True) if k]
    return boxes_to_labels(objects.boxes[kept], names, calib, image_size=image_size)


__all__ = [
    "ABSENT_CLASSES",
    "CLUTTER_CLASSES",
    "RIDER",
    "VOD_CLASSES",
    "VodObjects",
    "frame_labels",
    "frame_objects",
]
