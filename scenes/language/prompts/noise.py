"""Text-side regularisation for training: :func:`perturb` rewrites a prompt, its meaning kept.

Operations, each word at a time (the rates are arguments):

* dropout of meaning-free words only (:data:`DROPPABLE`: articles, "please", "that", "is", ...;
  "a" / "an" after "half" are kept, they are part of a number);
* synonym swaps with the same meaning and grammar (:data:`SYNONYMS`: closest / nearest, metres /
  meters, car / automobile, ...; not after "ego", "our", "my", whose noun names the ego vehicle);
* a character typo (swap two neighbours, drop or double a letter) in an alphabetic word of at
  least 5 letters that is not a meaning word;
* whole-sentence casing (lower, upper, sentence, title) and end punctuation (none, ".", "?", "!").

Meaning words are never dropped, swapped or misspelt (:func:`is_meaning_word`): negators ("not",
"no", "isn't", "never", "without"), exclusion words ("except", "but", "besides", "other",
"apart", "excluding"), numbers in digits or words (and "half", "point", "and"), ordinals,
counting words ("how", "many", "count", "number"), left / right, and units.
"""

from __future__ import annotations

import re

import numpy as np

from scenes.language.prompts.numbers import NUMBER_WORDS

DROPPABLE = frozenset(
    {"the", "a", "an", "please", "that", "which", "is", "are", "just", "exactly", "hey", "really"}
)
"""Words :func:`perturb` may drop."""

SYNONYMS: dict[str, str] = {
    "closest": "nearest",
    "nearest": "closest",
    "farthest": "furthest",
    "furthest": "farthest",
    "metres": "meters",
    "meters": "metres",
    "metre": "meter",
    "meter": "metre",
    "towards": "toward",
    "toward": "towards",
    "car": "automobile",
    "cars": "automobiles",
    "automobile": "car",
    "automobiles": "cars",
    "pedestrian": "person",
    "cyclist": "bicyclist",
    "cyclists": "bicyclists",
    "bike": "bicycle",
    "bikes": "bicycles",
    "stationary": "static",
    "static": "stationary",
    "road": "street",
    "street": "road",
    "roughly": "approximately",
    "approximately": "roughly",
    "highlight": "show",
    "locate": "find",
    "find": "locate",
    "beyond": "past",
}
"""One-word swaps :func:`perturb` may make (same meaning, same grammar)."""

_NUMBER_WORDS = [*sorted(NUMBER_WORDS), "half", "point", "and", "both"]
_MEANING = frozenset(
    [
        *_NUMBER_WORDS,
        "not",
        "no",
        "never",
        "without",
        "none",
        "nothing",
        "except",
        "but",
        "besides",
        "other",
        "than",
        "apart",
        "excluding",
        "first",
        "second",
        "third",
        "fourth",
        "fifth",
        "last",
        "next-to-nearest",
        "next-to-farthest",
        "2nd",
        "3rd",
        "4th",
        "how",
        "many",
        "count",
        "number",
        "left",
        "right",
        "m",
        "km/h",
        "m/s",
        "kph",
        "kmh",
        "mps",
    ]
)
_NEGATED = re.compile(r"n't$")
_DIGIT = re.compile(r"\d")
_EGO_BEFORE = frozenset({"ego", "our", "my"})
_CORE = re.compile(r"^(\W*)(.*?)(\W*)$", re.DOTALL)


def is_meaning_word(word: str) -> bool:
    """Whether a word (punctuation around it ignored) carries meaning :func:`perturb` must keep."""
    w = _CORE.match(word.lower()).group(2)  # type: ignore[union-attr]
    return (
        w in _MEANING
        or bool(_DIGIT.search(w))
        or bool(_NEGATED.search(w))
        or any(p in _MEANING for p in w.split("-"))
        or w.startswith(("left", "right"))
    )


def _typo(word: str, rng: np.random.Generator) -> str:
    i = int(rng.integers(1, len(word) - 1))
    kind = int(rng.integers(3))
    if kind == 0:
        return word[:i] + word[i + 1] + word[i] + word[i + 2 :]
    if kind == 1:
        return word[:i] + word[i + 1 :]
    return word[:i] + word[i] + word[i:]


def _restyle(text: str, rng: np.random.Generator) -> str:
    kind = int(rng.integers(4))
    if kind == 0:
        return text.lower()
    if kind == 1:
        return text.upper()
    if kind == 2:
        return text[:1].upper() + text[1:]
    return " ".join(w[:1].upper() + w[1:] for w in text.split(" "))


def perturb(
    text: str,
    rng: np.random.Generator,
    *,
    p_drop: float = 0.1,
    p_synonym: float = 0.15,
    p_typo: float = 0.03,
    p_case: float = 0.2,
    p_punct: float = 0.2,
) -> str:
    """``text`` with meaning-free words dropped, synonyms swapped, typos, other casing and end
    punctuation (module docstring); never an empty string (the text comes back when every word
    would go). Deterministic for a given ``rng`` state."""
    words = text.split()
    out: list[str] = []
    for k, word in enumerate(words):
        lead, core, trail = _CORE.match(word).groups()  # type: ignore[union-attr]
        low = core.lower()
        prev = words[k - 1].lower().strip(",.!?;:") if k else ""
        if is_meaning_word(word) or not core:
            out.append(word)
            continue
        if (
            low in DROPPABLE
            and rng.random() < p_drop
            and not (prev == "half" and low in ("a", "an"))
        ):
            continue
        if low in SYNONYMS and prev not in _EGO_BEFORE and rng.random() < p_synonym:
            new = SYNONYMS[low]
            core = new.upper() if core.isupper() and len(core) > 1 else new
        elif core.isalpha() and len(core) >= 5 and rng.random() < p_typo:
            core = _typo(core, rng)
        out.append(lead + core + trail)
    if not out:
        return text
    result = " ".join(out)
    if rng.random() < p_case:
        result = _restyle(result, rng)
    if rng.random() < p_punct:
        result = result.rstrip(".!?") + (("", ".", "?", "!")[int(rng.integers(4))])
    return result if result.strip() else text
