"""The words people use for road users, keyed by class name: what :mod:`scenes.language.reading`
recognises as a mention of an object of a class.

The generator names a class with a few nouns (``scenes.language.prompts.phrasing``'s ``noun.*``
slots); people use many more ("van", "taxi", "guy", "lorry", "scooter") and hypernyms
("vehicle"). :data:`CLASS_WORDS` holds them per class name (the classes of every preset,
:mod:`scenes.geometry.classes`), singular and plural, with multi-word names; :data:`HYPERNYMS`
the words that may mean several classes. A word maps to classes; :func:`classes_of` keeps those of
a class set, and a word for a class outside the set is reported as that class's noun
(:func:`named_class`), so a reader can say "no truck here" rather than guess.

nuScenes' own category definitions decide the borderline words: a van, minivan, SUV or jeep is a
car; a pickup, lorry or semi is a truck; a scooter or moped is a motorcycle.
"""

from __future__ import annotations

from functools import lru_cache

# fmt: off
CLASS_WORDS: dict[str, tuple[str, ...]] = {
    "Car": (
        "car|cars", "sedan|sedans", "suv|suvs", "van|vans", "minivan|minivans", "taxi|taxis",
        "taxicab|taxicabs", "cab|cabs", "jeep|jeeps", "hatchback|hatchbacks", "coupe|coupes",
        "convertible|convertibles", "automobile|automobiles", "limo|limos",
        "limousine|limousines", "caravan|caravans", "uber|ubers",
        "police car|police cars", "cop car|cop cars", "squad car|squad cars",
        "sports car|sports cars", "station wagon|station wagons", "mini van|mini vans",
        "camper|campers",
    ),
    "Truck": (
        "truck|trucks", "lorry|lorries", "pickup|pickups", "pickup truck|pickup trucks",
        "pick-up|pick-ups", "pick up truck|pick up trucks", "semi|semis",
        "semi truck|semi trucks", "tractor trailer|tractor trailers", "box truck|box trucks",
        "delivery truck|delivery trucks", "garbage truck|garbage trucks", "tanker|tankers",
        "dump truck|dump trucks", "fire truck|fire trucks", "firetruck|firetrucks",
        "tow truck|tow trucks", "eighteen wheeler|eighteen wheelers", "18 wheeler|18 wheelers",
        "ute|utes", "big rig|big rigs",
    ),
    "Bus": (
        "bus|buses", "coach|coaches", "double decker|double deckers", "shuttle|shuttles",
        "school bus|school buses", "minibus|minibuses", "tram|trams", "busses|busses",
    ),
    "Trailer": ("trailer|trailers",),
    "ConstructionVehicle": (
        "construction vehicle|construction vehicles", "excavator|excavators",
        "digger|diggers", "bulldozer|bulldozers", "crane|cranes", "forklift|forklifts",
        "cement mixer|cement mixers", "cement truck|cement trucks", "steamroller|steamrollers",
        "backhoe|backhoes", "construction truck|construction trucks",
        "construction machine|construction machines",
    ),
    "Pedestrian": (
        "pedestrian|pedestrians", "person|people", "person|persons", "man|men",
        "woman|women", "guy|guys", "lady|ladies", "gentleman|gentlemen", "boy|boys",
        "girl|girls", "kid|kids", "child|children", "worker|workers", "officer|officers",
        "policeman|policemen", "policewoman|policewomen", "cop|cops", "jogger|joggers",
        "runner|runners", "walker|walkers", "friend|friends", "son|sons", "daughter|daughters",
        "wife|wives", "husband|husbands", "mother|mothers", "mom|moms", "mum|mums",
        "father|fathers", "dad|dads", "brother|brothers", "sister|sisters",
        "colleague|colleagues", "boss|bosses", "uncle|uncles", "aunt|aunts",
        "grandma|grandmas", "grandpa|grandpas", "grandmother|grandmothers",
        "grandfather|grandfathers", "neighbour|neighbours", "neighbor|neighbors",
        "cousin|cousins", "buddy|buddies", "pal|pals", "girlfriend|girlfriends",
        "boyfriend|boyfriends", "student|students", "teenager|teenagers", "dude|dudes",
        "fellow|fellows", "individual|individuals", "human|humans", "adult|adults",
        "someone|someone", "somebody|somebody", "crossing guard|crossing guards",
        "construction worker|construction workers", "police officer|police officers",
        "hitchhiker|hitchhikers", "tourist|tourists",
        "businessman|businessmen", "fella|fellas", "folk|folks", "walker|walkers",
    ),
    "Cyclist": (
        "cyclist|cyclists", "bicyclist|bicyclists", "biker|bikers", "bike|bikes",
        "bicycle|bicycles", "bike rider|bike riders", "bicycle rider|bicycle riders",
        "rider|riders",
    ),
    "Motorcycle": (
        "motorcycle|motorcycles", "motorbike|motorbikes", "motorcyclist|motorcyclists",
        "scooter|scooters", "moped|mopeds", "vespa|vespas", "motor bike|motor bikes",
        "motor cycle|motor cycles", "biker|bikers", "bike|bikes", "rider|riders",
        "motorcycle rider|motorcycle riders",
    ),
    "Bicycle": (
        "bicycle|bicycles", "bike|bikes", "cyclist|cyclists", "bicyclist|bicyclists",
        "biker|bikers", "bike rider|bike riders", "bicycle rider|bicycle riders",
        "rider|riders",
    ),
    "TrafficCone": (
        "traffic cone|traffic cones", "cone|cones", "pylon|pylons", "traffic pylon|traffic pylons",
        "safety cone|safety cones", "road cone|road cones",
    ),
    "Barrier": (
        "barrier|barriers", "jersey barrier|jersey barriers", "roadblock|roadblocks",
        "road block|road blocks", "barricade|barricades", "guard rail|guard rails",
        "traffic barrier|traffic barriers", "concrete barrier|concrete barriers",
    ),
}
"""Per class name, ``singular|plural`` words people call an object of it."""

