"""Command phrasing: a driving instruction wrapped around a single-referent description.

Talk2Car's sentences are instructions to a driver ("pull over behind the cyclist on the right",
"wait for the pedestrian to cross", "follow that car"). :func:`command_text` wraps a description's
noun phrase ("the parked car on the left") in such an instruction ("Park next to the parked car on
the left."); the referent is the description's, exactly: a command never narrows or widens the
set (it is only made of single-referent descriptions, and its template adds no attribute of the
object). :func:`as_command` does the same to any description text (a generated prompt with its
frame, casing and punctuation: "Show me the car on the left." -> "follow the car on the left").

Templates (:data:`COMMAND_SLOTS`) fill ``{np}`` (the description's noun phrase) and ``{it}`` (its
pronoun: "it" for a car, "them" for a person or a rider). Each slot says where its templates fit:
``command/any`` fits every referent; ``command/moving`` / ``command/stationary`` one in motion or
not (ground speed above :data:`scenes.geometry.actors.MOVING_SPEED`); ``command/<class>`` and
``command/<class>_moving`` / ``_stationary`` one class ("wait for {np} to cross" is the
pedestrian's); ``command/road_vehicle_moving`` a moving car or cyclist ("overtake {np}"). With the
class or the motion unknown (``None``) only the slots that do not need it are used, and ``{it}``
templates only where the class is known.

Train / held-out (``PromptConfig.phrasing``): the split rule of
:mod:`scenes.language.prompts.phrasing` (:func:`~scenes.language.prompts.phrasing.split.split_variants`)
applied to :data:`COMMAND_SLOTS`, whose one group is ``command``: the ``core`` templates are always
``train``, a third of the ``more`` ones (ranked by CRC-32) are ``heldout``. A ``train`` stream never
draws a held-out template; a ``heldout`` stream draws only held-out ones where the referent admits
one; ``all`` draws from every template.
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from scenes.geometry.actors import MOVING_SPEED, Actor
from scenes.language.prompts.people import people_command
from scenes.language.prompts.phrasing.extra import EXTRA
from scenes.language.prompts.phrasing.slots import SLOTS, Slot
from scenes.language.prompts.phrasing.split import PHRASINGS, split_variants, variant_id
from scenes.language.prompts.render import Prompt

S = Slot
# fmt: off
COMMAND_SLOTS: dict[str, Slot] = {
    "command/any": S(
        ("follow {np}", "stop behind {np}", "keep a safe distance from {np}",
         "watch out for {np}", "slow down for {np}", "yield to {np}", "pull over behind {np}",
         "park next to {np}"),
        ("keep an eye on {np}", "be careful with {np}", "give way to {np}",
         "stay clear of {np}", "don't hit {np}", "drive carefully around {np}",
         "turn left after {np}", "turn right after {np}", "pull up next to {np}",
         "stop next to {np}", "keep your distance from {np}", "keep a distance from {np}",
         "park behind {np}", "mind {np}", "brake for {np}", "pull in behind {np}",
         "watch {np} carefully", "keep clear of {np}", "stay away from {np}",
         "be aware of {np}"),
    ),
    "command/moving": S(
        ("let {np} pass", "follow {np} for a while", "wait until {np} has passed"),
        ("let {np} go first", "let {np} pass while continuing straight", "keep pace with {np}",
         "stay behind {np}", "don't overtake {np}", "match the speed of {np}",
         "give {np} priority", "wait for {np} to go by", "hang back behind {np}"),
    ),
    "command/stationary": S(
        ("park behind {np}", "pull over in front of {np}", "drive around {np}"),
        ("stop beside {np}", "go around {np}", "park in front of {np}",
         "pull over just past {np}", "squeeze past {np} carefully"),
    ),
    "command/car": S(
        ("park next to {np}", "get in line behind {np}"),
        ("pull in next to {np}", "park right behind {np}", "find a spot near {np} and park",
         "stop next to {np} and let me out", "drop me off next to {np}"),
    ),
    "command/car_moving": S(
        ("follow {np} until the next junction", "tail {np}"),
        ("stick behind {np}", "drive after {np}", "follow {np}, but not too closely",
         "keep following {np}"),
    ),
    "command/car_stationary": S(
        ("park behind {np} and wait",),
        ("pull up behind {np}", "take the spot next to {np}", "overtake {np} carefully"),
    ),
    "command/pedestrian": S(
        ("wait for {np} to cross", "stop for {np}", "let {np} cross the street"),
        ("give {np} some room", "let {np} cross first", "wait until {np} has crossed",
         "stop and let {np} walk by", "pick up {np}", "stop next to {np} so {it} can get in",
         "slow down, there is {np}", "be careful, {np} might step onto the road"),
    ),
    "command/pedestrian_moving": S(
        ("let {np} walk past",),
        ("wait for {np} to get out of the way", "don't drive until {np} is gone"),
    ),
    "command/cyclist": S(
        ("give {np} plenty of room", "pass {np} carefully"),
        ("leave space for {np}", "watch out, there is {np}", "don't cut off {np}",
         "stay well clear of {np}"),
    ),
    "command/cyclist_moving": S(
        ("stay behind {np} until it is safe to pass",),
        ("slow down and follow {np}", "let {np} ride on first"),
    ),
    # the nuscenes class set's road users: core only, texts new to the group, so the vod
    # classes' train / held-out split does not move
    "command/truck": S(("keep a safe distance from {np}",)),
    "command/bus": S(("give {np} some space",)),
    "command/bus_stationary": S(("let {np} pull out",)),
    "command/motorcycle_moving": S(("let {np} get ahead",)),
    "command/traffic_cone": S(("steer around {np}", "slow down near {np}")),
    "command/barrier": S(("steer around {np}", "slow down near {np}")),
    "command/road_vehicle_moving": S(
        ("overtake {np}", "pass {np}"),
        ("get past {np}", "overtake {np} when it is safe", "change lanes to get around {np}",
         "go around {np} on the other side"),
    ),
}
# fmt: on
"""The command templates by where they fit (module docstring)."""

COMMAND_TRAIN, COMMAND_HELDOUT = split_variants(COMMAND_SLOTS)
"""Ids (``command:text``) of the ``train`` and ``heldout`` command templates; disjoint."""

_PRONOUN = {
    "Car": "it",
    "Pedestrian": "them",
    "Cyclist": "them",
    **{c: "it" for c in ("Truck", "Bus", "Trailer", "ConstructionVehicle", "Motorcycle")},
    **{c: "it" for c in ("Bicycle", "TrafficCone", "Barrier")},
}
_CLASS_KEY = {
    "Car": "car",
    "Pedestrian": "pedestrian",
    "Cyclist": "cyclist",
    "Truck": "truck",
    "Bus": "bus",
    "TrafficCone": "traffic_cone",
    "Barrier": "barrier",
    "Motorcycle": "motorcycle",
}
PEOPLE_FAMILIES = ("attribute", "ordinal", "relation")
"""The families whose single-referent descriptions are one singular noun phrase, which a
people's command can point back to with "it" (not "all cars but not ...")."""
_ROAD_VEHICLES = ("Car", "Cyclist", "Truck", "Bus", "Motorcycle", "Bicycle")
"""Classes a moving one of which can be overtaken ("overtake {np}")."""


