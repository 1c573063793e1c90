"""Numeric values of the words of a sentence, as extra token features for the referent stage.

A frozen sentence encoder tells "20" from "40" only weakly, and "twenty" from "20" not at all, yet
"beyond 40 metres" and "about twenty metres ahead" must be compared with a candidate's depth. So the
referent stage gets, beside each token's MiniLM features, the value of the number that token belongs
to. This module reads English numerals in general (digits with a decimal point or comma, digits glued
to a unit such as ``10m`` or ``20km/h``, cardinal words up to the thousands, "a half" / "and a half",
"a couple of", "a dozen"); it knows nothing of the sentences our generator writes or of what the
number measures. What a value means (metres, km/h, m/s, a count) is left to the model, which learns it
from the neighbouring tokens.

:func:`number_spans` returns ``(start, end, value)`` character spans; :func:`token_numeric_features`
aligns them with a tokenizer's offsets into a ``(L, NUMERIC_FEATURES)`` array.

**Numbers are bounded where they are read** ("how many cars are within 10^24 m?" once made every
score NaN: a value of 1e24 overflows float32 once squared in the stage's normalisations). Written
powers and exponents (``10^24``, ``10**24``, ``1e300``) and the large number words ("a million",
"a googol") are read as the numbers they are, then each value is bounded by what its unit, the
word right after it, makes it (:func:`number_kind`):

- a distance (``m``, ``metres``, ``km``, ``feet``, ...) beyond :data:`DISTANCE_BOUND` reads as
  that bound, "beyond range": past the sensors' reach (VoD's LiDAR and radar, about 100 m; the
  annotated range ends at 51.2 m), so every candidate lies within it and none beyond it;
- a speed (``km/h``, ``mph``, ``m/s``, "metres per second", ...) beyond :data:`SPEED_BOUND`, in
  its own unit, reads as that bound: faster than anything on a road in any of those units;
- any other number (a count: "the 10000000000 cars") beyond :data:`COUNT_BOUND` reads as that
  bound: more than a scene's candidates (``ReferentConfig.max_candidates``, 40 by default), so a
  count beyond the candidates is the candidates.

A value that is not finite (a digit string past float range) is bounded the same way; no feature
this module returns is NaN or infinite. The text encoder reads the bounded number too
(:func:`bound_numbers`: "within 10^24 m" is tokenised as "within 100 m"), so a bounded prompt
is the prompt of its bound, word for word, and :func:`model.referent.compare.prompt_numbers` bounds
what it reads back again (:data:`MAX_NUMBER`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

NUMERIC_FEATURES = 4
"""Per-token numeric features: is-number flag, value / 10, value / 50, log1p(value) / 4."""

_UNITS = {
    "zero": 0,
    "one": 1,
    "two": 2,
    "three": 3,
    "four": 4,
    "five": 5,
    "six": 6,
    "seven": 7,
    "eight": 8,
    "nine": 9,
    "ten": 10,
    "eleven": 11,
    "twelve": 12,
    "thirteen": 13,
    "fourteen": 14,
    "fifteen": 15,
    "sixteen": 16,
    "seventeen": 17,
    "eighteen": 18,
    "nineteen": 19,
}
_TENS = {
    "twenty": 20,
    "thirty": 30,
    "forty": 40,
    "fourty": 40,
    "fifty": 50,
    "sixty": 60,
    "seventy": 70,
    "eighty": 80,
    "ninety": 90,
}
_SCALES = {
    "hundred": 100,
    "thousand": 1000,
    "million": 10**6,
    "billion": 10**9,
    "trillion": 10**12,
}
_QUANTITIES = {"dozen": 12.0, "couple": 2.0, "half": 0.5, "googol": 1e100}
"""Words that are a number alone or after "a"."""
_WORD = re.compile(r"[A-Za-z]+|\d+(?:[.,]\d+)?(?:[eE][+-]?\d+|[ \t]?(?:\^|\*\*)[ \t]?[+-]?\d+)?")
"""A word, or digits with a decimal part and an exponent (``1e300``, ``10^24``, ``10 ** 24``)."""
_POWER = re.compile(r"[ \t]?(?:\^|\*\*)[ \t]?")

DISTANCE_BOUND = 100.0
"""The largest distance read, in the number's unit (module docstring: "beyond range")."""
SPEED_BOUND = 200.0
"""The largest speed read, in the number's unit."""
COUNT_BOUND = 50.0
"""The largest other number (a count) read."""
MAX_NUMBER = max(DISTANCE_BOUND, SPEED_BOUND, COUNT_BOUND)
"""No value read is larger."""

