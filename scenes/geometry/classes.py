"""Class sets: which road users a model knows, as configuration. The one home of class facts.

A :class:`ClassSet` is an ordered tuple of :class:`ObjectClass`; its order is the order of the
detector's heatmap channels. Two presets exist:

- ``vod`` (:data:`VOD`): ``Car``, ``Pedestrian``, ``Cyclist``, the Talk2Radar / View-of-Delft
  metric classes (the shipped ``checkpoints/tpcnet-small.pt``);
- ``nuscenes`` (:data:`NUSCENES`): nuScenes' 10 detection classes, in the order of the nuScenes
  detection benchmark's configuration (car, truck, bus, trailer, construction_vehicle, pedestrian,
  motorcycle, bicycle, traffic_cone, barrier). Names are single tokens (they are written into
  KITTI-style label files, whose fields are separated by spaces).

Facts per class (:class:`ObjectClass`): the name (model, label files, tables), the words a person
uses for it (the answer words of the app), the mean size ``(l, w, h)`` in metres, the evaluator's
minimum overlaps and KITTI's neighbouring label, the centre distances of a match (training's and
the class-prompt evaluation's), the legend colour, whether it has a heading, and the label names
and nuScenes categories that map onto it, and the per-class numbers of the tools that treat
classes differently (a box fit's minimum footprint, self-training's pseudo-label thresholds,
Talk2Car's overlaps and top-1 distance). The size statistics of the nuScenes
classes are the training-set means nuScenes-based detectors publish as anchor sizes; those of the
three VoD classes are the ones this project's synthetic world draws around. The detector has no
size prior (it regresses ``log l, log w, log h`` directly), so the mean size is the synthetic
world's, the documentation's and the typical size of a box an annotator places or fits. Each
fact has one home, here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

__all__ = [
    "ALL_CLASSES",
    "MATCH_DISTANCE",
    "NUSCENES",
    "PRESETS",
    "VOD",
    "WITH_RIDER",
    "ClassSet",
    "ObjectClass",
    "beyond_vod",
    "class_set",
    "object_class",
]


@dataclass(frozen=True)
class ObjectClass:
    """One class a model can detect and a prompt can name.

    Attributes:
        name: The class name: one token, as the model, label files and tables write it.
        noun: The singular word for it in an answer ("construction vehicle").
        plural: The plural word ("construction vehicles").
        mean_size: ``(l, w, h)`` mean box size in metres.
        min_overlaps: The evaluator's minimum overlaps ``(image 2D, BEV, 3D)`` of a match (a match
            needs strictly more). The VoD / KITTI table has three rows; the other classes take the
            row of the class they are scored like (``scored_as``): large vehicles (truck, bus,
            trailer, construction vehicle) as Car ``(0.7, 0.5, 0.5)``, two-wheelers (motorcycle,
            bicycle) as Cyclist and small objects (traffic cone, barrier) as Pedestrian
            ``(0.5, 0.25, 0.25)``.
        match_distance: Metres within which a detection's BEV centre is this class's actor
            (training's candidate matching, the language suite's scoring).
        color: ``(r, g, b)`` of the app's legend, boxes and heatmap channel. The colours of a
            set are told apart by a reader with normal vision, deuteranopia or protanopia
            (CIEDE2000 at least 20 / 10 between any two, and from the app's referent green:
            ``tests/app/test_class_colors.py``, :mod:`app.view.color_vision`).
        heading: Whether the class has a heading: False for a rotationally symmetric object
            (a traffic cone), whose yaw target is 0 and whose decoded yaw is 0.
        label_names: Lower-case label-file names (KITTI / View-of-Delft) that map onto the class;
            its own name (lower case) always does.
        categories: nuScenes categories that map onto the class, by nuScenes' own detection
            mapping; the first is the one a writer gives it.
        with_rider_only: A ``vehicle.bicycle`` maps onto the class only with the attribute
            ``cycle.with_rider`` (the VoD Cyclist: a parked bicycle is not one).
        find_radius: BEV centre distance (m) within which the class-prompt evaluation's loose
            rule counts a box as finding an object of the class (``model.class_prompts``).
        neighbour: KITTI's neighbouring label name (lower case) the evaluator ignores rather than
            counts as missed for this class (``van`` for a car, ``person_sitting`` for a
            pedestrian), or None.
        scored_as: The View-of-Delft class whose thresholds a metric defined for those three
            classes only applies to this one (its ``min_overlaps`` are that class's: checked
            below; Talk2Car's AP and top-1, :mod:`model.evaluation.talk2car.metrics`); empty:
            the class itself (one of the three).
        attributes: The nuScenes attribute a writer gives an object of the class, ``(moving,
            still)`` by nuScenes' conventions (``vehicle.moving`` / ``vehicle.parked``,
            ``pedestrian.moving`` / ``pedestrian.standing``, ``cycle.with_rider`` /
            ``cycle.without_rider``: a still two-wheeler counts as parked, a VoD Cyclist is
            ridden by definition); empty: the class takes none (traffic cones, barriers).
        min_footprint: The plausible minimum ``(length, width)`` in metres of the class's box
            seen from above, below which a box fit with the class completes the hidden part
            (:mod:`annotate.fitting`, ``FitConfig.class_min_sizes``), or None (no completion).
            Car 3.5 x 1.5 (a small city car; synthetic cars are 3.5-5.0 x 1.6-2.0), Pedestrian
            0.4 x 0.4 (a child's footprint), Cyclist 1.5 x 0.5 (a bicycle, a rider's shoulders).
        pseudo_thresholds: The positive score threshold of a pseudo-label of the class in the
            first and in the last self-training round (:mod:`model.adapt`), or None (the run's
            ``--threshold-start`` / ``--threshold-end``).
        talk2car_overlaps: MSSG's IoU thresholds ``(AP_A, AP_B)`` of a Talk2Car referent of the
            class (:mod:`model.evaluation.talk2car.metrics`: KITTI's moderate and loose
            overlaps), on the classes the metric is defined for (those every class is
            ``scored_as``); None on the others.
        top1_distance: Talk2Car's top-1: the largest BEV centre distance (m) of the best box from
            a referent of the class, on the same classes; None on the others.
    """

    name: str
    noun: str
    plural: str
    mean_size: tuple[float, float, float]
    min_overlaps: tuple[float, float, float]
    match_distance: float
    color: tuple[int, int, int]
    heading: bool = True
    label_names: tuple[str, ...] = ()
    categories: tuple[str, ...] = ()
    with_rider_only: bool = False
    find_radius: float = 1.0
    neighbour: str | None = None
    scored_as: str = ""
    attributes: tuple[str, str] | tuple[()] = ()
    min_footprint: tuple[float, float] | None = None
    pseudo_thresholds: tuple[float, float] | None = None
    talk2car_overlaps: tuple[float, float] | None = None
    top1_distance: float | None = None

    def __post_init__(self) -> None:
        if not self.scored_as:
            object.__setattr__(self, "scored_as", self.name)
        if not self.name or any(c.isspace() for c in self.name):
            raise ValueError(f"class name {self.name!r} must be one non-empty token")
        if len(self.mean_size) != 3 or min(self.mean_size) <= 0:
            raise ValueError(f"class {self.name}: mean_size must be 3 positive lengths")
        if len(self.min_overlaps) != 3 or not all(0 <= m < 1 for m in self.min_overlaps):
            raise ValueError(f"class {self.name}: min_overlaps must be 3 values in [0, 1)")
        if len(self.color) != 3 or not all(0 <= c <= 255 for c in self.color):
            raise ValueError(f"class {self.name}: color must be 3 values in [0, 255]")
        if self.match_distance <= 0:
            raise ValueError(f"class {self.name}: match_distance must be positive")
        if len(self.attributes) not in (0, 2):
            raise ValueError(f"class {self.name}: attributes must be (moving, still) or empty")
        if self.min_footprint is not None and (
            len(self.min_footprint) != 2 or min(self.min_footprint) <= 0
        ):
            raise ValueError(f"class {self.name}: min_footprint must be 2 positive lengths")
        for what, pair in (
            ("pseudo_thresholds", self.pseudo_thresholds),
            ("talk2car_overlaps", self.talk2car_overlaps),
        ):
            if pair is not None and (len(pair) != 2 or not all(0 < v < 1 for v in pair)):
                raise ValueError(f"class {self.name}: {what} must be 2 values in (0, 1)")
        if self.top1_distance is not None and not self.top1_distance > 0:
            raise ValueError(f"class {self.name}: top1_distance must be positive")
        object.__setattr__(
            self, "label_names", tuple(dict.fromkeys((self.name.lower(), *self.label_names)))
        )


@dataclass(frozen=True)
class ClassSet:
    """An ordered set of classes; index ``k`` is heatmap channel ``k``.

    Attributes:
        name: The preset's name (``vod``, ``nuscenes``): what configs and checkpoints store.
        classes: The classes, in channel order.
    """

    name: str
    classes: tuple[ObjectClass, ...]

    def __post_init__(self) -> None:
        names = [c.name for c in self.classes]
        if not names or len(set(names)) != len(names):
            raise ValueError(f"class set {self.name!r}: names must be unique and non-empty")
        seen: dict[str, str] = {}
        for c in self.classes:
            for key in (*c.label_names, *c.categories):
                if seen.setdefault(key, c.name) != c.name:
                    raise ValueError(
                        f"class set {self.name!r}: {key!r} maps onto {seen[key]} and {c.name}"
                    )

    @property
    def names(self) -> tuple[str, ...]:
        """The class names in channel order."""
        return tuple(c.name for c in self.classes)

    @property
    def match_distances(self) -> tuple[float, ...]:
        """:attr:`ObjectClass.match_distance` in channel order (metres)."""
        return tuple(c.match_distance for c in self.classes)

    @property
    def plurals(self) -> tuple[str, ...]:
        """The plural words in channel order ("cars", "pedestrians", "cyclists")."""
        return tuple(c.plural for c in self.classes)

    def __len__(self) -> int:
        return len(self.classes)

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def index(self, name: str) -> int:
        """The channel of class ``name``; ValueError naming the set when it has no such class."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(
                f"class {name!r} is not in the {self.name!r} class set {self.names}"
            ) from None

    def get(self, name: str) -> ObjectClass:
        """The :class:`ObjectClass` called ``name`` (ValueError when absent)."""
        return self.classes[self.index(name)]

    @cached_property
    def _by_label(self) -> dict[str, str]:
        """Lower-case label name -> class name (built once; the readers and the evaluator ask
        for every label of every frame)."""
        return {n: c.name for c in self.classes for n in c.label_names}

    def label_class(self, label_name: str) -> str | None:
        """The class a label file's name (KITTI / View-of-Delft spelling, any case) maps onto,
        or None when it is outside the set (``rider``, ``DontCare``, a typo)."""
        return self._by_label.get(label_name.lower())

    def label_index(self, label_name: str) -> int:
        """The channel of :meth:`label_class` of ``label_name``, or ``-1`` outside the set."""
        cls = self.label_class(label_name)
        return -1 if cls is None else self.names.index(cls)

    def category_class(self, category: str, attributes: Sequence[str] = ()) -> str | None:
        """The class a nuScenes object of ``category`` (with its attribute names) maps onto, or
        None outside the set."""
        for c in self.classes:
            if category in c.categories:
                return None if c.with_rider_only and WITH_RIDER not in attributes else c.name
        return None

    def plural_list(self) -> str:
        """The plurals as prose: "cars, pedestrians and cyclists"."""
        words = self.plurals
        return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


