"""The slot vocabularies: every slot's variants (:data:`SLOTS`), the base language's and the
``nuscenes`` class set's road users' (:data:`ROAD_USER_SLOTS`).

Templates fill ``{placeholders}`` (``{np}`` noun phrase, ``{n}`` noun, ``{be}`` is/are, ``{rel}``
that/which, ``{us}`` the ego vehicle, ``{verb}`` the class's verb, ``{d}`` a depth with its unit,
``{lo}`` / ``{hi}`` a depth range, ``{v}`` a speed with its unit, ``{side}`` left/right, ``{k}`` a
count, ``{x}`` the number before a unit). Nouns are written ``singular|plural``. Each
:class:`Slot` has ``core`` variants, always ``train`` (the first is the canonical one; the rest are
the phrasings the generator always had and the forms issue 15 names: "twenty metres", m / meters /
metres, km/h / kph / kilometres per hour, m/s, lower case without punctuation, "where is", "show
me", "find", "can you locate", "highlight", people / persons, bikes / bicyclists / riders,
automobiles, closest / nearest), and ``more`` variants, a share of which is held out
(:mod:`scenes.language.prompts.phrasing.split`). Left and right share templates (``{side}``), so a
flip never crosses the split.
"""

from __future__ import annotations

from dataclasses import dataclass

from scenes.language.prompts.numbers import DIGITS, HYPHENATED, SPACED


@dataclass(frozen=True)
class Slot:
    """The variants of one choice: ``core`` (always train, ``core[0]`` canonical) and ``more``."""

    core: tuple[str, ...]
    more: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.core:
            raise ValueError("Slot: needs at least one core variant")
        if len(set(self.core + self.more)) != len(self.core) + len(self.more):
            raise ValueError(f"Slot: repeated variant in {self.core + self.more}")


S = Slot
_STATIONARY_MORE = ("motionless", "at a standstill", "at rest", "{rel} {be} not moving")
_STATIONARY = ("stationary", "{rel} {be} stationary", "not moving")