_SPEED_UNIT = re.compile(
    r"[ \t]*-?[ \t]*(?:km[ \t]*/[ \t]*h|kmh|kph|mph|m[ \t]*/[ \t]*s|mps|"
    r"(?:kilomet(?:er|re)s?|met(?:er|re)s?|miles?)[ \t]+(?:per|an|a)[ \t]+(?:hour|second))\b",
    re.IGNORECASE,
)
_DISTANCE_UNIT = re.compile(
    r"[ \t]*-?[ \t]*(?:m|km|met(?:er|re)s?|kilomet(?:er|re)s?|ft|feet|foot|yards?|miles?)\b",
    re.IGNORECASE,
)


def number_kind(text: str, end: int) -> str:
    """What the number ending at character ``end`` of ``text`` is, by the unit right after it:
    ``"speed"``, ``"distance"`` or ``"count"`` (anything else). (:func:`number_spans` also gives
    a range's first end the kind of its second: "between 60 and 80 m".)"""
    if _SPEED_UNIT.match(text, end):
        return "speed"
    if _DISTANCE_UNIT.match(text, end):
        return "distance"
    return "count"


_RANGE_JOIN = re.compile(r"\s*(?:and|to|or|-|\u2013)\s*", re.IGNORECASE)
"""What joins the two ends of a range ("20 and 35 m", "20 to 35 m", "20-35 m")."""

_BOUNDS = {"speed": SPEED_BOUND, "distance": DISTANCE_BOUND, "count": COUNT_BOUND}


def bounded(value: float, kind: str) -> float:
    """``value`` bounded for a number of ``kind`` (:func:`number_kind`); a value that is not
    finite or is negative is bounded too (at the bound, at 0; NaN reads as the bound)."""
    bound = _BOUNDS[kind]
    if not value <= bound:  # larger, +inf or NaN
        return bound
    return max(value, 0.0)


def _digits_value(word: str) -> float:
    """The value of a digits word: ``20``, ``2,5``, ``1e300``, ``10^24``; inf past float range."""
    word = word.replace(",", ".")
    parts = _POWER.split(word)
    if len(parts) == 2:
        try:
            return float(parts[0]) ** float(parts[1])
        except OverflowError:
            return math.inf
    return float(word)


def _word_value(word: str) -> float | None:
    w = word.lower()
    if w in _UNITS:
        return float(_UNITS[w])
    if w in _TENS:
        return float(_TENS[w])
    return None


def number_spans(text: str) -> list[tuple[int, int, float]]:
    """Numbers in ``text`` as ``(start, end, value)`` character spans, in order, each value
    bounded (:func:`read_numbers` with the bounds applied).
    """
    return [(a, b, bounded(v, kind)) for a, b, v, kind in read_numbers(text)]


def bound_numbers(text: str) -> str:
    """``text`` with each number that its bound changes written as the bound (``"how many cars
    are within 10^24 m?"`` -> ``"how many cars are within 100 m?"``; ``"the 10000000000 cars"``
    -> ``"the 50 cars"``), so that the text encoder reads the number the features carry. Other
    text, numbers within their bounds included, is left as it is."""
    out, last = [], 0
    for a, b, v, kind in read_numbers(text):
        value = bounded(v, kind)
        if value != v:
            out += [text[last:a], f"{value:g}"]
            last = b
    return "".join(out) + text[last:] if out else text


