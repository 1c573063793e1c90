"""Class sets: which road users a model knows, as configuration. The one home of class facts.

A :class:`ClassSet` is an ordered tuple of :class:`ObjectClass`; its order is the order of the
detector's heatmap channels. Two presets exist:

- ``vod`` (:data:`VOD`): ``Car``, ``Pedestrian``, ``Cyclist``, the Talk2Radar / View-of-Delft
  metric classes (the shipped ``checkpoints/tpcnet-small.pt``);
- ``nuscenes`` (:data:`NUSCENES`): nuScenes' 10 detection classes, in the order of the nuScenes
  detection benchmark's configuration (car, truck, bus, trailer, construction_vehicle, pedestrian,
  motorcycle, bicycle, traffic_cone, barrier). Names are single tokens (they are written into
  KITTI-style label files, whose fields are separated by spaces).

Facts per class: the name (model, label files, tables), the words a person uses for it (the answer
words of the app) and the mean size ``(l, w, h)`` in metres. The size statistics of the nuScenes
classes are the training-set means nuScenes-based detectors publish as anchor sizes; those of the
three VoD classes are the ones this project's synthetic world draws around.

Further facts (anchor and size priors of the detector, the evaluator's minimum overlaps, legend
colours, label-name and category mappings) join these dataclasses as the parts that use them follow
the class set; each fact has one home, here.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "ALL_CLASSES",
    "NUSCENES",
    "PRESETS",
    "VOD",
    "ClassSet",
    "ObjectClass",
    "class_set",
]


@dataclass(frozen=True)
class ObjectClass:
    """One class a model can detect and a prompt can name.

    Attributes:
        name: The class name: one token, as the model, label files and tables write it.
        noun: The singular word for it in an answer ("construction vehicle").
        plural: The plural word ("construction vehicles").
        mean_size: ``(l, w, h)`` mean box size in metres.
    """

    name: str
    noun: str
    plural: str
    mean_size: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not self.name or any(c.isspace() for c in self.name):
            raise ValueError(f"class name {self.name!r} must be one non-empty token")
        if len(self.mean_size) != 3 or min(self.mean_size) <= 0:
            raise ValueError(f"class {self.name}: mean_size must be 3 positive lengths")


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

    @property
    def names(self) -> tuple[str, ...]:
        """The class names in channel order."""
        return tuple(c.name for c in self.classes)

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


def _c(name: str, noun: str, plural: str, size: tuple[float, float, float]) -> ObjectClass:
    return ObjectClass(name=name, noun=noun, plural=plural, mean_size=size)


_CAR = _c("Car", "car", "cars", (4.2, 1.8, 1.6))
_PEDESTRIAN = _c("Pedestrian", "pedestrian", "pedestrians", (0.6, 0.6, 1.75))
_CYCLIST = _c("Cyclist", "cyclist", "cyclists", (1.8, 0.6, 1.7))

VOD = ClassSet("vod", (_CAR, _PEDESTRIAN, _CYCLIST))
"""The Talk2Radar / View-of-Delft metric classes."""

NUSCENES = ClassSet(
    "nuscenes",
    (
        _c("Car", "car", "cars", (4.63, 1.97, 1.74)),
        _c("Truck", "truck", "trucks", (6.93, 2.51, 2.84)),
        _c("Bus", "bus", "buses", (10.5, 2.94, 3.47)),
        _c("Trailer", "trailer", "trailers", (12.29, 2.90, 3.87)),
        _c(
            "ConstructionVehicle",
            "construction vehicle",
            "construction vehicles",
            (6.37, 2.85, 3.19),
        ),
        _c("Pedestrian", "pedestrian", "pedestrians", (0.73, 0.67, 1.77)),
        _c("Motorcycle", "motorcycle", "motorcycles", (2.11, 0.77, 1.47)),
        _c("Bicycle", "bicycle", "bicycles", (1.70, 0.60, 1.28)),
        _c("TrafficCone", "traffic cone", "traffic cones", (0.41, 0.41, 1.07)),
        _c("Barrier", "barrier", "barriers", (0.50, 2.53, 0.98)),
    ),
)
"""nuScenes' 10 detection classes (the categories map onto them by nuScenes' own mapping)."""

PRESETS: dict[str, ClassSet] = {s.name: s for s in (VOD, NUSCENES)}
"""The class sets by name: what ``--classes`` accepts."""

ALL_CLASSES: tuple[str, ...] = tuple(dict.fromkeys(n for s in PRESETS.values() for n in s.names))
"""Every class name of every preset (an :class:`~scenes.geometry.actors.Actor` may be any)."""


def class_set(name: str) -> ClassSet:
    """The preset called ``name``; ValueError listing the presets otherwise."""
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown class set {name!r}: one of {tuple(PRESETS)}") from None
