"""Sentences from predicates: a referring expression whose counts agree with its referents.

:func:`render` builds ``[frame] determiner [adjective | superlative] noun [phrases]``, e.g. "Show
me the two parked cars on the left.", "where is the closest cyclist riding towards us", "The
pedestrians about twenty metres ahead." Each choice is drawn from a slot of
:mod:`scenes.language.prompts.phrasing` (``phrasing``: ``train`` variants only, ``all``, or ``heldout``: all
variants with at least one held-out variant in every sentence). Singular / plural and is / are
agree with the number of referents, and a stated count ("two pedestrians", "both", "the 3 cars")
equals it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from scenes.language.prompts.atoms import (
    Atom,
    DepthBetween,
    Extreme,
    OnSide,
    SpeedAbout,
    SpeedAbove,
    SpeedBelow,
    SpeedUnit,
)
from scenes.language.prompts.numbers import DIGITS, HYPHENATED, spell_number, takes_singular
from scenes.language.prompts.phrasing.extra import DROPPED, EXTRA
from scenes.language.prompts.phrasing.family_slots import FAMILY_SLOTS
from scenes.language.prompts.phrasing.slot_choice import (
    CLASS_KEYS,
    adjective_slot,
    extreme_slot,
    phrase_slot,
)
from scenes.language.prompts.phrasing.slots import SLOTS
from scenes.language.prompts.phrasing.split import HELDOUT_VARIANTS, PHRASINGS, variant_id
from scenes.language.prompts.predicate import Predicate
from scenes.language.prompts.sampling import LANGUAGES
from scenes.language.prompts.tags import flip_left_right, infer_tags


@dataclass(frozen=True)
class Prompt:
    """A referring sentence with its referents.

    Attributes:
        text: The sentence.
        referent_ids: Ids of the actors it refers to, ascending (empty for real prompts whose
            actors are unknown).
        tags: Type tags, a subset of :data:`~scenes.language.prompts.tags.TAGS`.
        predicate: The predicate it was rendered from (None for real / typed prompts).
        variants: Ids of the phrasing variants the sentence used, in order
            (:mod:`scenes.language.prompts.phrasing`); empty for real / typed prompts. Not compared.
        family: The prompt family (:data:`scenes.language.prompts.sampling.FAMILIES`); ``attribute`` for
            a predicate and for real / typed prompts. Not compared.
        expression: The compositional expression of the other families
            (:mod:`scenes.language.prompts.families`; None for ``attribute`` and ``out_of_class``; the
            ``predicate`` is then the base predicate, or None). Not compared.
    """

    text: str
    referent_ids: tuple[int, ...]
    tags: frozenset[str]
    predicate: Predicate | None = field(default=None, repr=False)
    variants: tuple[str, ...] = field(default=(), repr=False, compare=False)
    family: str = field(default="attribute", repr=False, compare=False)
    expression: object = field(default=None, repr=False, compare=False)

    @staticmethod
    def from_text(text: str, referent_ids: Sequence[int] = ()) -> Prompt:
        """A prompt from free text (real Talk2Radar, typed), tags from :func:`infer_tags`."""
        return Prompt(text, tuple(sorted(int(i) for i in referent_ids)), infer_tags(text))

    def flipped(self) -> Prompt:
        """The prompt for the world flipped y -> -y: left/right swapped in text and predicate."""
        pred = self.predicate.flipped() if self.predicate is not None else None
        text = flip_left_right(self.text)
        expr = self.expression
        flip = getattr(expr, "flipped", None)
        expr = flip() if flip is not None else expr
        return Prompt(text, self.referent_ids, self.tags, pred, self.variants, self.family, expr)


# --------------------------------------------------------------------------------------------
# Variant picking
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Choices:
    canonical: str
    allowed: tuple[str, ...]
    heldout: tuple[str, ...]
    ids: dict[str, str]


def _choices(phrasing: str, language: str) -> dict[str, _Choices]:
    """Base: the slots of :data:`SLOTS`. Extended: each slot less its :data:`DROPPED` variants
    plus its :data:`EXTRA` ones (train side), and the :data:`FAMILY_SLOTS` (train side)."""
    out = {}
    extended = language == "extended"
    slots = {**SLOTS, **FAMILY_SLOTS} if extended else SLOTS
    for name, slot in slots.items():
        texts = slot.core + slot.more
        if extended:
            texts = tuple(t for t in texts if t not in DROPPED.get(name, ())) + EXTRA.get(name, ())
        ids = {t: variant_id(name, t) for t in texts}
        heldout = tuple(t for t in texts if ids[t] in HELDOUT_VARIANTS)
        allowed = (
            tuple(t for t in texts if ids[t] not in HELDOUT_VARIANTS)
            if phrasing == "train"
            else texts
        )
        out[name] = _Choices(texts[0], allowed, heldout, ids)
    return out


_CHOICES = {(lang, p): _choices(p, lang) for p in PHRASINGS for lang in LANGUAGES}


class Picker:
    """Draws variants for one sentence and records them."""

    def __init__(
        self,
        rng: np.random.Generator,
        phrasing: str,
        forced: str | None,
        language: str = "base",
    ) -> None:
        self.rng = rng
        self.table = _CHOICES[(language, phrasing)]
        self.forced = forced
        self.ids: list[str] = []
        self.slots: list[str] = []
        self.heldout_used = False

    def uniform(self, n: int) -> int:
        return min(int(self.rng.random() * n), n - 1)

    def pick(self, slot: str, p_vary: float = 1.0) -> str:
        """A variant of ``slot``: the canonical one with probability ``1 - p_vary``, else a
        uniform draw among the stream's variants (only held-out ones when ``slot`` is forced)."""
        c = self.table[slot]
        if slot == self.forced and c.heldout:
            text = c.heldout[self.uniform(len(c.heldout))]
        elif p_vary < 1.0 and self.rng.random() >= p_vary:
            text = c.canonical
        else:
            text = c.allowed[self.uniform(len(c.allowed))]
        vid = c.ids[text]
        self.ids.append(vid)
        self.slots.append(slot)
        self.heldout_used = self.heldout_used or vid in HELDOUT_VARIANTS
        return text


