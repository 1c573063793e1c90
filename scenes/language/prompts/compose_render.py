"""Sentences of the compositional families (:mod:`scenes.language.prompts.families`), extended wording.

Each ``render_*`` builds on :func:`scenes.language.prompts.render.noun_phrase` and
:func:`~scenes.language.prompts.render.finish` with the ``extended`` tables
(:mod:`scenes.language.prompts.phrasing.extra`, :mod:`scenes.language.prompts.phrasing.family_slots`), and returns ``(text, variant ids)``. A draw that repeats
"away", says "ahead" / "in front" twice or runs past ``max_words`` is redrawn (up to 8 times).
Singular / plural agree with the sets the sentence names (the base set of an exclusion is
plural, a count question is plural whatever the count).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from scenes.language.prompts.atoms import (
    Atom,
    DepthAbout,
    DepthBetween,
    DepthBeyond,
    DepthWithin,
    Extreme,
    HeadingIs,
    MotionState,
    OnSide,
    Side,
    SpeedAbove,
)
from scenes.language.prompts.families import (
    Count,
    Exclusion,
    Not,
    Ordinal,
    Related,
    Relation,
    negated,
)
from scenes.language.prompts.nouns import article
from scenes.language.prompts.phrasing.slot_choice import CLASS_KEYS, adjective_slot, phrase_slot
from scenes.language.prompts.predicate import Predicate
from scenes.language.prompts.render import Picker, Sentence, Style, finish, noun_phrase, repeats

EXTENDED = "extended"


def negation_slot(atom: Atom, cls_key: str) -> str | None:
    """The slot of a negated atom's phrase (None: the atom is not said negated)."""
    if isinstance(atom, MotionState):
        return "neg.moving" if atom.moving else f"neg.stationary/{cls_key}"
    if isinstance(atom, HeadingIs):
        return f"neg.heading.{atom.heading.value}"
    if isinstance(atom, OnSide):
        return "neg.ahead" if atom.side is Side.AHEAD else "neg.side"
    if isinstance(atom, SpeedAbove):
        return "neg.speed.above"
    kinds = {DepthAbout: "about", DepthBetween: "between", DepthWithin: "within"}
    kinds[DepthBeyond] = "beyond"
    kind = kinds.get(type(atom))
    return f"neg.depth.{kind}" if kind is not None else None


def _attempts(
    build: Callable[[Picker], str], rng: np.random.Generator, phrasing: str, max_words: int
) -> tuple[str, tuple[str, ...]]:
    text, ids = "", ()
    for _ in range(8):
        pk = Picker(rng, phrasing, None, EXTENDED)
        text = build(pk)
        ids = tuple(pk.ids)
        if not repeats(text) and len(text.split()) <= max_words:
            break
    return text, ids


def _extreme_word_slot(extreme: Extreme, prefix: str) -> str:
    if extreme in (Extreme.LEFTMOST, Extreme.RIGHTMOST):
        return f"{prefix}.lateral"
    return f"{prefix}.{extreme.value}"


def _side(extreme: Extreme) -> str:
    return {Extreme.LEFTMOST: "left", Extreme.RIGHTMOST: "right"}.get(extreme, "")


def render_negation(
    pred: Predicate, n: int, rng: np.random.Generator, style: Style, phrasing: str, max_words: int
) -> tuple[str, tuple[str, ...]]:
    """A predicate with one :class:`Not` atom: "the cars on the left that are not moving"."""
    neg = negated(pred)
    if not isinstance(neg, Not):
        raise ValueError("render_negation: the predicate has no negated atom")
    key = CLASS_KEYS[pred.cls]
    slot = negation_slot(neg.atom, key)
    if slot is None:
        raise ValueError(f"render_negation: {neg.atom!r} has no negated phrasing")
    rest = Predicate(pred.cls, tuple(a for a in pred.atoms if a is not neg), pred.extreme)

    def build(pk: Picker) -> str:
        s = Sentence(pk, n, key, style)
        np_text = noun_phrase(rest, s)
        nbe = pk.pick("nbe/plural" if n > 1 else "nbe/singular")
        phrase = s.fill(pk.pick(slot), atom=neg.atom, nbe=nbe)
        return finish(f"{np_text} {phrase}", s)

    return _attempts(build, rng, phrasing, max_words)


