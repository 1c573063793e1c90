"""Commands the way people say them to a driver, around a single-referent description.

The generator's commands (:mod:`scenes.language.prompts.commands`) wrap a description in one
instruction. People also (issue 49):

- put the manoeuvre's preposition before the referent ("park behind ...", "pull over before
  ...", "move around ..."), which says what to do, not where the referent is;
- name what no sensor here observes: a colour or a make ("the silver car"), clothes ("the man in
  the red jacket");
- use their own words for the class ("van", "taxi", "guy", "lorry", "scooter");
- give context first, in another sentence, and point back with a pronoun ("my friend is in the
  car on the left. stop next to it.").

:func:`people_command` writes such a command about the description's referent, from templates
of this module's own (:data:`PEOPLE_SLOTS`) and a dressing of the noun phrase (:func:`dress`):
a people's word for the class (:data:`scenes.language.words.CLASS_WORDS`, less the generator's
own nouns), a colour before a vehicle's noun, clothes after a person's. None of it changes the
referent: the description's words that select it are all kept.

Train / held-out (``PromptConfig.phrasing``): the templates split by
:func:`scenes.language.prompts.phrasing.split.split_variants` (the ``core`` ones always ``train``, a
third of the ``more`` ones held out); the people's words and the colours by the same CRC-32 rule
(:func:`heldout_word`): a ``train`` stream never writes a held-out word or template, a
``heldout`` stream only held-out ones where it has any. The reader of such sentences is
:mod:`scenes.language.reading`; its tests and ``model.evaluate`` on a root written with
``scenes.synth --command-share 1 --people-share 1 --phrasing heldout`` measure it.
"""

from __future__ import annotations

import re
import zlib

import numpy as np

from scenes.language.phrases import find_mentions
from scenes.language.prompts.phrasing.slots import Slot
from scenes.language.prompts.phrasing.split import PHRASINGS, split_variants, variant_id
from scenes.language.words import CLASS_WORDS, generator_nouns, lexicon

S = Slot
# fmt: off
PEOPLE_SLOTS: dict[str, Slot] = {
    "people/any": S(
        ("park behind {np}", "pull over before {np}", "move around {np}", "stay behind {np}",
         "please stop right next to {np}", "ok, pull up beside {np}"),
        ("could you get us behind {np}, please", "squeeze in behind {np}",
         "go around {np} and carry on", "drive up next to {np} and stop",
         "hang on, pull over just before {np}", "keep going until we reach {np}",
         "slowly pass {np}", "let's stop beside {np}", "we should park close to {np}"),
    ),
    "people/context": S(
        ("{np} is the one we want. follow {it}.", "see {np}? park behind {it}.",
         "{np} is where we stop. pull over next to {it}."),
        ("look at {np}. stay behind {it}.", "i know {np}. stop close to {it}.",
         "there is {np}. go around {it} carefully.", "{np} is in the way. move around {it}."),
    ),
    "people/person": S(
        ("that is my uncle, {np}. pull over next to {it}.", "my friend is {np}. stop for {it}."),
        ("oh, {np} is my neighbour. pick {it} up.", "my sister is {np}. wait for {it}.",
         "{np} needs a ride. stop beside {it}."),
    ),
}
# fmt: on
"""People's command templates by where they fit: ``{np}`` the referent's noun phrase (dressed),
``{it}`` its pronoun ("it", "him"); ``people/person`` only for a pedestrian."""

PEOPLE_TRAIN, PEOPLE_HELDOUT = split_variants(PEOPLE_SLOTS)
"""Ids of the ``train`` and ``heldout`` templates; disjoint."""

COLOURS = ("silver", "white", "black", "grey", "red", "blue", "dark green", "yellow", "beige")
"""Colours said of a vehicle (no sensor here sees them)."""
CLOTHES = (
    "in the red jacket", "wearing a grey coat", "with the blue backpack", "in a white shirt",
    "wearing a black hat", "in the yellow vest", "with an umbrella",
)  # fmt: skip
"""What is said after a person's noun (no sensor here sees it)."""
PERSON_CLASSES = frozenset({"Pedestrian"})
_PRONOUN = {"Pedestrian": "them", "Cyclist": "them", "Motorcycle": "it", "Bicycle": "them"}