# --------------------------------------------------------------------------------------------
# Sentence composition
# --------------------------------------------------------------------------------------------

_FIELD = re.compile(r"\{(\w+)\}")
_SPELLED_UNIT = re.compile(r"met(?:er|re)s")
CASES: dict[str, Callable[[str], str]] = {
    "sentence case": lambda s: s[:1].upper() + s[1:],
    "lower case": lambda s: s,
    "upper case": str.upper,
    "title case": lambda s: " ".join(w[:1].upper() + w[1:] for w in s.split(" ")),
}
ENDS = {
    "period": ".",
    "no punctuation": "",
    "exclamation mark": "!",
    "question mark": "?",
}
_JOINERS = {"space": " ", "comma": ", ", "and": " and "}


@dataclass(frozen=True)
class Style:
    p_count_word: float
    p_adjective: float
    p_frame: float
    p_restyle: float
    p_number_words: float


class Sentence:
    """Fills templates for one sentence about ``n`` referents; ``{rel}``, ``{us}``, ``{verb}``,
    units, the number style and the count style are drawn once per sentence, when first used."""

    def __init__(self, pk: Picker, n: int, cls_key: str, style: Style) -> None:
        self.pk = pk
        self.n = n
        self.plural = n > 1
        self.cls_key = cls_key
        self.style = style
        self.cache: dict[str, str] = {}

    def once(self, slot: str, p_vary: float = 1.0) -> str:
        if slot not in self.cache:
            self.cache[slot] = self.pk.pick(slot, p_vary)
        return self.cache[slot]

    def quantity(self, value: float, unit_slot: str, with_unit: bool = True) -> str:
        unit = self.once(unit_slot)
        style = DIGITS
        if _SPELLED_UNIT.search(unit):
            style = self.once("number", self.style.p_number_words)
        num = spell_number(value, style)
        if not with_unit:
            return num
        if takes_singular(value, num):
            unit = unit.replace("metres", "metre").replace("meters", "meter")
        return unit.replace("{x}", num)

    def fill(self, template: str, atom: Atom | None = None, **known: str) -> str:
        def field_value(m: re.Match[str]) -> str:
            name = m.group(1)
            if name in known:
                return known[name]
            if name == "be":
                return "are" if self.plural else "is"
            if name == "k":
                count = self.once("count")
                return spell_number(self.n, HYPHENATED) if count == "words" else str(self.n)
            if name == "rel":
                return self.once("rel")
            if name == "us":
                return self.once("ego")
            if name == "verb":
                return self.once(f"verb/{self.cls_key}")
            if name == "side" and isinstance(atom, OnSide):
                return atom.side.value
            if name in ("d", "lo", "hi") and atom is not None:
                if isinstance(atom, DepthBetween):
                    value = atom.hi if name != "lo" else atom.lo
                else:
                    value = atom.metres  # type: ignore[attr-defined]
                return self.quantity(value, "unit.depth", with_unit=name != "lo")
            if name == "v" and isinstance(atom, SpeedAbout | SpeedAbove | SpeedBelow):
                slot = "unit.kmh" if atom.unit is SpeedUnit.KMH else "unit.mps"
                return self.quantity(atom.value, slot)
            raise ValueError(f"render: no value for {{{name}}} in template {template!r}")

        return _FIELD.sub(field_value, template)