WITH_RIDER = "cycle.with_rider"
"""The nuScenes attribute of a bicycle being ridden (:attr:`ObjectClass.with_rider_only`)."""

_AS_CAR = (0.7, 0.5, 0.5)
_AS_SMALL = (0.5, 0.25, 0.25)
_VEHICLE = ("vehicle.moving", "vehicle.parked")
_WALKING = ("pedestrian.moving", "pedestrian.standing")
_CYCLE = (WITH_RIDER, "cycle.without_rider")
_CAR_RULES = {
    "min_footprint": (3.5, 1.5),
    "pseudo_thresholds": (0.5, 0.35),
    "talk2car_overlaps": (0.7, 0.5),
    "top1_distance": 1.0,
}
"""A car's tool numbers (the same in every preset: a name means one class to these tools)."""
_PEDESTRIAN_RULES = {
    "min_footprint": (0.4, 0.4),
    "pseudo_thresholds": (0.4, 0.3),
    "talk2car_overlaps": (0.5, 0.25),
    "top1_distance": 0.5,
}
"""A pedestrian's tool numbers (as :data:`_CAR_RULES`)."""
_PEDESTRIANS = (
    "human.pedestrian.adult",
    "human.pedestrian.child",
    "human.pedestrian.construction_worker",
    "human.pedestrian.police_officer",
)