def command_slots(cls: str | None, moving: bool | None) -> tuple[str, ...]:
    """The slots of :data:`COMMAND_SLOTS` that fit a referent of class ``cls`` (None: unknown)
    that is ``moving`` or not (None: unknown)."""
    names = ["command/any"]
    if moving is not None:
        names.append("command/moving" if moving else "command/stationary")
    key = _CLASS_KEY.get(cls) if cls is not None else None
    if key is not None:
        names.append(f"command/{key}")
        if moving is not None:
            names.append(f"command/{key}_{'moving' if moving else 'stationary'}")
        if moving and cls in _ROAD_VEHICLES:
            names.append("command/road_vehicle_moving")
    return tuple(n for n in names if n in COMMAND_SLOTS)


def command_templates(
    phrasing: str, cls: str | None = None, moving: bool | None = None
) -> tuple[tuple[str, str], ...]:
    """``(variant id, template)`` a ``phrasing`` stream draws for such a referent (module
    docstring; ``heldout`` falls back to every template when none held out fits).

    Raises:
        ValueError: ``phrasing`` is not one of :data:`~scenes.language.prompts.phrasing.split.PHRASINGS`.
    """
    if phrasing not in PHRASINGS:
        raise ValueError(f"phrasing must be one of {PHRASINGS}, got {phrasing!r}")
    out: dict[str, str] = {}
    for name in command_slots(cls, moving):
        slot = COMMAND_SLOTS[name]
        for text in slot.core + slot.more:
            if "{it}" in text and cls not in _PRONOUN:
                continue
            out.setdefault(variant_id(name, text), text)
    pairs = tuple(out.items())
    if phrasing == "train":
        return tuple(p for p in pairs if p[0] in COMMAND_TRAIN)
    if phrasing == "heldout":
        held = tuple(p for p in pairs if p[0] in COMMAND_HELDOUT)
        return held or pairs
    return pairs


