"""Which slot says what: an atom's post-noun phrase (:func:`phrase_slot`), its pre-noun
adjective (:func:`adjective_slot`), a superlative (:func:`extreme_slot`), a class's slot suffix
(:data:`CLASS_KEYS`), and the noun variants that say more than their class in a class set
(:data:`WIDER_THAN_CLASS`, :func:`too_wide`).
"""

from __future__ import annotations

from scenes.language.prompts.atoms import (
    Atom,
    DepthAbout,
    DepthBetween,
    DepthBeyond,
    DepthWithin,
    Extreme,
    Heading,
    HeadingIs,
    MotionState,
    OnSide,
    Side,
    SpeedAbout,
    SpeedAbove,
    SpeedBelow,
)
from scenes.language.prompts.phrasing.slots import SLOTS
from scenes.language.prompts.phrasing.split import variant_id

CLASS_KEYS: dict[str | None, str] = {
    "Car": "car",
    "Pedestrian": "pedestrian",
    "Cyclist": "cyclist",
    None: "any",
    "Truck": "truck",
    "Bus": "bus",
    "Trailer": "trailer",
    "ConstructionVehicle": "construction_vehicle",
    "Motorcycle": "motorcycle",
    "Bicycle": "bicycle",
    "TrafficCone": "traffic_cone",
    "Barrier": "barrier",
}
"""Slot-name suffix of a predicate class (``None``: any class, "objects")."""


WIDER_THAN_CLASS: dict[str, frozenset[str]] = {
    "vod": frozenset(),
    "nuscenes": frozenset(
        {
            variant_id("noun.car", "vehicle|vehicles"),
            variant_id("noun.car", "motor vehicle|motor vehicles"),
        }
    ),
}
"""Per class set, the noun variants (ids) that say more than their class there: with trucks,
buses and construction vehicles about, "the vehicle" is no longer only a car. A prompt using
one is not generated for that set (:func:`too_wide`)."""


def too_wide(variants: tuple[str, ...], classes: str) -> bool:
    """Whether a prompt's variant ids use a noun wider than its class in the set ``classes``."""
    wide = WIDER_THAN_CLASS[classes]
    return bool(wide) and any(v in wide for v in variants)


def phrase_slot(atom: Atom, cls_key: str) -> str:
    """The slot of an atom's post-noun phrase (an atom with a ``slot`` attribute names its own:
    the extended language's atoms, :mod:`scenes.language.prompts.families`)."""
    own = getattr(atom, "slot", None)
    if isinstance(own, str):
        return own
    if isinstance(atom, OnSide):
        return "position.ahead" if atom.side is Side.AHEAD else "position.side"
    if isinstance(atom, MotionState):
        return "motion.moving" if atom.moving else f"motion.stationary/{cls_key}"
    if isinstance(atom, HeadingIs):
        slot = f"heading.{atom.heading.value}"
        return f"{slot}/{cls_key}" if f"{slot}/{cls_key}" in SLOTS else slot
    if isinstance(atom, SpeedAbout):
        return "speed.about"
    if isinstance(atom, SpeedAbove):
        return "speed.above"
    if isinstance(atom, SpeedBelow):
        return "speed.below"
    if isinstance(atom, DepthAbout):
        return "depth.about"
    if isinstance(atom, DepthBetween):
        return "depth.between"
    if isinstance(atom, DepthWithin):
        return "depth.within"
    if isinstance(atom, DepthBeyond):
        return "depth.beyond"
    raise ValueError(f"phrase_slot: no phrasing for atom {atom!r}")


def adjective_slot(atom: Atom, cls_key: str) -> str | None:
    """The slot of an atom's pre-noun adjective, None when it has none."""
    if isinstance(atom, MotionState):
        return "adj.moving" if atom.moving else f"adj.stationary/{cls_key}"
    if isinstance(atom, HeadingIs):
        if atom.heading is Heading.APPROACHING:
            return f"adj.approaching/{cls_key}"
        return f"adj.{atom.heading.value}"
    return None


def extreme_slot(extreme: Extreme) -> str:
    """The slot of a superlative's noun phrase."""
    if extreme in (Extreme.LEFTMOST, Extreme.RIGHTMOST):
        return "extreme.lateral"
    return f"extreme.{extreme.value}"