VOD = ClassSet(
    "vod",
    (
        ObjectClass(
            "Car", "car", "cars", (4.2, 1.8, 1.6), _AS_CAR, 2.0, (255, 150, 0),
            categories=("vehicle.car",), neighbour="van", find_radius=2.0, attributes=_VEHICLE,
            **_CAR_RULES,
        ),
        ObjectClass(
            "Pedestrian", "pedestrian", "pedestrians", (0.6, 0.6, 1.75), _AS_SMALL, 1.0,
            (255, 70, 170), categories=_PEDESTRIANS, neighbour="person_sitting",
            attributes=_WALKING, **_PEDESTRIAN_RULES,
        ),
        ObjectClass(
            "Cyclist", "cyclist", "cyclists", (1.8, 0.6, 1.7), _AS_SMALL, 1.2, (70, 200, 255),
            categories=("vehicle.bicycle",), with_rider_only=True,
            attributes=(WITH_RIDER, WITH_RIDER), min_footprint=(1.5, 0.5),
            pseudo_thresholds=(0.4, 0.3), talk2car_overlaps=(0.5, 0.25), top1_distance=0.5,
        ),
    ),
)  # fmt: skip
"""The Talk2Radar / View-of-Delft metric classes (label names matched case-insensitively; nuScenes:
cars, the four walking-person categories, ridden bicycles)."""

