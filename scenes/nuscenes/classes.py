"""nuScenes' 23 categories and the model's classes: the one place the mapping lives.

:data:`CATEGORY_CLASS` maps each category to one of :data:`scenes.geometry.actors.CLASSES`
(``Car``, ``Pedestrian``, ``Cyclist``) or to None (outside the class set). ``vehicle.bicycle`` is a
``Cyclist`` only with the attribute ``cycle.with_rider`` (:func:`model_class`): a parked bicycle
is not a road user the Talk2Radar classes name. Objects outside the class set are reported by
the readers (counts and reasons), never silently dropped. A later issue makes the class set
configurable (nuScenes' 10 detection classes); this mapping stays here.
"""

from __future__ import annotations

from collections.abc import Sequence

from scenes.geometry.actors import CLASSES

__all__ = [
    "ATTRIBUTES",
    "CATEGORIES",
    "CATEGORY_CLASS",
    "CLASS_CATEGORY",
    "WITH_RIDER",
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

WITH_RIDER = "cycle.with_rider"
"""The attribute that makes a ``vehicle.bicycle`` a Cyclist."""

CATEGORY_CLASS: dict[str, str | None] = {
    **dict.fromkeys(CATEGORIES, None),
    "vehicle.car": "Car",
    "human.pedestrian.adult": "Pedestrian",
    "human.pedestrian.child": "Pedestrian",
    "human.pedestrian.construction_worker": "Pedestrian",
    "human.pedestrian.police_officer": "Pedestrian",
    "vehicle.bicycle": "Cyclist",
}
"""Category -> model class (``vehicle.bicycle`` only with :data:`WITH_RIDER`: see
:func:`model_class`), None outside the class set."""

CLASS_CATEGORY: dict[str, str] = {
    "Car": "vehicle.car",
    "Pedestrian": "human.pedestrian.adult",
    "Cyclist": "vehicle.bicycle",
}
"""Model class -> the category a writer gives it (a Cyclist also gets :data:`WITH_RIDER`)."""

assert set(CLASS_CATEGORY) == set(CLASSES)


def model_class(category: str, attributes: Sequence[str] = ()) -> str | None:
    """The model class of a nuScenes object, or None when it is outside the class set.

    Args:
        category: A category name (``vehicle.car``; unknown names give None).
        attributes: The annotation's attribute names (``cycle.with_rider``, ...).
    """
    cls = CATEGORY_CLASS.get(category)
    if cls == "Cyclist" and WITH_RIDER not in attributes:
        return None
    return cls