# ---- the description's noun phrase -------------------------------------------------------------


def _frame_pattern(template: str) -> re.Pattern[str]:
    body = re.escape(template.rstrip("?")).replace(re.escape("{np}"), "(?P<np>.+?)")
    body = body.replace(re.escape("{be}"), "(?:is|are)")
    return re.compile(rf"^{body}$")


_FRAMES = tuple(
    _frame_pattern(t)
    for t in dict.fromkeys((*SLOTS["frame"].core, *SLOTS["frame"].more, *EXTRA.get("frame", ())))
    if t.rstrip("?") != "{np}"
)
_END = re.compile(r"[\s.!?,;]+$")


def noun_phrase_of(description: str) -> str:
    """The noun phrase of a description: its end punctuation, casing (upper or title case is
    lowered; a sentence-case first letter too) and any command or question frame of the
    generator's ("show me ...", "where is ...?", "... please") taken off. A description the
    frames do not fit is returned lowered at its first letter, as is."""
    text = _END.sub("", description.strip())
    words = text.split()
    if text.isupper() or (
        len(words) > 1 and all(w[:1].isupper() for w in words if w[:1].isalpha())
    ):
        text = text.lower()
    elif text[:1].isupper() and not text[1:2].isupper():
        text = text[:1].lower() + text[1:]
    for pattern in _FRAMES:
        m = pattern.match(text)
        if m is not None:
            return m.group("np").strip()
    return text


# ---- commands -----------------------------------------------------------------------------------


def command_text(
    noun_phrase: str,
    template: str,
    cls: str | None,
    rng: np.random.Generator,
) -> str:
    """``template`` filled with ``noun_phrase`` (and ``{it}``: ``cls``'s pronoun), its first
    letter capitalised and a period added, each with probability 1/2 (Talk2Car's commands come
    both ways)."""
    text = template.replace("{np}", noun_phrase).replace("{it}", _PRONOUN.get(cls or "", "it"))
    if rng.random() < 0.5:
        text = text[:1].upper() + text[1:]
    if rng.random() < 0.5:
        text += "."
    return text