# fmt: off
SLOTS: dict[str, Slot] = {
    # ---- sentence frame, casing, punctuation ------------------------------------------------
    "frame": S(
        ("{np}", "where {be} {np}?", "show me {np}", "find {np}", "can you locate {np}?",
         "highlight {np}"),
        ("show {np}", "find me {np}", "locate {np}", "point out {np}", "select {np}", "mark {np}",
         "detect {np}", "look for {np}", "please find {np}", "please highlight {np}",
         "i am looking for {np}", "i'm looking for {np}", "give me {np}", "identify {np}",
         "can you find {np}?", "can you show me {np}?", "could you highlight {np}?",
         "do you see {np}?", "where can i see {np}?", "where exactly {be} {np}?", "{np} please",
         "box {np}", "track {np}"),
    ),
    "case": S(("sentence case", "lower case"), ("upper case", "title case")),
    "end/statement": S(("period", "no punctuation"), ("exclamation mark",)),
    "end/question": S(("question mark", "no punctuation")),
    "joiner": S(("space", "comma"), ("and",)),
    "rel": S(("that",), ("which",)),
    "ego": S(
        ("us", "the ego vehicle", "the ego car"),
        ("our car", "our vehicle", "me", "the ego-vehicle"),
    ),
    # ---- nouns, verbs, determiners, counts ----------------------------------------------------
    "noun.car": S(
        ("car|cars", "vehicle|vehicles", "automobile|automobiles"),
        ("auto|autos", "motor vehicle|motor vehicles"),
    ),
    "noun.pedestrian": S(
        ("pedestrian|pedestrians", "person|people", "person|persons"),
        ("walker|walkers", "person on foot|people on foot"),
    ),
    "noun.cyclist": S(
        ("cyclist|cyclists", "bike rider|bike riders", "bicyclist|bicyclists", "rider|riders",
         "bike|bikes"),
        ("bicycle|bicycles", "person on a bike|people on bikes", "bicycle rider|bicycle riders",
         "biker|bikers"),
    ),
    "noun.any": S(("object|objects", "road user|road users", "target|targets"), ("thing|things",)),
    "verb/car": S(("driving",), ("travelling", "going", "traveling")),
    "verb/pedestrian": S(("walking",), ("going",)),
    "verb/cyclist": S(("riding",), ("cycling", "going")),
    "verb/any": S(("travelling",), ("going", "traveling")),
    "det.plural": S(("the", "all the", "all of the"), ("all",)),
    "det.count": S(("the {k}", "{k}", "all {k}"), ("all {k} of the",)),
    "det.pair": S(("the {k}", "{k}", "both"), ("both of the", "both the")),
    "count": S(("words",), ("digits",)),
    # ---- numbers and units ------------------------------------------------------------------
    "number": S((DIGITS, HYPHENATED), (SPACED,)),
    "unit.depth": S(("{x} m", "{x} meters", "{x} metres"), ("{x}m",)),
    "unit.kmh": S(
        ("{x} km/h", "{x} kph", "{x} kilometres per hour"),
        ("{x}km/h", "{x} kmh", "{x} kilometers per hour", "{x} km per hour",
         "{x} kilometres an hour"),
    ),
    "unit.mps": S(
        ("{x} m/s", "{x} metres per second"), ("{x}m/s", "{x} mps", "{x} meters per second")
    ),
    # ---- position ---------------------------------------------------------------------------
    "position.side": S(
        ("on the {side}", "on our {side}", "on the {side} side", "to the {side}",
         "on the {side}-hand side", "to the {side} of {us}", "on the {side} side of the road"),
        ("on the {side} side of the street", "to our {side}", "{side} of {us}",
         "off to the {side}", "on the {side}-hand side of the road", "over on the {side}"),
    ),
    "position.ahead": S(
        ("directly ahead", "straight ahead", "in front of {us}", "directly in front of {us}",
         "in our lane"),
        ("dead ahead", "straight ahead of {us}", "straight in front of {us}", "in the same lane as {us}"),
    ),
    # ---- motion state -----------------------------------------------------------------------
    "motion.moving": S(
        ("moving", "{rel} {be} moving", "in motion"),
        ("on the move", "{rel} {be} in motion", "{rel} {be} on the move"),
    ),
    "motion.stationary/car": S(
        (*_STATIONARY, "parked", "{rel} {be} parked", "parked by the road"),
        (*_STATIONARY_MORE, "stopped"),
    ),
    "motion.stationary/pedestrian": S(
        (*_STATIONARY, "standing still", "{rel} {be} standing still"), _STATIONARY_MORE
    ),
    "motion.stationary/cyclist": S(
        (*_STATIONARY, "stopped", "standing still"), (*_STATIONARY_MORE, "{rel} {be} stopped")
    ),
    "motion.stationary/any": S(_STATIONARY, _STATIONARY_MORE),
    # ---- heading ----------------------------------------------------------------------------
    "heading.approaching": S(
        ("approaching {us}", "{verb} towards {us}", "{verb} toward {us}", "heading towards {us}",
         "moving toward {us}", "coming towards {us}", "{rel} {be} approaching"),
        ("coming our way", "heading our way", "moving towards {us}",
         "{rel} {be} coming towards {us}", "heading toward {us}"),
    ),
    "heading.away": S(
        ("moving away from {us}", "{verb} away from {us}", "heading away from {us}",
         "{rel} {be} moving away", "{verb} away"),
        ("going away from {us}", "receding from {us}", "{rel} {be} moving away from {us}",
         "{rel} {be} heading away"),
    ),
    "heading.crossing": S(
        ("crossing the road", "crossing our path", "{rel} {be} crossing the road",
         "crossing the street"),
        ("{rel} {be} crossing", "{rel} {be} crossing the street", "crossing the roadway"),
    ),
    # ---- adjectives (before the noun) -------------------------------------------------------
    "adj.moving": S(("moving",)),
    "adj.stationary/car": S(("stationary", "static", "parked"), ("motionless", "stopped")),
    "adj.stationary/pedestrian": S(("stationary", "static"), ("motionless",)),
    "adj.stationary/cyclist": S(("stationary", "static", "stopped"), ("motionless",)),
    "adj.stationary/any": S(("stationary", "static"), ("motionless",)),
    "adj.approaching/car": S(("approaching", "oncoming")),
    "adj.approaching/pedestrian": S(("approaching",)),
    "adj.approaching/cyclist": S(("approaching",)),
    "adj.approaching/any": S(("approaching",)),
    "adj.away": S(("receding",)),
    "adj.crossing": S(("crossing",)),
    # ---- speed ------------------------------------------------------------------------------
    "speed.about": S(
        ("at about {v}", "travelling at roughly {v}", "at a speed of about {v}",
         "{verb} at around {v}", "going about {v}"),
        ("at around {v}", "at approximately {v}", "at roughly {v}", "with a speed of about {v}",
         "doing about {v}", "{verb} at about {v}", "{rel} {be} going about {v}",
         "at a speed of roughly {v}"),
    ),
    "speed.above": S(
        ("faster than {v}", "at more than {v}", "{verb} faster than {v}",
         "at a speed above {v}", "going over {v}"),
        ("at over {v}", "above {v}", "exceeding {v}", "{verb} at more than {v}",
         "with a speed of more than {v}", "{rel} {be} faster than {v}", "quicker than {v}",
         "doing more than {v}"),
    ),
    "speed.below": S(
        ("slower than {v}", "at less than {v}", "{verb} slower than {v}",
         "at a speed below {v}", "going under {v}"),
        ("at under {v}", "below {v}", "{verb} at less than {v}", "with a speed under {v}",
         "{rel} {be} slower than {v}", "doing less than {v}"),
    ),
    # ---- depth ------------------------------------------------------------------------------
    "depth.about": S(
        ("about {d} ahead", "roughly {d} ahead", "around {d} away", "approximately {d} from {us}",
         "at a distance of about {d}", "about {d} away from {us}"),
        ("some {d} ahead", "roughly {d} away", "at about {d}", "at around {d}",
         "approximately {d} ahead of {us}", "about {d} from {us}", "around {d} ahead"),
    ),
    "depth.between": S(
        ("between {lo} and {hi} ahead", "{lo} to {hi} ahead", "between {lo} and {hi} away",
         "at a distance of {lo} to {hi}"),
        ("from {lo} to {hi} ahead", "{lo} to {hi} away from {us}",
         "at a distance between {lo} and {hi}", "somewhere between {lo} and {hi} ahead",
         "between {lo} and {hi} from {us}"),
    ),
    "depth.within": S(
        ("within {d}", "less than {d} ahead", "closer than {d}", "within {d} of {us}",
         "no more than {d} away"),
        ("under {d} away", "at most {d} ahead", "less than {d} from {us}", "nearer than {d}",
         "no further than {d} from {us}", "not more than {d} ahead"),
    ),
    "depth.beyond": S(
        ("further than {d}", "more than {d} ahead", "beyond {d}", "farther than {d} away"),
        ("over {d} away", "more than {d} from {us}", "further than {d} from {us}", "past {d}",
         "beyond {d} ahead", "at least {d} ahead"),
    ),
    # ---- superlatives ({n}: the noun) -------------------------------------------------------
    "extreme.nearest": S(
        ("nearest {n}", "closest {n}"),
        ("{n} closest to {us}", "{n} nearest to {us}", "{n} {rel} {be} closest to {us}"),
    ),
    "extreme.farthest": S(
        ("farthest {n}", "furthest {n}"),
        ("most distant {n}", "{n} farthest from {us}", "{n} furthest from {us}",
         "{n} {rel} {be} farthest from {us}"),
    ),
    "extreme.lateral": S(
        ("{side}most {n}",),
        ("{side}-most {n}", "{n} furthest to the {side}", "{n} farthest to the {side}",
         "{n} on the far {side}", "{n} {rel} {be} furthest to the {side}"),
    ),
    "extreme.fastest": S(
        ("fastest {n}",),
        ("quickest {n}", "speediest {n}", "{n} with the highest speed", "{n} going the fastest",
         "{n} {rel} {be} fastest"),
    ),
}
# fmt: on