HYPERNYMS: dict[str, tuple[str, ...]] = {
    "vehicle|vehicles": ("Car", "Truck", "Bus", "Trailer", "ConstructionVehicle", "Motorcycle"),
    "motor vehicle|motor vehicles": ("Car", "Truck", "Bus", "Trailer", "ConstructionVehicle"),
    "auto|autos": ("Car",),
    "road user|road users": (),
}
"""Words that may mean several classes (``()``: any class of the set)."""
# fmt: on

PERSON_CLASSES = ("Pedestrian", "Cyclist", "Motorcycle", "Bicycle")
"""Classes "he", "she", "him", "her" may be about: a person walking or riding."""
THING_CLASSES = (
    "Car", "Truck", "Bus", "Trailer", "ConstructionVehicle", "Motorcycle", "Bicycle", "Cyclist",
    "TrafficCone", "Barrier",
)  # fmt: skip
"""Classes "it" may be about."""


@lru_cache(maxsize=1)
def lexicon() -> dict[str, tuple[tuple[str, ...], bool]]:
    """Every word (lower case, spaces between words) -> ``(class names, plural)``: people's
    (:data:`CLASS_WORDS`, :data:`HYPERNYMS`) and the generator's own nouns (its ``noun.*``
    slots); a word several classes share lists them all (``"bike"``: a cyclist, a bicycle or a
    motorcycle)."""
    table: dict[str, tuple[list[str], bool]] = {}

    def add(pair: str, classes: tuple[str, ...]) -> None:
        for word, plural in zip(pair.split("|"), (False, True), strict=True):
            names, _ = table.setdefault(word, ([], plural))
            names.extend(c for c in classes if c not in names)

    for key, pairs in _generator_noun_slots().items():
        for pair in pairs:
            add(pair, GENERATOR_NOUN_CLASSES.get(key, ()))
    for cls, words in CLASS_WORDS.items():
        for pair in words:
            add(pair, (cls,))
    for pair, classes in HYPERNYMS.items():
        for word, plural in zip(pair.split("|"), (False, True), strict=True):
            table[word] = (list(classes), plural)
    return {w: (tuple(c), p) for w, (c, p) in table.items()}


GENERATOR_NOUN_CLASSES: dict[str, tuple[str, ...]] = {
    "noun.car": ("Car",),
    "noun.pedestrian": ("Pedestrian",),
    "noun.cyclist": ("Cyclist", "Bicycle"),
    "noun.truck": ("Truck",),
    "noun.bus": ("Bus",),
    "noun.trailer": ("Trailer",),
    "noun.construction_vehicle": ("ConstructionVehicle",),
    "noun.motorcycle": ("Motorcycle",),
    "noun.bicycle": ("Bicycle", "Cyclist"),
    "noun.traffic_cone": ("TrafficCone",),
    "noun.barrier": ("Barrier",),
    "noun.any": (),
}
"""The classes each of the generator's noun slots names (``()``: any class)."""


def _generator_noun_slots() -> dict[str, tuple[str, ...]]:
    """The generator's noun slots (``noun.*``), every variant (train, held-out, extra)."""
    from scenes.language.prompts.phrasing.extra import EXTRA
    from scenes.language.prompts.phrasing.slots import SLOTS

    return {
        key: (*slot.core, *slot.more, *EXTRA.get(key, ()))
        for key, slot in SLOTS.items()
        if key.startswith("noun.")
    }


def longest_word() -> int:
    """The most words a lexicon entry has."""
    return max(len(w.split()) for w in lexicon())


def classes_of(names: tuple[str, ...], set_names: tuple[str, ...]) -> tuple[str, ...]:
    """The classes of ``names`` that a class set (its ``names``) has, in the set's order (``()``
    names: every class of the set)."""
    if not names:
        return set_names
    return tuple(n for n in set_names if n in names)


@lru_cache(maxsize=4)
def generator_nouns(class_set: str = "vod") -> frozenset[str]:
    """Every noun the generator writes for prompts of ``class_set`` (singular and plural): its
    class nouns (train and held-out) and the out-of-class things of its empty-answer prompts,
    less the nouns it does not write for that set because they say more than one class there
    ("vehicle" beside trucks and buses). A sentence naming only these is one the model was
    trained on, and is grounded as written."""
    from scenes.geometry.classes import class_set as named_set
    from scenes.language.prompts.nouns import OUT_OF_CLASS
    from scenes.language.prompts.phrasing.slot_choice import WIDER_THAN_CLASS

    names = named_set(class_set).names
    wide = {v.partition(":")[2] for v in WIDER_THAN_CLASS.get(class_set, ())}
    pairs = [*OUT_OF_CLASS]
    for key, slot in _generator_noun_slots().items():
        owner = GENERATOR_NOUN_CLASSES.get(key, ())
        if not owner or owner[0] in names:  # the slots of the set's classes, and "objects"
            pairs += [p for p in slot if p not in wide]
    return frozenset(w for pair in pairs for w in pair.split("|"))
