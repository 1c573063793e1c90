"""Things in a street scene that none of the classes (Car, Pedestrian, Cyclist) covers, and nonsense.

:data:`OUT_OF_CLASS` lists common street things as ``singular|plural``: other vehicles, animals,
signs and signals, street furniture, buildings, vegetation, road features, objects. A prompt
naming one of them refers to nothing. A third of them are held out of the ``train`` phrasing
stream (:data:`HELDOUT_NOUNS`), to measure nouns never trained on. Left out on purpose, because a class may cover them or a
person may mean one: car-like vehicles (van, taxi, SUV, jeep, pickup, police car, ambulance,
minivan, camper), two-wheelers a cyclist may ride (motorbike, motorcycle, scooter, moped,
e-bike, tricycle), and people (child, jogger, skateboarder, wheelchair user, stroller, rider).
A class set whose classes cover some of these things (the ``nuscenes`` set: buses, trucks,
trailers, works machines, cones, barriers) leaves them out (:data:`COVERED`, :func:`nouns_for`).

:func:`nonsense` draws text that names nothing: keyboard runs, made-up words, filler.
"""

from __future__ import annotations

import zlib

import numpy as np

_IRREGULAR = {
    "bus": "buses",
    "sheep": "sheep",
    "deer": "deer",
    "goose": "geese",
    "mouse": "mice",
    "fish": "fish",
    "bench": "benches",
    "box": "boxes",
    "fox": "foxes",
    "bush": "bushes",
    "church": "churches",
    "ditch": "ditches",
    "hedgehog": "hedgehogs",
    "pony": "ponies",
    "lorry": "lorries",
    "puppy": "puppies",
    "butterfly": "butterflies",
    "billboard": "billboards",
    "cross": "crosses",
    "glass": "glasses",
    "switch": "switches",
    "statue": "statues",
    "ferry": "ferries",
    "sandbox": "sandboxes",
    "leaf": "leaves",
    "shelf": "shelves",
    "scarecrow": "scarecrows",
    "gas station": "gas stations",
    "bus stop": "bus stops",
    "bus shelter": "bus shelters",
    "bus lane": "bus lanes",
    "bus station": "bus stations",
    "school bus": "school buses",
    "city bus": "city buses",
    "double-decker bus": "double-decker buses",
    "minibus": "minibuses",
    "trolleybus": "trolleybuses",
    "coach": "coaches",
    "bunch of flowers": "bunches of flowers",
    "phone booth": "phone booths",
    "traffic island": "traffic islands",
    "speed bump": "speed bumps",
}

# fmt: off
_WORDS = (
    # other vehicles (not cars, not bicycles)
    "bus", "school bus", "city bus", "double-decker bus", "minibus", "trolleybus", "coach",
    "truck", "lorry", "semi-truck", "tractor-trailer", "dump truck", "fire truck", "fire engine",
    "garbage truck", "tow truck", "delivery truck", "cement mixer", "tanker", "tram", "streetcar",
    "train", "locomotive", "trailer", "tractor", "forklift", "excavator", "bulldozer", "crane",
    "road roller", "street sweeper", "snowplough", "boat", "ferry", "canoe", "airplane",
    "helicopter", "hot air balloon", "horse carriage", "rickshaw", "wagon", "cart", "shopping cart",
    "wheelbarrow", "handcart", "golf cart",
    # animals
    "dog", "puppy", "cat", "horse", "pony", "cow", "bull", "sheep", "goat", "pig", "deer",
    "moose", "fox", "rabbit", "squirrel", "hedgehog", "rat", "mouse", "bird", "pigeon", "seagull",
    "crow", "duck", "goose", "swan", "chicken", "owl", "butterfly", "bee", "fish", "frog",
    "badger", "bear", "wolf", "donkey", "camel",
    # signs and signals
    "traffic light", "traffic signal", "stop sign", "yield sign", "speed limit sign", "road sign",
    "street sign", "traffic sign", "direction sign", "warning sign", "parking sign",
    "no entry sign", "billboard", "advertisement", "poster", "banner", "flag", "signpost",
    "walk signal", "railway signal", "traffic camera", "speed camera", "road marking",
    "arrow on the road",
    # street furniture
    "street lamp", "lamp post", "lamppost", "street light", "light pole", "utility pole", "pole",
    "power line", "bollard", "traffic cone", "cone", "barrier", "road barrier", "guardrail",
    "railing", "fence", "gate", "wall", "bench", "trash can", "bin", "rubbish bin", "litter bin",
    "dumpster", "recycling container", "container", "skip", "fire hydrant", "hydrant",
    "mailbox", "postbox", "phone booth", "bus stop", "bus shelter", "kiosk", "vending machine",
    "parking meter", "ticket machine", "charging station", "bicycle rack", "bike rack",
    "planter", "flower pot", "fountain", "statue", "sculpture", "monument", "clock", "drain",
    "manhole", "manhole cover", "grate", "pillar", "column", "sandbag", "pallet", "crate",
    "barrel", "ladder", "scaffolding", "umbrella", "parasol", "tent", "awning", "canopy",
    "table", "chair", "stool", "picnic table", "sign board", "notice board", "advertising column",
    # buildings and structures
    "building", "house", "shop", "store", "supermarket", "restaurant", "cafe", "bar", "hotel",
    "office", "church", "tower", "skyscraper", "garage", "shed", "barn", "warehouse", "factory",
    "school", "hospital", "station", "bus station", "gas station", "petrol station", "bridge",
    "tunnel", "overpass", "underpass", "archway", "arch", "windmill", "lighthouse", "castle",
    "apartment block", "doorway", "door", "window", "balcony", "chimney", "staircase", "ramp",
    "porch", "tollbooth",
    # vegetation and terrain
    "tree", "palm tree", "bush", "shrub", "hedge", "flower bed", "flower", "bunch of flowers",
    "lawn", "patch of grass", "field", "forest", "park", "garden", "leaf", "pile of leaves",
    "rock", "boulder", "hill", "pond", "lake", "river", "canal", "ditch", "puddle", "snowbank",
    "snowman",
    # road features
    "pothole", "crosswalk", "zebra crossing", "speed bump", "roundabout", "traffic island",
    "curb", "kerb", "sidewalk", "pavement", "bus lane", "railway track", "tram track",
    "level crossing", "intersection", "junction", "driveway", "parking lot", "median strip",
    "road works", "construction site", "tollgate",
    # objects
    "box", "cardboard box", "package", "parcel", "suitcase", "bag", "backpack", "shopping bag",
    "ball", "football", "balloon", "kite", "drone", "toy", "bottle", "can", "cup", "newspaper",
    "tyre", "wheel", "rope", "cable", "pipe", "plank", "brick", "stone", "traffic barrel",
    "mattress", "sofa", "fridge", "television", "computer", "phone", "camera", "mirror",
    "scarecrow", "sandbox", "glass", "shelf", "switch", "cross",
)
# fmt: on