def heldout_word(word: str) -> bool:
    """Whether a people's word or a dressing is held out of ``train`` (a third, by CRC-32)."""
    return zlib.crc32(word.encode()) % 3 == 0


def _split(items: tuple[str, ...], phrasing: str) -> tuple[str, ...]:
    if phrasing == "train":
        return tuple(w for w in items if not heldout_word(w))
    if phrasing == "heldout":
        return tuple(w for w in items if heldout_word(w)) or items
    return items


def people_words(cls: str, class_set: str, phrasing: str) -> tuple[str, ...]:
    """Singular words people use for ``cls`` that the generator never writes and that name
    ``cls`` alone in ``class_set`` (a "bike" may be a motorcycle too: not used)."""
    known = generator_nouns(class_set)
    table = lexicon()
    words = []
    for pair in CLASS_WORDS.get(cls, ()):
        word = pair.split("|")[0]
        classes = table[word][0]
        if word in known or len([c for c in classes if c != cls]) > 0:
            continue
        words.append(word)
    return _split(tuple(words), phrasing)


def dress(phrase: str, cls: str, class_set: str, rng: np.random.Generator, phrasing: str) -> str:
    """The noun phrase with its noun said in a people's word (half the time) and a colour before
    a vehicle's noun or clothes after a person's (half the time each); ``phrase`` unchanged
    where its noun is not found."""
    toks = phrase.split()
    found = find_mentions([[t.lower() for t in toks]])
    if not found or found[0].pronoun or cls not in found[0].classes:
        return phrase  # the referent's noun is not a road-user word ("the object ..."): as is
    start, end = found[0].start, found[0].end
    words = people_words(cls, class_set, phrasing)
    if words and rng.random() < 0.5:
        toks[start:end] = [words[int(rng.integers(len(words)))]]
        end = start + 1
    if cls in PERSON_CLASSES:
        if rng.random() < 0.5:
            clothes = _split(CLOTHES, phrasing)
            toks.insert(end, clothes[int(rng.integers(len(clothes)))])
    elif rng.random() < 0.5:
        colours = _split(COLOURS, phrasing)
        toks.insert(start, colours[int(rng.integers(len(colours)))])
    return " ".join(toks)


def people_templates(phrasing: str, cls: str | None) -> tuple[tuple[str, str], ...]:
    """``(variant id, template)`` a ``phrasing`` stream draws for a referent of ``cls``."""
    if phrasing not in PHRASINGS:
        raise ValueError(f"phrasing must be one of {PHRASINGS}, got {phrasing!r}")
    names = ["people/any", "people/context"] + (["people/person"] if cls in PERSON_CLASSES else [])
    pairs = tuple(
        (variant_id(n, t), t) for n in names for t in (*PEOPLE_SLOTS[n].core, *PEOPLE_SLOTS[n].more)
    )
    if phrasing == "train":
        return tuple(p for p in pairs if p[0] in PEOPLE_TRAIN)
    if phrasing == "heldout":
        return tuple(p for p in pairs if p[0] in PEOPLE_HELDOUT) or pairs
    return pairs


def people_command(
    phrase: str,
    cls: str,
    class_set: str,
    rng: np.random.Generator,
    phrasing: str = "train",
) -> tuple[str, str]:
    """``(command, template id)``: a people's command about the referent of the noun phrase
    ``phrase`` ("the parked car on the left"), of class ``cls``."""
    pairs = people_templates(phrasing, cls)
    vid, template = pairs[int(rng.integers(len(pairs)))]
    dressed = dress(phrase, cls, class_set, rng, phrasing)
    text = template.replace("{np}", dressed).replace("{it}", _PRONOUN.get(cls, "it"))
    text = re.sub(r"(^|[.?] )([a-z])", lambda m: m.group(1) + m.group(2).upper(), text)
    return text, vid


__all__ = [
    "PEOPLE_HELDOUT",
    "PEOPLE_SLOTS",
    "PEOPLE_TRAIN",
    "dress",
    "heldout_word",
    "people_command",
    "people_templates",
    "people_words",
]
