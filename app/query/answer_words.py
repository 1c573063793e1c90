"""The answer said in words, above the Query tab's table of boxes.

A grounding model that boxes something for every sentence looks as if it understood every
sentence. The app says what it found instead: how many objects of which classes, the count
itself when the prompt asks "how many", and, when nothing is boxed, that nothing here matches
and which kinds of object the model can find at all, worded from the served checkpoint's own
class set (so "the bus" is answered honestly by a ``vod`` model, "the tram" by any).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

from scenes.geometry.classes import VOD, ClassSet, object_class
from scenes.language.prompts import is_count_question


def _noun(cls: str, count: int) -> str:
    """The class's word (:attr:`scenes.geometry.classes.ObjectClass.noun` or ``plural``); an
    unknown name as it is."""
    try:
        found = object_class(cls)
    except ValueError:
        return cls
    return found.noun if count == 1 else found.plural


def _join(parts: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    if len(parts) <= 1:
        return "".join(parts)
    return ", ".join(parts[:-1]) + " and " + parts[-1]


def answer_sentence(prompt: str, classes: Sequence[str], known: ClassSet = VOD) -> str:
    """One sentence for an answer of boxes of ``classes`` (one entry per box, in score order) to
    ``prompt``; ``known``: the class set the model finds (the empty answer names its plurals:
    "I find cars, pedestrians and cyclists"). Plain text (no markup)."""
    if not classes:
        return f"No object here matches; I find {known.plural_list()}."
    counts = Counter(classes)
    parts = [f"{k} {_noun(c, k)}" for c, k in sorted(counts.items(), key=lambda x: -x[1])]
    n = len(classes)
    if is_count_question(prompt):
        return f"{n}: {_join(parts)} (boxed)."
    verb = "matches" if n == 1 else "match"
    return f"{_join(parts)} {verb}."


__all__ = ["answer_sentence"]