def noun_phrase(
    pred: Predicate,
    s: Sentence,
    *,
    noun: str | None = None,
    determiner: bool = True,
    adjective: bool = True,
    core_of: Callable[[str], str] | None = None,
) -> str:
    """``determiner [adjective | superlative] noun [phrases]`` of a predicate, for ``s.n``
    referents. ``noun``: ``singular|plural`` instead of the class's noun slot (out-of-class
    things). ``determiner`` False: no determiner ("how many parked cars ..."). ``adjective``
    False: every atom after the noun. ``core_of``: builds the core from the noun instead of a
    superlative or adjective (ordinals: "second closest car")."""
    pk, style, n = s.pk, s.style, s.n
    plural = n > 1
    key = s.cls_key
    singular_noun, plural_noun = (noun or pk.pick(f"noun.{key}")).split("|")
    noun_text = plural_noun if plural else singular_noun
    atoms = list(pred.atoms)
    if core_of is not None:
        core = core_of(noun_text)
    elif pred.extreme is not None:
        side = {Extreme.LEFTMOST: "left", Extreme.RIGHTMOST: "right"}.get(pred.extreme, "")
        core = s.fill(pk.pick(extreme_slot(pred.extreme)), n=noun_text, side=side)
    else:
        core = noun_text
        if adjective and pk.rng.random() < style.p_adjective:
            with_adj = [a for a in atoms if adjective_slot(a, key) is not None]
            if with_adj:
                chosen = with_adj[pk.uniform(len(with_adj))]
                core = f"{pk.pick(adjective_slot(chosen, key))} {core}"  # type: ignore[arg-type]
                atoms.remove(chosen)
    # Motion words right after the noun ("the cyclist stopped between 40 and 45 m ahead"), the
    # other phrases after them in random order.
    ordered = [a for a in atoms if a.family in ("motion", "heading")]
    rest = [a for a in atoms if a.family not in ("motion", "heading")]
    while rest:
        ordered.append(rest.pop(pk.uniform(len(rest))))
    posts = [s.fill(pk.pick(phrase_slot(a, key)), atom=a) for a in ordered]
    if not determiner:
        np_text = core
    elif not plural:
        np_text = f"the {core}"
    elif n <= 10 and pk.rng.random() < style.p_count_word:
        np_text = f"{s.fill(pk.pick('det.pair' if n == 2 else 'det.count'))} {core}"
    else:
        np_text = f"{pk.pick('det.plural')} {core}"
    if posts:
        joiner = _JOINERS[pk.pick("joiner", style.p_restyle)] if len(posts) > 1 else " "
        np_text += " " + joiner.join(posts)
    return np_text


def finish(np_text: str, s: Sentence, frame_slot: str = "frame", **known: str) -> str:
    """The sentence around a noun phrase: a command / question frame (of ``frame_slot``, its
    other fields from ``known``), casing, end punctuation."""
    pk, style = s.pk, s.style
    frame = pk.pick(frame_slot, style.p_frame)
    question = frame.endswith("?")
    body = s.fill(frame.rstrip("?"), np=np_text, **known)
    case = pk.pick("case", style.p_restyle)
    end = pk.pick("end/question" if question else "end/statement", style.p_restyle)
    return CASES[case](body) + ENDS[end]


