"""The phrases the model was trained to read after a noun: the generator's own position, motion,
heading, speed, depth and ranking phrases (``scenes.language.prompts.phrasing``'s slots, train
and held-out, and the extra wordings), as patterns over a sentence's tokens.

:func:`phrase_at` finds the longest such phrase starting at a token: "on the left-hand side",
"that is parked", "moving away from us", "at about 30 km/h", "roughly 20 m ahead", "closest to
us". The reader (:mod:`scenes.language.phrases`) keeps those of a person's sentence and drops
the rest (what no sensor observes, and what the model never learnt to read).

Placeholders: ``{us}`` the ego phrases, ``{side}`` left / right, ``{rel}`` that / which / who,
``{be}`` is / are, ``{verb}`` the class verbs, ``{d}`` / ``{v}`` / ``{lo}`` / ``{hi}`` a number
(digits or words) with a unit of the generator's, ``{k}`` a number; the ranking phrases'
noun ``{n}`` is where the phrase starts ("{n} closest to {us}").
"""

from __future__ import annotations

import re
from functools import lru_cache

PHRASE_SLOTS = ("position.", "motion.", "heading.", "speed.", "depth.", "extreme.")
"""The slots whose phrases follow a noun."""
_NUMBER = r"(?:\d+(?:\.\d+)?|[a-z]+(?:-[a-z]+)*(?: (?:point|and) [a-z]+)?)"


def _alternatives(values: list[str]) -> str:
    words = sorted({re.escape(v) for v in values if v}, key=len, reverse=True)
    return "(?:" + "|".join(words) + ")"


@lru_cache(maxsize=1)
def _patterns() -> tuple[re.Pattern[str], ...]:
    from scenes.language.prompts.phrasing.extra import EXTRA
    from scenes.language.prompts.phrasing.slots import SLOTS

    def variants(key: str) -> list[str]:
        slot = SLOTS[key]
        return [*slot.core, *slot.more, *EXTRA.get(key, ())]

    units = [
        u.replace("{x}", "").strip() for k in SLOTS if k.startswith("unit.") for u in variants(k)
    ]
    verbs = [v for k in SLOTS if k.startswith("verb/") for v in variants(k)]
    quantity = rf"{_NUMBER} ?{_alternatives(units)}"
    fill = {
        "{us}": _alternatives(variants("ego")),
        "{side}": "(?:left|right)",
        "{rel}": "(?:that|which|who)",
        "{be}": "(?:is|are|'s)",
        "{verb}": _alternatives(verbs),
        "{d}": quantity,
        "{v}": quantity,
        "{lo}": quantity,
        "{hi}": quantity,
        "{k}": _NUMBER,
    }
    out = set()
    for key in SLOTS:
        if not key.startswith(PHRASE_SLOTS):
            continue
        for template in variants(key):
            if template.startswith("{n} "):  # "{n} closest to {us}": what follows the noun
                template = template[4:]
            elif "{n}" in template:  # "nearest {n}": before the noun, not a post-modifier
                continue
            body = re.escape(template.lower())
            for name, pattern in fill.items():
                body = body.replace(re.escape(name), pattern)
            out.add(body)
    return tuple(re.compile(rf"(?:{b})(?= |$)") for b in sorted(out, key=len, reverse=True))


def phrase_at(toks: list[str], start: int) -> int:
    """How many tokens from ``start`` the longest model phrase spans (0: none starts there)."""
    text = " ".join(toks[start:])
    best = 0
    for pattern in _patterns():
        m = pattern.match(text)
        if m and m.end() > best:
            best = m.end()
    return len(text[:best].split()) if best else 0