def _plural(word: str) -> str:
    if word in _IRREGULAR:
        return _IRREGULAR[word]
    if word.endswith(("s", "x", "ch", "sh")):
        return word + "es"
    if word.endswith("y") and word[-2:-1] not in "aeiou":
        return word[:-1] + "ies"
    return word + "s"


OUT_OF_CLASS: tuple[str, ...] = tuple(dict.fromkeys(f"{w}|{_plural(w)}" for w in _WORDS))
"""Out-of-class things as ``singular|plural`` (module docstring)."""

HELDOUT_NOUN_SHARE = 1.0 / 3.0


def _heldout_nouns() -> frozenset[str]:
    ranked = sorted(OUT_OF_CLASS, key=lambda e: (zlib.crc32(f"ooc:{e}".encode()), e))
    return frozenset(ranked[: round(len(ranked) * HELDOUT_NOUN_SHARE)])


HELDOUT_NOUNS = _heldout_nouns()
"""The out-of-class nouns of the ``heldout`` phrasing stream: a third, ranked by CRC-32 of
``ooc:singular|plural`` like the phrasing split (:mod:`scenes.language.prompts.phrasing`); the ``train``
stream names only the others, ``all`` every one."""


COVERED: dict[str, frozenset[str]] = {
    "vod": frozenset(),
    "nuscenes": frozenset(
        # buses and trucks of every kind, trailers, works machines (construction vehicles),
        # cones, traffic barrels and barriers: the set's classes cover them or a person may mean
        # one of them by it
        ("bus", "school bus", "city bus", "double-decker bus", "minibus", "trolleybus", "coach",
         "truck", "lorry", "semi-truck", "tractor-trailer", "dump truck", "fire truck",
         "fire engine", "garbage truck", "tow truck", "delivery truck", "cement mixer", "tanker",
         "trailer", "tractor", "forklift", "excavator", "bulldozer", "crane", "road roller",
         "street sweeper", "snowplough", "traffic cone", "cone", "barrier", "road barrier",
         "guardrail", "traffic barrel")
    ),
}  # fmt: skip
"""Per class set, the out-of-class words (singular) its classes cover: left out of its
out-of-class things (the ``vod`` set covers none of :data:`OUT_OF_CLASS`)."""


def nouns_for(phrasing: str, classes: str = "vod") -> tuple[str, ...]:
    """The out-of-class nouns a phrasing stream draws from (``train``, ``heldout`` or ``all``),
    for the class set ``classes`` (its :data:`COVERED` words left out)."""
    covered = COVERED[classes]
    nouns = tuple(e for e in OUT_OF_CLASS if e.split("|")[0] not in covered)
    if phrasing == "all":
        return nouns
    heldout = phrasing == "heldout"
    return tuple(e for e in nouns if (e in HELDOUT_NOUNS) == heldout)


_LETTERS = "abcdefghijklmnopqrstuvwxyz"
_KEYBOARD_RUNS = ("qwerty", "asdf", "zxcv", "hjkl", "uiop", "qwertz", "yxcvb", "poiuy", "lkjh")
_FILLER = (
    "lorem ipsum dolor sit amet",
    "blah blah",
    "test test",
    "hello",
    "hello there",
    "foo bar baz",
    "???",
    "...",
    "asdfgh jkl",
    "abc",
    "xyz",
    "nothing",
    "ok",
    "hmm",
)


def nonsense(rng: np.random.Generator) -> str:
    """Text that names nothing: a keyboard run, made-up words, or filler (lower case)."""
    kind = int(rng.integers(3))
    if kind == 0:
        k = int(rng.integers(1, 4))
        return " ".join(_KEYBOARD_RUNS[int(rng.integers(len(_KEYBOARD_RUNS)))] for _ in range(k))
    if kind == 1:
        words = []
        for _ in range(int(rng.integers(1, 5))):
            n = int(rng.integers(2, 9))
            words.append("".join(_LETTERS[int(rng.integers(26))] for _ in range(n)))
        return " ".join(words)
    return _FILLER[int(rng.integers(len(_FILLER)))]


def article(noun: str) -> str:
    """``a`` or ``an`` before a singular noun (by its first letter)."""
    return "an" if noun[:1] in "aeiou" else "a"