def _compose(pred: Predicate, n: int, pk: Picker, style: Style) -> str:
    s = Sentence(pk, n, CLASS_KEYS[pred.cls], style)
    return finish(noun_phrase(pred, s), s)


def repeats(text: str) -> bool:
    words = re.findall(r"[a-z]+", text.lower())
    return words.count("away") > 1 or words.count("ahead") + words.count("front") > 1


def render_with_variants(
    predicate: Predicate,
    n_referents: int,
    rng: np.random.Generator,
    *,
    phrasing: str = "train",
    p_count_word: float = 0.4,
    p_adjective: float = 0.35,
    p_frame: float = 0.35,
    p_restyle: float = 0.35,
    p_number_words: float = 0.3,
    max_words: int = 22,
    language: str = "base",
) -> tuple[str, tuple[str, ...]]:
    """:func:`render`, and the ids of the phrasing variants the sentence used (``language``:
    ``base`` or ``extended`` wording, :func:`_choices`)."""
    if n_referents < 1:
        raise ValueError(f"render: a prompt must refer to something, got n_referents={n_referents}")
    if predicate.extreme is not None and n_referents != 1:
        raise ValueError("render: a superlative refers to exactly one actor")
    if phrasing not in PHRASINGS:
        raise ValueError(f"render: phrasing must be one of {PHRASINGS}, got {phrasing!r}")
    style = Style(p_count_word, p_adjective, p_frame, p_restyle, p_number_words)
    forced: str | None = None
    text, ids = "", ()
    for attempt in range(8):
        pk = Picker(rng, phrasing, forced, language)
        text = _compose(predicate, n_referents, pk, style)
        ids = tuple(pk.ids)
        if phrasing == "heldout" and not pk.heldout_used:
            # Redraw with one slot this sentence uses restricted to its held-out variants; the
            # frame (always used) after three misses.
            cands = [sl for sl in dict.fromkeys(pk.slots) if pk.table[sl].heldout]
            forced = cands[pk.uniform(len(cands))] if cands and attempt < 3 else "frame"
            continue
        if not repeats(text) and len(text.split()) <= max_words:
            break
    return text, ids


def render(
    predicate: Predicate,
    n_referents: int,
    rng: np.random.Generator,
    *,
    p_count_word: float = 0.4,
    p_adjective: float = 0.35,
    max_words: int = 22,
    phrasing: str = "train",
    p_frame: float = 0.35,
    p_restyle: float = 0.35,
    p_number_words: float = 0.3,
) -> str:
    """A referring sentence for a predicate that resolves to ``n_referents`` actors.

    Singular / plural and is / are agree with ``n_referents``; a stated count ("two
    pedestrians", "both", "the 3 cars") equals it (stated with probability ``p_count_word`` for
    2..10 referents). One atom goes before the noun with probability ``p_adjective``
    ("the parked cars"). A command or question frame ("show me ...", "where are ...") is used
    with probability ``p_frame``; another casing, end punctuation or phrase joiner than
    "Sentence case, period, spaces" each with probability ``p_restyle``; numbers before a
    spelled-out unit are words ("twenty metres") with probability ``p_number_words``. With all
    three at 0 the sentence is a Talk2Radar-style noun phrase ("The cars moving away from us.").
    ``phrasing`` selects the variants (module docstring). A draw that repeats "away", says
    "ahead" / "in front" twice or runs past ``max_words`` words is redrawn (up to 8 times).
    Deterministic for a given ``rng`` state; rendering the flipped predicate with the same state
    gives :func:`flip_left_right` of the sentence.

    Raises:
        ValueError: ``n_referents < 1``, a superlative predicate with ``n_referents != 1``, or an
            unknown ``phrasing``.
    """
    text, _ = render_with_variants(
        predicate,
        n_referents,
        rng,
        phrasing=phrasing,
        p_count_word=p_count_word,
        p_adjective=p_adjective,
        p_frame=p_frame,
        p_restyle=p_restyle,
        p_number_words=p_number_words,
        max_words=max_words,
    )
    return text
