"""The compositional families' templates (:data:`FAMILY_SLOTS`,
:mod:`scenes.language.prompts.families`), used only with ``PromptConfig.language == "extended"``:
negated phrases (``{nbe}``: "is not" / "are not" / "isn't" / "aren't"), exclusion joiners,
ordinals, relations (``{ref}``: the reference's noun phrase), direction of travel, behind us, the
slowest, out-of-class things and counting frames. All ``train``; none shadows a base slot (an
import check). Every variant stays literally true of its atom and
:func:`scenes.language.prompts.tags.infer_tags` finds exactly the atom's tag in it (tests check
each).
"""

from __future__ import annotations

from scenes.language.prompts.phrasing.slots import SLOTS, Slot

# fmt: off
FAMILY_SLOTS: dict[str, Slot] = {
    "nbe/singular": Slot(("is not", "isn't")),
    "nbe/plural": Slot(("are not", "aren't")),
    # ---- negated attribute phrases ----------------------------------------------------------
    "neg.moving": Slot(("not moving", "{rel} {nbe} moving", "not in motion", "{rel} {nbe} in motion")),
    "neg.stationary/car": Slot(("not parked", "{rel} {nbe} parked", "{rel} {nbe} stationary",
                                "not stationary")),
    "neg.stationary/pedestrian": Slot(("not standing still", "{rel} {nbe} standing still",
                                       "not stationary", "{rel} {nbe} stationary")),
    "neg.stationary/cyclist": Slot(("not stopped", "{rel} {nbe} stopped", "not stationary",
                                    "{rel} {nbe} stationary")),
    "neg.stationary/any": Slot(("not stationary", "{rel} {nbe} stationary")),
    **{f"neg.stationary/{k}": Slot(("not parked", "{rel} {nbe} parked", "not stationary",
                                    "{rel} {nbe} stationary"))
       for k in ("truck", "trailer", "construction_vehicle", "bicycle")},
    **{f"neg.stationary/{k}": Slot(("not stopped", "{rel} {nbe} stopped", "not stationary",
                                    "{rel} {nbe} stationary"))
       for k in ("bus", "motorcycle")},
    **{f"neg.stationary/{k}": Slot(("not stationary", "{rel} {nbe} stationary"))
       for k in ("traffic_cone", "barrier")},
    "neg.heading.approaching": Slot(("not approaching {us}", "{rel} {nbe} approaching {us}",
                                     "not coming towards {us}", "{rel} {nbe} heading towards {us}",
                                     "not {verb} toward {us}", "{rel} {nbe} coming our way")),
    "neg.heading.away": Slot(("not moving away from {us}", "{rel} {nbe} moving away",
                              "not heading away from {us}", "{rel} {nbe} {verb} away from {us}")),
    "neg.heading.crossing": Slot(("not crossing the road", "{rel} {nbe} crossing",
                                  "{rel} {nbe} crossing the street", "not crossing our path")),
    "neg.side": Slot(("not on the {side}", "{rel} {nbe} on the {side}", "not to the {side} of {us}",
                      "{rel} {nbe} on the {side} side", "not on our {side}")),
    "neg.ahead": Slot(("not directly ahead", "{rel} {nbe} in our lane", "not in our lane",
                       "{rel} {nbe} straight ahead")),
    "neg.speed.above": Slot(("not faster than {v}", "{rel} {nbe} going faster than {v}",
                             "no faster than {v}", "{rel} {nbe} faster than {v}")),
    "neg.depth.about": Slot(("not about {d} away", "{rel} {nbe} about {d} ahead",
                             "not around {d} from {us}")),
    "neg.depth.between": Slot(("not between {lo} and {hi} ahead",
                               "{rel} {nbe} between {lo} and {hi} away")),
    "neg.depth.within": Slot(("not within {d}", "{rel} {nbe} within {d} of {us}",
                              "not closer than {d}", "not less than {d} ahead")),
    "neg.depth.beyond": Slot(("not beyond {d}", "not further than {d}",
                              "{rel} {nbe} more than {d} ahead", "not farther than {d} away")),
    # ---- direction of travel (families.Travel) --------------------------------------------
    "travel.same": Slot(("heading the same way as {us}", "leaving in the same direction as {us}",
                         "going in the same direction as {us}", "moving the same way as {us}",
                         "{verb} in the same direction as {us}", "{rel} {be} going our way",
                         "travelling in our direction of travel")),
    "travel.opposite": Slot(("coming the other way", "heading the opposite way to {us}",
                             "{verb} in the opposite direction", "going the opposite way",
                             "moving in the opposite direction to {us}",
                             "{rel} {be} coming the other way")),
    # ---- behind the ego vehicle (families.Behind): outside the annotated area -------------
    "position.behind": Slot(("behind {us}", "right behind {us}", "directly behind {us}",
                             "{rel} {be} behind {us}", "back behind {us}", "somewhere behind {us}",
                             "following behind {us}")),
    # ---- the slowest (moving) one: the extended language's superlative --------------------
    "extreme.slowest": Slot(("slowest {n}", "slowest-moving {n}", "{n} going the slowest",
                             "{n} with the lowest speed", "{n} {rel} {be} slowest",
                             "{n} moving the slowest")),
    # ---- exclusion --------------------------------------------------------------------------
    "excl.det": Slot(("all the", "all", "all of the", "the")),
    "excl.join": Slot(("except", "but", "except for", "other than", "apart from", "excluding",
                       "but not")),
    "excl.nearest": Slot(("nearest one", "closest one", "one closest to {us}", "nearest",
                          "closest")),
    "excl.farthest": Slot(("farthest one", "furthest one", "one farthest away",
                           "most distant one", "farthest")),
    "excl.lateral": Slot(("{side}most one", "one furthest to the {side}", "one on the far {side}",
                          "{side}most")),
    "excl.fastest": Slot(("fastest one", "quickest one", "fastest")),
    "excl.slowest": Slot(("slowest one", "slowest-moving one", "slowest")),
    "excl.subset/singular": Slot(("the one", "the {n}")),
    "excl.subset/plural": Slot(("the ones", "those", "the {n}")),
    # ---- ordinals ({o}: second, 2nd, ...) ---------------------------------------------------
    "ord.2": Slot(("second", "2nd")),
    "ord.3": Slot(("third", "3rd")),
    "ord.4": Slot(("fourth", "4th")),
    "ord.k.2": Slot(("two",)),
    "ord.k.3": Slot(("three",)),
    "ord.k.4": Slot(("four",)),
    "ord.nearest": Slot(("{o} closest {n}", "{o} nearest {n}", "{o}-closest {n}",
                         "{n} {rel} {be} {o} closest to {us}", "{o} closest {n} to {us}",
                         "{n} in {o} place by distance", "{o} {n} counting from {us}",
                         "{n} number {k} by distance from {us}", "{o} {n} nearest to {us}")),
    "ord.nearest/2": Slot(("closest {n} but one", "next-to-nearest {n}", "nearest {n} but one")),
    "ord.farthest": Slot(("{o} farthest {n}", "{o} furthest {n}", "{o} most distant {n}",
                          "{n} {rel} {be} {o} farthest from {us}", "{o}-farthest {n}",
                          "{o} {n} counting from the farthest", "{o} furthest away {n}",
                          "{n} {rel} {be} {o} furthest away")),
    "ord.farthest/2": Slot(("farthest {n} but one", "furthest {n} but one",
                            "next-to-farthest {n}")),
    "ord.lateral": Slot(("{o} {n} from the {side}", "{o} {side}most {n}",
                         "{o} {n} counting from the {side}", "{o} {n} from the {side} side",
                         "{n} number {k} from the {side}", "{n} in {o} place from the {side}",
                         "{o} {n} in from the {side}", "{n} {rel} {be} {o} from the {side}",
                         "{o} {n} when counting from the {side}", "{o} {n} from the {side} edge")),
    "ord.fastest": Slot(("{o} fastest {n}", "{o} quickest {n}", "{o}-fastest {n}",
                         "{o} fastest-moving {n}", "{n} with the {o} highest speed",
                         "{n} {rel} {be} {o} fastest", "{o} speediest {n}")),
    "ord.slowest": Slot(("{o} slowest {n}", "{o}-slowest {n}", "{o} slowest-moving {n}",
                         "{n} with the {o} lowest speed", "{n} {rel} {be} {o} slowest")),
    # ---- relations ({ref}: the reference's noun phrase) -------------------------------------
    "relation.closest_to": Slot(("closest to {ref}", "nearest to {ref}",
                                 "{rel} {be} closest to {ref}", "nearest {ref}")),
    "relation.behind": Slot(("behind {ref}", "just behind {ref}", "{rel} {be} behind {ref}",
                             "right behind {ref}")),
    "relation.next_to": Slot(("next to {ref}", "beside {ref}", "close to {ref}",
                              "{rel} {be} next to {ref}", "alongside {ref}", "right next to {ref}",
                              "near {ref}")),
    "relation.between": Slot(("between {ref}", "in between {ref}", "{rel} {be} between {ref}",
                              "located between {ref}")),
    "relation.pair": Slot(("the two {n}", "both {n}", "the pair of {n}")),
    # ---- out-of-class things, indefinite ({a}: a / an) --------------------------------------
    "ooc.frame/singular": Slot(("is there {a} {np}?", "do you see {a} {np}?", "find {a} {np}",
                                "{a} {np}", "can you find {a} {np}?", "where is {a} {np}?",
                                "show me {a} {np}")),
    "ooc.frame/plural": Slot(("are there any {np}?", "any {np}?", "find all {np}",
                              "show me any {np}", "do you see any {np}?")),
    # ---- counting ({np}: a plural noun phrase without determiner) ---------------------------
    "count.frame": Slot(("how many {np} are there?", "how many {np}?", "how many {np} can you see?",
                         "how many {np} do you see?", "count the {np}", "count all the {np}",
                         "what is the number of {np}?", "number of {np}?",
                         "how many {np} are in the scene?", "can you count the {np}?",
                         "tell me how many {np} there are")),
}
# fmt: on
"""Slots of the compositional families (module docstring)."""


def _check() -> None:
    for name in FAMILY_SLOTS:
        if name in SLOTS:
            raise ValueError(f"phrasing.family_slots: family slot {name!r} shadows a base slot")


_check()