def draw_command(
    description: str,
    rng: np.random.Generator,
    phrasing: str = "train",
    *,
    cls: str | None = None,
    moving: bool | None = None,
    max_words: int | None = None,
) -> tuple[str, str] | None:
    """``(command text, template id)`` wrapping ``description`` (:func:`as_command`); None when
    every one of a few draws runs past ``max_words`` words (None: no bound)."""
    pairs = command_templates(phrasing, cls, moving)
    np_text = noun_phrase_of(description)
    for _ in range(4):
        vid, template = pairs[int(rng.integers(len(pairs)))]
        text = command_text(np_text, template, cls, rng)
        if max_words is None or len(text.split()) <= max_words:
            return text, vid
    return None


def as_command(
    prompt: str,
    rng: np.random.Generator,
    phrasing: str = "train",
    *,
    cls: str | None = None,
    moving: bool | None = None,
) -> str:
    """A single-referent description (``prompt``: "The parked car on the left.", "show me the
    cyclist", "where is the pedestrian?") phrased as a driving command ("park behind the parked car
    on the left"), referring to the same object.

    Args:
        prompt: The description; it must refer to exactly one object (the command says "the ...").
        rng: Draws the template and the casing; deterministic for a given state.
        phrasing: ``train``, ``heldout`` or ``all`` (module docstring).
        cls: The referent's class (``Car``, ``Pedestrian``, ``Cyclist``) where known: class-
            specific templates ("wait for ... to cross" only for a pedestrian). None: templates
            that fit any class.
        moving: Whether the referent moves (ground speed above ``MOVING_SPEED``) where known.

    Raises:
        ValueError: an empty ``prompt`` or an unknown ``phrasing``.
    """
    if not prompt.strip():
        raise ValueError("as_command: empty prompt")
    drawn = draw_command(prompt, rng, phrasing, cls=cls, moving=moving)
    assert drawn is not None  # no word bound
    return drawn[0]


def is_moving(actor: Actor) -> bool:
    """Whether an actor moves: ground speed above :data:`scenes.geometry.actors.MOVING_SPEED`."""
    return float(np.hypot(*actor.velocity[:2])) > MOVING_SPEED


def commands_for(
    prompts: list[Prompt],
    actors: dict[int, Actor],
    rng: np.random.Generator,
    share: float,
    phrasing: str,
    max_words: int,
    people_share: float = 0.0,
    classes: str = "vod",
) -> list[Prompt]:
    """``prompts`` with a ``share`` of the single-referent ones (not counting questions) phrased
    as commands about their referent (:func:`draw_command`; the template's id appended to
    :attr:`Prompt.variants`); referents, tags, predicate and family kept. A prompt whose referent
    is not in ``actors`` is kept as it is. ``people_share`` of the commands are said the way
    people say them (:func:`scenes.language.prompts.people.people_command`: manoeuvre first,
    colours and clothes, people's words, context first; ``classes``: the class set's name); 0
    draws nothing, so the commands are those without the option."""
    out = []
    for p in prompts:
        if len(p.referent_ids) != 1 or p.family == "count" or rng.random() >= share:
            out.append(p)
            continue
        actor = actors.get(p.referent_ids[0])
        if actor is None:  # its motion unknown (generate_prompts' unknown_motion)
            out.append(p)
            continue
        if people_share > 0.0 and rng.random() < people_share and p.family in PEOPLE_FAMILIES:
            text, vid = people_command(noun_phrase_of(p.text), actor.cls, classes, rng, phrasing)
            out.append(replace(p, text=text, variants=(*p.variants, vid)))
            continue
        drawn = draw_command(
            p.text, rng, phrasing, cls=actor.cls, moving=is_moving(actor), max_words=max_words
        )
        if drawn is None:
            out.append(p)
            continue
        text, vid = drawn
        out.append(replace(p, text=text, variants=(*p.variants, vid)))
    return out


__all__ = [
    "COMMAND_HELDOUT",
    "COMMAND_SLOTS",
    "COMMAND_TRAIN",
    "as_command",
    "command_slots",
    "command_templates",
    "command_text",
    "commands_for",
    "draw_command",
    "noun_phrase_of",
]