NUSCENES = ClassSet(
    "nuscenes",
    (
        ObjectClass(
            "Car", "car", "cars", (4.63, 1.97, 1.74), _AS_CAR, 2.0, (255, 150, 0),
            categories=("vehicle.car",), neighbour="van", find_radius=2.0, attributes=_VEHICLE,
            **_CAR_RULES,
        ),
        ObjectClass(
            "Truck", "truck", "trucks", (6.93, 2.51, 2.84), _AS_CAR, 3.0, (240, 120, 105),
            categories=("vehicle.truck",), find_radius=3.0, scored_as="Car",
            attributes=_VEHICLE,
        ),
        ObjectClass(
            "Bus", "bus", "buses", (10.5, 2.94, 3.47), _AS_CAR, 4.0, (0, 255, 255),
            categories=("vehicle.bus.rigid", "vehicle.bus.bendy"), find_radius=4.0,
            scored_as="Car", attributes=_VEHICLE,
        ),
        ObjectClass(
            "Trailer", "trailer", "trailers", (12.29, 2.90, 3.87), _AS_CAR, 4.0, (180, 165, 150),
            categories=("vehicle.trailer",), find_radius=4.0, scored_as="Car",
            attributes=_VEHICLE,
        ),
        ObjectClass(
            "ConstructionVehicle", "construction vehicle", "construction vehicles",
            (6.37, 2.85, 3.19), _AS_CAR, 3.0, (105, 135, 30),
            label_names=("construction_vehicle",), categories=("vehicle.construction",),
            find_radius=3.0, scored_as="Car", attributes=_VEHICLE,
        ),
        ObjectClass(
            "Pedestrian", "pedestrian", "pedestrians", (0.73, 0.67, 1.77), _AS_SMALL, 1.0,
            (255, 70, 170), categories=_PEDESTRIANS, neighbour="person_sitting",
            attributes=_WALKING, **_PEDESTRIAN_RULES,
        ),
        ObjectClass(
            "Motorcycle", "motorcycle", "motorcycles", (2.11, 0.77, 1.47), _AS_SMALL, 1.2,
            (135, 120, 255), label_names=("motor", "moped_scooter"),
            categories=("vehicle.motorcycle",), scored_as="Cyclist", attributes=_CYCLE,
        ),
        ObjectClass(
            "Bicycle", "bicycle", "bicycles", (1.70, 0.60, 1.28), _AS_SMALL, 1.2, (70, 200, 255),
            label_names=("cyclist",), categories=("vehicle.bicycle",), scored_as="Cyclist",
            attributes=_CYCLE,
        ),
        ObjectClass(
            "TrafficCone", "traffic cone", "traffic cones", (0.41, 0.41, 1.07), _AS_SMALL, 0.6,
            (240, 180, 210), heading=False, label_names=("traffic_cone",),
            categories=("movable_object.trafficcone",), find_radius=0.6, scored_as="Pedestrian",
        ),
        ObjectClass(
            "Barrier", "barrier", "barriers", (0.50, 2.53, 0.98), _AS_SMALL, 1.2, (255, 255, 210),
            categories=("movable_object.barrier",), scored_as="Pedestrian",
        ),
    ),
)  # fmt: skip
"""nuScenes' 10 detection classes, the categories mapped as nuScenes' detection benchmark maps them
(both buses to bus; the walking persons to pedestrian; a bicycle with or without rider to bicycle;
animals, strollers, wheelchairs, personal mobility, debris, pushable objects, bicycle racks and
emergency vehicles to none). A View-of-Delft ``Cyclist`` (rider and bicycle in one box) and a
parked ``bicycle`` are a Bicycle; ``motor`` and ``moped_scooter`` a Motorcycle."""

