"""Numbers as people write them: digits ("20", "2.5") or words ("twenty-five", "two and a half").

Prompt values are integers or have one decimal (the generator rounds depths to metres and speeds
to halves of m/s or 5 km/h), so words cover ``0 <= value < 100`` with at most one decimal; anything
else stays in digits.
"""

from __future__ import annotations

_ONES = (
    "zero",
    "one",
    "two",
    "three",
    "four",
    "five",
    "six",
    "seven",
    "eight",
    "nine",
    "ten",
    "eleven",
    "twelve",
    "thirteen",
    "fourteen",
    "fifteen",
    "sixteen",
    "seventeen",
    "eighteen",
    "nineteen",
)
_TENS = ("", "", "twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety")

NUMBER_WORDS: frozenset[str] = frozenset((*_ONES, *_TENS[2:], "hundred"))
"""Every word :func:`spell_number` may write for a number (besides "point" and "and")."""

DIGITS = "digits"
HYPHENATED = "hyphenated words"
SPACED = "spaced words"
NUMBER_STYLES = (DIGITS, HYPHENATED, SPACED)
"""``digits``: 25, 2.5; ``hyphenated words``: twenty-five, two and a half, half a;
``spaced words``: twenty five, two point five, zero point five."""


def digits(value: float) -> str:
    """A number in digits as people write it: ``20``, ``2.5`` (rounded to one decimal)."""
    r = round(float(value), 1)
    return str(int(r)) if r == int(r) else f"{r:g}"


def _int_words(n: int, sep: str) -> str:
    if n < 20:
        return _ONES[n]
    tens, ones = divmod(n, 10)
    return _TENS[tens] if ones == 0 else f"{_TENS[tens]}{sep}{_ONES[ones]}"


def spell_number(value: float, style: str) -> str:
    """``value`` (rounded to one decimal) in the given style of :data:`NUMBER_STYLES`.

    Words: ``0 <= value < 100``; halves are "and a half" ("half a" for 0.5) in the hyphenated
    style and "point five" in the spaced one; other tenths are "point N" in both. Out of range
    values fall back to digits.

    Raises:
        ValueError: ``style`` is not one of :data:`NUMBER_STYLES`.
    """
    if style not in NUMBER_STYLES:
        raise ValueError(f"spell_number: style {style!r} is not one of {NUMBER_STYLES}")
    r = round(float(value), 1)
    if style == DIGITS or not 0.0 <= r < 100.0:
        return digits(r)
    whole = int(r)
    tenth = int(round((r - whole) * 10))
    sep = "-" if style == HYPHENATED else " "
    if tenth == 0:
        return _int_words(whole, sep)
    if style == HYPHENATED and tenth == 5:
        return "half a" if whole == 0 else f"{_int_words(whole, sep)} and a half"
    return f"{_int_words(whole, sep)} point {_ONES[tenth]}"


def takes_singular(value: float, spelled: str) -> bool:
    """Whether a unit after this number is singular ("one metre", "half a metre", "1 m/s")."""
    return round(float(value), 1) == 1.0 or spelled.startswith("half a")
