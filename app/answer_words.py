"""The answer said in words, above the Query tab's table of boxes.

A grounding model that boxes something for every sentence looks as if it understood every
sentence. The app says what it found instead: how many objects of which classes, the count
itself when the prompt asks "how many", and, when nothing is boxed, that nothing here matches
and which kinds of object the model can find at all (so "the bus" is answered honestly).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

from scenes.geometry.actors import CLASSES
from scenes.language.prompts import is_count_question

CLASS_WORDS: dict[str, tuple[str, str]] = {
    "Car": ("car", "cars"),
    "Pedestrian": ("pedestrian", "pedestrians"),
    "Cyclist": ("cyclist", "cyclists"),
}
"""Class name -> (singular, plural) as the answer says it."""


def _noun(cls: str, count: int) -> str:
    one, many = CLASS_WORDS.get(cls, (cls, cls))
    return one if count == 1 else many


def _join(parts: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    if len(parts) <= 1:
        return "".join(parts)
    return ", ".join(parts[:-1]) + " and " + parts[-1]


def answer_sentence(prompt: str, classes: Sequence[str], known: Sequence[str] = CLASSES) -> str:
    """One sentence for an answer of boxes of ``classes`` (one entry per box, in score order) to
    ``prompt``; ``known``: the classes the model finds. Plain text (no markup)."""
    if not classes:
        kinds = _join([_noun(c, 2) for c in known])
        return f"No object here matches; I find {kinds}."
    counts = Counter(classes)
    parts = [f"{k} {_noun(c, k)}" for c, k in sorted(counts.items(), key=lambda x: -x[1])]
    n = len(classes)
    if is_count_question(prompt):
        return f"{n}: {_join(parts)} (boxed)."
    verb = "matches" if n == 1 else "match"
    return f"{_join(parts)} {verb}."


__all__ = ["CLASS_WORDS", "answer_sentence"]