def render_exclusion(
    expr: Exclusion,
    n_base: int,
    n_removed: int,
    rng: np.random.Generator,
    style: Style,
    phrasing: str,
    max_words: int,
) -> tuple[str, tuple[str, ...]]:
    """ "all the pedestrians except the nearest one", "every car but the ones on the right"."""
    key = CLASS_KEYS[expr.base.cls]
    extra = [a for a in expr.removed.atoms if a not in expr.base.atoms]

    def build(pk: Picker) -> str:
        s = Sentence(pk, max(n_base, 2), key, style)
        singular, plural = pk.pick(f"noun.{key}").split("|")
        base_np = noun_phrase(expr.base, s, noun=f"{singular}|{plural}", determiner=False)
        det = pk.pick("excl.det")
        join = pk.pick("excl.join")
        if expr.removed.extreme is not None:
            word = pk.pick(_extreme_word_slot(expr.removed.extreme, "excl"))
            removed = f"the {s.fill(word, side=_side(expr.removed.extreme))}"
        else:
            atom = extra[0]
            s2 = Sentence(pk, n_removed, key, style)
            adj = adjective_slot(atom, key)
            one = "ones" if n_removed > 1 else "one"
            if adj is not None and pk.rng.random() < style.p_adjective:
                removed = f"the {pk.pick(adj)} {one}"
            else:
                number = "plural" if n_removed > 1 else "singular"
                head = pk.pick(f"excl.subset/{number}")
                head = head.replace("{n}", plural if n_removed > 1 else singular)
                removed = f"{head} {s2.fill(pk.pick(phrase_slot(atom, key)), atom=atom)}"
        return finish(f"{det} {base_np} {join} {removed}", s)

    return _attempts(build, rng, phrasing, max_words)


def render_ordinal(
    expr: Ordinal, rng: np.random.Generator, style: Style, phrasing: str, max_words: int
) -> tuple[str, tuple[str, ...]]:
    """ "the second closest cyclist", "the third car from the left", "the farthest car but one",
    "the pedestrian number two from the right", "the second slowest cyclist", "the third closest
    object" (a class-free base)."""
    key = CLASS_KEYS[expr.base.cls]
    ext = expr.extreme

    def build(pk: Picker) -> str:
        s = Sentence(pk, 1, key, style)
        if expr.rank == 2 and ext in (Extreme.NEAREST, Extreme.FARTHEST) and pk.rng.random() < 0.3:
            template = pk.pick(f"ord.{ext.value}/2")
        else:
            template = pk.pick(_extreme_word_slot(ext, "ord"))
        o = pk.pick(f"ord.{expr.rank}")
        k = pk.pick(f"ord.k.{expr.rank}") if "{k}" in template else ""

        def core(noun: str) -> str:
            return s.fill(template, n=noun, o=o, k=k, side=_side(ext))

        return finish(noun_phrase(expr.base, s, core_of=core), s)

    return _attempts(build, rng, phrasing, max_words)


def render_relation(
    expr: Related,
    n: int,
    rng: np.random.Generator,
    style: Style,
    phrasing: str,
    max_words: int,
) -> tuple[str, tuple[str, ...]]:
    """ "the pedestrian closest to the parked car", "the cars behind the cyclist", "the cyclist
    between the two cars"."""
    key = CLASS_KEYS[expr.target.cls]
    ref_key = CLASS_KEYS[expr.reference.cls]
    plain = replace(style, p_count_word=0.0)

    def build(pk: Picker) -> str:
        s = Sentence(pk, n, key, style)
        target_np = noun_phrase(expr.target, s, adjective=False)
        if expr.relation is Relation.BETWEEN:
            plural = pk.pick(f"noun.{ref_key}").split("|")[1]
            ref_np = pk.pick("relation.pair").replace("{n}", plural)
        else:
            ref_np = noun_phrase(expr.reference, Sentence(pk, 1, ref_key, plain))
        phrase = s.fill(pk.pick(f"relation.{expr.relation.value}"), ref=ref_np)
        return finish(f"{target_np} {phrase}", s)

    return _attempts(build, rng, phrasing, max_words)


def render_count(
    expr: Count, rng: np.random.Generator, style: Style, phrasing: str, max_words: int
) -> tuple[str, tuple[str, ...]]:
    """ "how many cars are parked on the left?", "count the cyclists moving away from us"."""
    key = CLASS_KEYS[expr.base.cls]
    framed = replace(style, p_frame=1.0)

    def build(pk: Picker) -> str:
        s = Sentence(pk, 2, key, framed)
        return finish(noun_phrase(expr.base, s, determiner=False), s, "count.frame")

    return _attempts(build, rng, phrasing, max_words)


def render_plain(
    pred: Predicate,
    n: int,
    rng: np.random.Generator,
    style: Style,
    phrasing: str,
    max_words: int,
    noun: str | None = None,
) -> tuple[str, tuple[str, ...]]:
    """A predicate that refers to nothing, said in the singular (``n == 1``) or plural
    (``n > 1``) without a count word ("the cyclists moving toward us"); ``noun``: an
    out-of-class ``singular|plural`` instead of the class noun, sometimes with an indefinite
    frame ("is there a bus on the left?")."""
    key = CLASS_KEYS[pred.cls] if noun is None else "any"
    said = max(n, 1)
    plain = replace(style, p_count_word=0.0)

    indefinite = replace(plain, p_frame=1.0)

    def build(pk: Picker) -> str:
        if noun is not None and pred.extreme is None and pk.rng.random() < 0.35:
            s = Sentence(pk, said, key, indefinite)
            np_text = noun_phrase(pred, s, noun=noun, determiner=False)
            slot = "ooc.frame/plural" if said > 1 else "ooc.frame/singular"
            return finish(np_text, s, slot, a=article(np_text))
        s = Sentence(pk, said, key, plain)
        return finish(noun_phrase(pred, s, noun=noun), s)

    return _attempts(build, rng, phrasing, max_words)
