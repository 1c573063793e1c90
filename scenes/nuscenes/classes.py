"""nuScenes' 23 categories and 8 attributes, and their mapping onto a class set.

The mapping itself is a fact of each class (:attr:`scenes.geometry.classes.ObjectClass.
categories`, the one home); :func:`model_class` applies a set's (default ``vod``: ``Car``,
``Pedestrian``, ``Cyclist``; ``nuscenes``: the 10 detection classes by nuScenes' own mapping) and
:data:`CATEGORY_CLASS` is ``vod``'s table. ``vehicle.bicycle`` is a VoD ``Cyclist`` only with the
attribute ``cycle.with_rider``: a parked bicycle is not a road user the Talk2Radar classes name
(a nuScenes ``bicycle`` it is). Objects outside the class set are reported by the readers
(counts and reasons), never silently dropped.
"""

from __future__ import annotations

from collections.abc import Sequence

from scenes.geometry.classes import PRESETS, VOD, ClassSet
from scenes.geometry.classes import WITH_RIDER as _WITH_RIDER

__all__ = [
    "ATTRIBUTES",
    "CATEGORIES",
    "CATEGORY_CLASS",
    "CLASS_CATEGORY",
    "WITH_RIDER",
    "category_classes",
    "model_class",
]

CATEGORIES: tuple[str, ...] = (
    "animal",
    "human.pedestrian.adult",
    "human.pedestrian.child",
    "human.pedestrian.construction_worker",
    "human.pedestrian.personal_mobility",
    "human.pedestrian.police_officer",
    "human.pedestrian.stroller",
    "human.pedestrian.wheelchair",
    "movable_object.barrier",
    "movable_object.debris",
    "movable_object.pushable_pullable",
    "movable_object.trafficcone",
    "static_object.bicycle_rack",
    "vehicle.bicycle",
    "vehicle.bus.bendy",
    "vehicle.bus.rigid",
    "vehicle.car",
    "vehicle.construction",
    "vehicle.emergency.ambulance",
    "vehicle.emergency.police",
    "vehicle.motorcycle",
    "vehicle.trailer",
    "vehicle.truck",
)
"""The 23 annotation categories of nuScenes v1.0, sorted."""

ATTRIBUTES: tuple[str, ...] = (
    "vehicle.moving",
    "vehicle.stopped",
    "vehicle.parked",
    "cycle.with_rider",
    "cycle.without_rider",
    "pedestrian.moving",
    "pedestrian.standing",
    "pedestrian.sitting_lying_down",
)
"""The 8 attributes of nuScenes v1.0."""

WITH_RIDER = _WITH_RIDER
"""The attribute that makes a ``vehicle.bicycle`` a VoD Cyclist."""


def category_classes(classes: ClassSet = VOD) -> dict[str, str | None]:
    """Category -> class of ``classes`` (None outside the set), by the set's own mapping
    (:attr:`scenes.geometry.classes.ObjectClass.categories`; a ``vod`` Cyclist also needs
    :data:`WITH_RIDER`: see :func:`model_class`)."""
    out: dict[str, str | None] = dict.fromkeys(CATEGORIES, None)
    for c in classes.classes:
        out.update(dict.fromkeys(c.categories, c.name))
    return out


CATEGORY_CLASS: dict[str, str | None] = category_classes(VOD)
"""Category -> ``vod`` class (``vehicle.bicycle`` only with :data:`WITH_RIDER`: see
:func:`model_class`), None outside the class set."""

CLASS_CATEGORY: dict[str, str] = {
    c.name: c.categories[0] for s in PRESETS.values() for c in s.classes if c.categories
}
"""Class (of any class set) -> the category a writer gives it (its first; a ``vod`` Cyclist also
gets :data:`WITH_RIDER`)."""

if set(CATEGORY_CLASS.values()) - {None} != set(VOD.names) or not set(CATEGORIES) >= {
    cat for s in PRESETS.values() for c in s.classes for cat in c.categories
}:
    raise ImportError("scenes.geometry.classes maps categories this module does not list")
if not set(ATTRIBUTES) >= {a for s in PRESETS.values() for c in s.classes for a in c.attributes}:
    raise ImportError("scenes.geometry.classes gives attributes this module does not list")


def model_class(
    category: str, attributes: Sequence[str] = (), classes: ClassSet = VOD
) -> str | None:
    """The class of ``classes`` (the model's; default ``vod``) of a nuScenes object, or None
    when it is outside the set (:meth:`scenes.geometry.classes.ClassSet.category_class`).

    Args:
        category: A category name (``vehicle.car``; unknown names give None).
        attributes: The annotation's attribute names (``cycle.with_rider``, ...).
        classes: The class set.
    """
    return classes.category_class(category, attributes)
