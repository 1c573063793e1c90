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
_SCALES = {"hundred": 100, "thousand": 1000}
_QUANTITIES = {"dozen": 12.0, "couple": 2.0, "half": 0.5}
"""Words that are a number alone or after "a"."""
_WORD = re.compile(r"[A-Za-z]+|\d+(?:[.,]\d+)?")


def _word_value(word: str) -> float | None:
    w = word.lower()
    if w in _UNITS:
        return float(_UNITS[w])
    if w in _TENS:
        return float(_TENS[w])
    return None


def number_spans(text: str) -> list[tuple[int, int, float]]:
    """Numbers in ``text`` as ``(start, end, value)`` character spans, in order.

    Digits (``20``, ``2.5``, ``2,5``, ``10m``: the digits of a digit-unit word) and runs of number
    words (``twenty five``, ``twenty-five``, ``two and a half``, ``two point five``, ``a hundred``,
    ``half a``, ``a dozen``, ``a couple of``). A lone "a" or "and" is never a number.
    """
    tokens = [(m.start(), m.end(), m.group()) for m in _WORD.finditer(text)]
    spans: list[tuple[int, int, float]] = []
    i = 0
    while i < len(tokens):
        start, end, word = tokens[i]
        low = word.lower()
        if word[0].isdigit():
            value = float(word.replace(",", "."))
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
    return spans


def numeric_vector(value: float | None) -> np.ndarray:
    """The :data:`NUMERIC_FEATURES` features of one token (zeros for a non-number)."""
    if value is None:
        return np.zeros(NUMERIC_FEATURES, dtype=np.float32)
    v = max(float(value), 0.0)
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


__all__ = ["NUMERIC_FEATURES", "number_spans", "numeric_vector", "token_numeric_features"]