def read_numbers(text: str) -> list[tuple[int, int, float, str]]:
    """Numbers in ``text`` as ``(start, end, value, kind)`` character spans, in order; ``value``
    as written (maybe infinite: not bounded), ``kind`` as :func:`number_kind` says (a range's
    first end takes its second end's kind: "between 60 and 80 m").

    Digits (``20``, ``2.5``, ``2,5``, ``10m``: the digits of a digit-unit word; ``1e300``,
    ``10^24``, ``10**24``) and runs of number words (``twenty five``, ``twenty-five``, ``two and a
    half``, ``two point five``, ``a hundred``, ``a million``, ``half a``, ``a dozen``, ``a couple
    of``, ``a googol``). A lone "a" or "and" is never a number. Each value is bounded by its
    kind (:func:`number_kind`, :func:`bounded`): finite, in ``[0, MAX_NUMBER]``.
    """
    tokens = [(m.start(), m.end(), m.group()) for m in _WORD.finditer(text)]
    spans: list[tuple[int, int, float]] = []
    i = 0
    while i < len(tokens):
        start, end, word = tokens[i]
        low = word.lower()
        if word[0].isdigit():
            value = _digits_value(word)
            j = i + 1
            # "2 and a half"
            if j + 2 < len(tokens) and [t[2].lower() for t in tokens[j : j + 3]] == [
                "and",
                "a",
                "half",
            ]:
                value += 0.5
                end = tokens[j + 2][1]
                j += 3
            spans.append((start, end, value))
            i = j
            continue
        # "dozen" / "a dozen", "couple" / "a couple", "half" / "a half"
        quantity = low if low in _QUANTITIES else None
        if low == "a" and i + 1 < len(tokens) and tokens[i + 1][2].lower() in _QUANTITIES:
            quantity = tokens[i + 1][2].lower()
        if quantity is not None:
            j = i + 1 if low == quantity else i + 2
            spans.append((start, tokens[j - 1][1], _QUANTITIES[quantity]))
            i = j
            continue
        value_of_first = _word_value(low)
        if value_of_first is None and not (
            low == "a" and i + 1 < len(tokens) and tokens[i + 1][2].lower() in _SCALES
        ):
            i += 1
            continue
        total, current = 0.0, value_of_first if value_of_first is not None else 1.0
        j = i + 1
        last_end = end
        while j < len(tokens):
            nxt = tokens[j][2].lower()
            v = _word_value(nxt)
            if v is not None and v < 10 and current >= 20 and current % 10 == 0:
                current += v
            elif nxt in _SCALES:
                current *= _SCALES[nxt]
                if _SCALES[nxt] >= 1000:
                    total, current = total + current, 0.0
            elif (
                nxt == "and"
                and j + 2 < len(tokens)
                and [t[2].lower() for t in tokens[j + 1 : j + 3]] == ["a", "half"]
            ):
                current += 0.5
                last_end = tokens[j + 2][1]
                j += 3
                break
            elif (
                nxt == "point"
                and j + 1 < len(tokens)
                and (_word_value(tokens[j + 1][2]) or 10.0) < 10
            ):
                # "two point five": one decimal digit after "point".
                current += float(_word_value(tokens[j + 1][2]) or 0.0) / 10.0
                last_end = tokens[j + 1][1]
                j += 2
                break
            elif nxt == "and" and j + 1 < len(tokens) and _word_value(tokens[j + 1][2]) is not None:
                j += 1
                continue
            else:
                break
            last_end = tokens[j][1]
            j += 1
        spans.append((start, last_end, total + current))
        i = j
    kinds = [number_kind(text, b) for _, b, _ in spans]
    for k in range(len(spans) - 2, -1, -1):  # "between 60 and 80 m": 60 is in metres too
        if kinds[k] == "count" and _RANGE_JOIN.fullmatch(text, spans[k][1], spans[k + 1][0]):
            kinds[k] = kinds[k + 1]
    return [(a, b, v, kind) for (a, b, v), kind in zip(spans, kinds, strict=True)]


def numeric_vector(value: float | None) -> np.ndarray:
    """The :data:`NUMERIC_FEATURES` features of one token (zeros for a non-number)."""
    if value is None:
        return np.zeros(NUMERIC_FEATURES, dtype=np.float32)
    v = float(value)
    v = MAX_NUMBER if not v <= MAX_NUMBER else max(v, 0.0)  # NaN and inf too
    return np.array([1.0, v / 10.0, v / 50.0, math.log1p(v) / 4.0], dtype=np.float32)


def token_numeric_features(
    text: str, offsets: Sequence[tuple[int, int]], length: int | None = None
) -> np.ndarray:
    """Numeric features aligned with a tokenizer's character offsets.

    Args:
        text: The sentence the offsets index into.
        offsets: ``(start, end)`` per token; special tokens have ``(0, 0)``.
        length: Rows of the output (default ``len(offsets)``); extra rows stay zero.

    Returns:
        ``(length, NUMERIC_FEATURES)`` float32; a token overlapping a number span gets its value.
    """
    n = len(offsets) if length is None else int(length)
    out = np.zeros((n, NUMERIC_FEATURES), dtype=np.float32)
    spans = number_spans(text)
    if not spans:
        return out
    for t, (s, e) in enumerate(offsets[:n]):
        if e <= s:
            continue
        for a, b, value in spans:
            if s < b and e > a:
                out[t] = numeric_vector(value)
                break
    return out


__all__ = [
    "COUNT_BOUND",
    "DISTANCE_BOUND",
    "MAX_NUMBER",
    "NUMERIC_FEATURES",
    "SPEED_BOUND",
    "bound_numbers",
    "bounded",
    "number_kind",
    "number_spans",
    "numeric_vector",
    "read_numbers",
    "token_numeric_features",
]