_PARKED = (*_STATIONARY, "parked", "{rel} {be} parked", "stopped")
_STOPPED = (*_STATIONARY, "stopped", "standing still")
# fmt: off
ROAD_USER_SLOTS: dict[str, Slot] = {
    # ---- the nuscenes class set's nouns (each its own split group) ---------------------------
    "noun.truck": S(("truck|trucks", "lorry|lorries"),
                    ("heavy goods vehicle|heavy goods vehicles", "goods vehicle|goods vehicles")),
    "noun.bus": S(("bus|buses", "city bus|city buses"), ("coach|coaches", "transit bus|transit buses")),
    "noun.trailer": S(("trailer|trailers", "semi-trailer|semi-trailers"),
                      ("truck trailer|truck trailers",)),
    "noun.construction_vehicle": S(
        ("construction vehicle|construction vehicles", "work vehicle|work vehicles"),
        ("construction machine|construction machines", "site vehicle|site vehicles"),
    ),
    "noun.motorcycle": S(("motorcycle|motorcycles", "motorbike|motorbikes"),
                         ("motor bike|motor bikes", "powered two-wheeler|powered two-wheelers")),
    "noun.bicycle": S(("bicycle|bicycles", "bike|bikes"), ("pushbike|pushbikes", "push bike|push bikes")),
    "noun.traffic_cone": S(("traffic cone|traffic cones", "cone|cones"),
                           ("road cone|road cones", "safety cone|safety cones")),
    "noun.barrier": S(("barrier|barriers", "road barrier|road barriers"),
                      ("traffic barrier|traffic barriers", "construction barrier|construction barriers")),
    # ---- verbs and motion words: core only, each text new to its group or core there already,
    # so the vod classes' train / held-out split does not move ------------------------------------
    "verb/truck": S(("driving",)),
    "verb/bus": S(("driving",)),
    "verb/trailer": S(("travelling",)),
    "verb/construction_vehicle": S(("driving",)),
    "verb/motorcycle": S(("riding",)),
    "verb/bicycle": S(("riding",)),
    "verb/traffic_cone": S(("travelling",)),
    "verb/barrier": S(("travelling",)),
    "motion.stationary/truck": S(_PARKED),
    "motion.stationary/bus": S((*_STATIONARY, "stopped", "waiting", "standing still")),
    "motion.stationary/trailer": S(_PARKED),
    "motion.stationary/construction_vehicle": S(_PARKED),
    "motion.stationary/motorcycle": S(_STOPPED),
    "motion.stationary/bicycle": S((*_STATIONARY, "parked", "{rel} {be} parked")),
    "motion.stationary/traffic_cone": S(_STATIONARY),
    "motion.stationary/barrier": S(_STATIONARY),
    "adj.stationary/truck": S(("stationary", "static", "parked")),
    "adj.stationary/bus": S(("stationary", "static", "stopped")),
    "adj.stationary/trailer": S(("stationary", "static", "parked")),
    "adj.stationary/construction_vehicle": S(("stationary", "static", "parked")),
    "adj.stationary/motorcycle": S(("stationary", "static", "stopped")),
    "adj.stationary/bicycle": S(("stationary", "static", "parked")),
    "adj.stationary/traffic_cone": S(("stationary", "static")),
    "adj.stationary/barrier": S(("stationary", "static")),
    "adj.approaching/truck": S(("approaching", "oncoming")),
    "adj.approaching/bus": S(("approaching", "oncoming")),
    "adj.approaching/trailer": S(("approaching", "oncoming")),
    "adj.approaching/construction_vehicle": S(("approaching",)),
    "adj.approaching/motorcycle": S(("approaching", "oncoming")),
    "adj.approaching/bicycle": S(("approaching",)),
    "adj.approaching/traffic_cone": S(("approaching",)),
    "adj.approaching/barrier": S(("approaching",)),
    # ---- class-specific heading phrases (phrase_slot prefers them where they exist) -----------
    "heading.away/bus": S((*SLOTS["heading.away"].core, "pulling away", "{rel} {be} pulling away")),
}
# fmt: on
"""The slots of the ``nuscenes`` class set's road users beyond the car and the pedestrian
(:data:`scenes.language.prompts.phrasing.slot_choice.CLASS_KEYS`); part of :data:`SLOTS`. Their nouns are new groups with held-out variants of
their own; every other text is ``core`` and either new to its group or core there already, so
adding them leaves the ``vod`` classes' wording and split exactly as they were."""
SLOTS.update(ROAD_USER_SLOTS)
"""Every slot's variants (module docstring)."""
