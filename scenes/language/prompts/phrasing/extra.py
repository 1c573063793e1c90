"""The extended language's wording of the base slots: more variants (:data:`EXTRA`) and the
base variants it leaves out (:data:`DROPPED`).

Used only with ``PromptConfig.language == "extended"`` (the base tables of
:mod:`scenes.language.prompts.phrasing.slots` stay as they are, so base prompts are
byte-identical):

* :data:`EXTRA` -- more variants of existing slots (more nouns per class, frames, colloquial
  motion and heading phrases, "past the {d} mark", "{d} in front of {us}", ...). All are on the
  ``train`` side; none repeats a held-out variant of the base slots (an import check), so the
  held-out set keeps measuring unseen wording.
* :data:`DROPPED` -- base variants the extended wording does not use: "in front of us" for the
  ego lane. In the extended language "N metres in front of us" is a depth (N metres ahead) and
  the lane is "in our lane" / "directly ahead in our lane" / "straight ahead".

The new families' own templates are :mod:`scenes.language.prompts.phrasing.family_slots`. Every
variant stays literally true of its atom and :func:`scenes.language.prompts.tags.infer_tags` finds
exactly the atom's tag in it (tests check each).
"""

from __future__ import annotations

from scenes.language.prompts.phrasing.slots import SLOTS
from scenes.language.prompts.phrasing.split import HELDOUT_VARIANTS, variant_id

# fmt: off
EXTRA: dict[str, tuple[str, ...]] = {
    "frame": (
        "could you show me {np}?", "i need {np}", "tell me where {np} {be}", "spot {np}",
        "pick out {np}", "{np}?", "help me find {np}", "outline {np}", "draw a box around {np}",
        "can you spot {np}?", "where on earth {be} {np}?", "hey, find {np}", "show me where {np} {be}",
        "i want to see {np}", "let me see {np}",
    ),
    "ego": ("my car", "the ego", "my vehicle"),
    "noun.car": (
        "sedan|sedans", "passenger car|passenger cars", "motorcar|motorcars",
        "hatchback|hatchbacks",
    ),
    "noun.pedestrian": ("passer-by|passers-by", "human|humans", "individual|individuals",
                        "pedestrian|peds"),
    "noun.cyclist": ("bicycle user|bicycle users", "bike-rider|bike-riders",
                     "rider on a bike|riders on bikes"),
    "noun.any": ("traffic participant|traffic participants", "detected object|detected objects",
                 "agent|agents"),
    "verb/car": ("heading", "rolling"),
    "verb/pedestrian": ("heading", "strolling"),
    "verb/cyclist": ("pedalling", "heading", "biking"),
    "verb/any": ("heading",),
    "det.plural": ("those",),
    "position.side": ("on the {side} of the road", "at the {side}", "along the {side} side",
                      "over to the {side}", "{side} side"),
    "position.ahead": ("directly ahead in our lane", "ahead in our lane", "in the ego lane",
                       "in the lane ahead", "straight ahead in our lane"),
    "motion.moving": ("underway", "on the go", "{rel} {be} underway"),
    "motion.stationary/car": ("parked up", "standing", "sitting still", "not going anywhere",
                              "halted", "at a stop"),
    "motion.stationary/pedestrian": ("standing", "stood still", "waiting in place",
                                     "not going anywhere"),
    "motion.stationary/cyclist": ("halted", "not going anywhere", "waiting in place"),
    "motion.stationary/any": ("not going anywhere", "halted"),
    "heading.approaching": ("coming at {us}", "coming closer", "getting closer to {us}",
                            "closing in on {us}", "{verb} in our direction", "headed our way",
                            "coming toward {us}"),
    "heading.away": ("leaving", "pulling away from {us}",
                     "moving off", "going further away", "{rel} {be} leaving"),
    "heading.crossing": ("cutting across the road", "going across the street", "crossing over"),
    "adj.stationary/car": ("standing", "halted"),
    "adj.approaching/car": ("incoming",),
    "speed.about": ("at a speed of around {v}", "{verb} around {v}",
                    "clocking about {v}"),
    "speed.above": ("going faster than {v}", "at a speed over {v}", "over {v}"),
    "speed.below": ("going slower than {v}", "under {v}"),
    "depth.about": ("{d} in front of {us}", "about {d} in front of {us}",
                    "roughly {d} in front of {us}", "about {d} out", "around {d} down the road",
                    "about {d} up the road"),
    "depth.between": ("{lo} to {hi} in front of {us}", "between {lo} and {hi} out",
                      "in the {lo} to {hi} range"),
    "depth.within": ("inside {d}", "less than {d} in front of {us}", "closer than {d} to {us}",
                     "before the {d} mark"),
    "depth.beyond": ("past the {d} mark", "further out than {d}",
                     "more than {d} in front of {us}", "beyond the {d} mark"),
    "extreme.nearest": ("closest {n} to {us}", "{n} nearest {us}"),
    "extreme.farthest": ("{n} at the greatest distance", "{n} farthest out"),
    "extreme.lateral": ("{n} on the extreme {side}",),
    "extreme.fastest": ("{n} going fastest", "quickest-going {n}"),
}
"""More variants of :data:`scenes.language.prompts.phrasing.slots.SLOTS` slots (module docstring)."""

DROPPED: dict[str, tuple[str, ...]] = {
    "position.ahead": ("in front of {us}", "directly in front of {us}", "straight in front of {us}"),
}
"""Base variants the extended wording leaves out (module docstring)."""
# fmt: on


def _check() -> None:
    for name, texts in EXTRA.items():
        if name not in SLOTS:
            raise ValueError(f"phrasing.extra: EXTRA names unknown slot {name!r}")
        base = SLOTS[name].core + SLOTS[name].more
        for t in texts:
            if t in base or variant_id(name, t) in HELDOUT_VARIANTS:
                raise ValueError(f"phrasing.extra: EXTRA {name}: {t!r} is already a base variant")


_check()