PRESETS: dict[str, ClassSet] = {s.name: s for s in (VOD, NUSCENES)}
"""The class sets by name: what ``--classes`` accepts."""

ALL_CLASSES: tuple[str, ...] = tuple(dict.fromkeys(n for s in PRESETS.values() for n in s.names))
"""Every class name of every preset (an :class:`~scenes.geometry.actors.Actor` may be any)."""


MATCH_DISTANCE: dict[str, float] = {
    c.name: c.match_distance for s in PRESETS.values() for c in s.classes
}
""":attr:`ObjectClass.match_distance` by class name, over every preset (a name means one class
in every set that has it: checked below)."""

_BY_NAME = (
    "match_distance",
    "min_footprint",
    "pseudo_thresholds",
    "talk2car_overlaps",
    "top1_distance",
)
"""Facts the tools look up by class name: the same in every preset that has the name."""

_FIRST: dict[str, ObjectClass] = {}
for _set in PRESETS.values():
    for _c in _set.classes:
        _FIRST.setdefault(_c.name, _c)
        for _fact in _BY_NAME:
            if getattr(_c, _fact) != getattr(_FIRST[_c.name], _fact):
                raise ValueError(f"class {_c.name}: {_fact} differs between the presets")
        if _set is VOD and (_c.talk2car_overlaps is None or _c.top1_distance is None):
            raise ValueError(f"class {_c.name}: a View-of-Delft class needs its Talk2Car numbers")


for _set in PRESETS.values():
    for _c in _set.classes:
        if _c.scored_as not in VOD or VOD.get(_c.scored_as).min_overlaps != _c.min_overlaps:
            raise ValueError(
                f"class {_c.name}: scored_as {_c.scored_as!r} must be a View-of-Delft class whose "
                "min_overlaps it has"
            )


def object_class(name: str) -> ObjectClass:
    """The class called ``name`` in the first preset that has it (a name means one class in
    every set: its words are the same); ValueError listing :data:`ALL_CLASSES` otherwise."""
    for s in PRESETS.values():
        if name in s:
            return s.get(name)
    raise ValueError(f"unknown class {name!r}: one of {ALL_CLASSES}")


def beyond_vod(name: str) -> bool:
    """Whether the class called ``name`` is beyond View-of-Delft's three: none of its nuScenes
    categories is one of theirs (a truck, bus, trailer, construction vehicle, motorcycle, traffic
    cone or barrier: nuScenes' seven beyond car, pedestrian and bicycle)."""
    three = {category for c in VOD.classes for category in c.categories}
    return not set(object_class(name).categories) & three


def class_set(name: str) -> ClassSet:
    """The preset called ``name``; ValueError listing the presets otherwise."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown class set {name!r}: one of {tuple(PRESETS)}") from None
