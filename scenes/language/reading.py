"""Reading a person's sentence before the model grounds it: which object it is about, in words the
model knows, and whether it means one object or a set.

People say "park behind the silver car", "my friend is in that car. stop next to it.", "follow
him", "the taxi on the right". The model grounds referring expressions ("the car on the right"):
:func:`read_prompt` turns a sentence into a :class:`Reading`:

- **the manoeuvre is separated from the referring expression**: a command (a sentence that opens
  with a driving verb, or several sentences, or context first: "there is ...", "my friend ...")
  is read down to the noun phrase of its referent ("park behind the parked car on the left" ->
  "the parked car on the left"); the preposition of the manoeuvre ("behind", "in front of") is
  what the driver does, not where the referent is;
- **which mention is the referent**: the first road-user mention of the last sentence that names
  one; a sentence that only points back ("stop next to it", "pull up to him") takes the nearest
  earlier mention a pronoun can mean ("it": a vehicle or an object, "him" / "her": a person or a
  rider); "he is on the left" after the mention adds "on the left" to it;
- **attributes no sensor observes are dropped**, never a reason for no answer: colours, makes,
  sizes, clothing, possessives ("my friend's"), landmarks that are not road users;
- **people's words for a class** (:mod:`scenes.language.words`): "van", "taxi", "guy", "lorry";
  the hypernym "vehicle" and a sentence with no noun ("follow him", "pull over here") become one
  text per class they may mean (:attr:`Reading.texts`); the model's answer is the best candidate
  over them (the maximum of its referent probabilities);
- **number**: a singular definite description or a command means one object
  (:attr:`Reading.single`: answered with the best box only); plurals, counts, "all" and "both"
  keep a set.

A sentence the generator could have written (a description: no driving verb first, one sentence,
only the generator's nouns) is left exactly as it is: :attr:`Reading.texts` is ``(text,)``.
Every rule here is about English words; nothing is learnt, so the reading is the same for every
checkpoint and is tested on its own (``tests/scenes/language/test_reading.py``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from functools import lru_cache

from scenes.geometry.classes import ClassSet
from scenes.language.model_phrases import phrase_at
from scenes.language.phrases import (
    ASKING,
    BE,
    BEFORE_OBJECT,
    BOUNDARIES,
    COLOURS,
    DETERMINERS,
    MANOEUVRES,
    PERSON_VERBS,
    PERSON_WORDS,
    PLACE_NOUNS,
    SENTENCE,
    Mention,
    choose,
    content_start,
    cut_post,
    find_mentions,
    noun_words,
    places,
    predicates,
    start_of_phrase,
    tokens,
    words,
)
from scenes.language.words import PERSON_CLASSES, classes_of, generator_nouns, lexicon


@dataclass(frozen=True)
class Reading:
    """How a sentence is grounded.

    Attributes:
        texts: What the model grounds, one text per class the referent may be (the answer is the
            best candidate over them); ``(prompt,)`` when the sentence is read as written.
        single: Exactly one object is meant: answer with the best box only.
        command: A driving command: one object, and never nothing without a word.
        classes: The classes the referent may be (empty: not told by the sentence).
        missing: The words of a class the sentence names that the class set lacks ("truck" to a
            three-class model), or "".
    """

    texts: tuple[str, ...]
    single: bool = False
    command: bool = False
    classes: tuple[str, ...] = ()
    missing: str = ""

    def rewritten(self, prompt: str) -> bool:
        """Whether the model grounds something other than ``prompt`` as written."""
        return self.texts != (prompt.strip(),)


@lru_cache(maxsize=1)
def _frames() -> tuple[str, ...]:
    """The generator's sentence frames before the noun phrase ("show me", "where is", ""),
    lower case, longest first."""
    from scenes.language.prompts.phrasing.extra import EXTRA
    from scenes.language.prompts.phrasing.slots import SLOTS

    out = set()
    for frame in (*SLOTS["frame"].core, *SLOTS["frame"].more, *EXTRA["frame"]):
        head = frame.split("{np}")[0].replace(",", " ")
        for be in ("is", "are"):
            out.add(" ".join(tokens(head.replace("{be}", be))))
    return tuple(sorted(out, key=len, reverse=True))


def _np_first(toks: list[str]) -> bool:
    """Whether ``toks`` open with a noun phrase naming a thing (a road user, or a thing the
    generator names), its modifiers before it."""
    known = lexicon().keys() | generator_nouns()
    for i, t in enumerate(toks[:7]):
        if any(" ".join(toks[i : i + n]) in known for n in (1, 2, 3)):
            return True
        if t == "of":
            continue  # "all of the riders", "the number of people"
        if t in BEFORE_OBJECT or t in BOUNDARIES or t in PLACE_NOUNS or t in BE or t == ",":
            return False
    return False


QUESTIONS = frozenset(["what", "how", "which", "where", "count", "number", "total", "is", "are"])
"""First words of a question about the scene ("how many cyclists ...", "what is the number of
...", "is there a car ..."): a description, not a command."""


def _is_command(sentences: list[list[str]], raw: str) -> bool:
    """Whether a sentence is a driving command or people's talk (context, several sentences)
    rather than a description the generator could have written: one sentence that is a noun
    phrase, or one of the generator's frames ("show me", "where is") and a noun phrase."""
    if len(sentences) > 1 or _template_phrase(raw) is not None:
        return True
    toks = sentences[0]
    i = content_start(toks)
    if i < len(toks) and toks[i] in QUESTIONS:
        return False
    rest = " ".join(toks[i:])
    for j in {0, i}:  # "show me the car ...", "hey, find the cyclists ...", "look for ..."
        said = " ".join(toks[j:])
        framed = [f for f in _frames() if f and said.startswith(f + " ")]
        if any(_np_first(toks[j + len(f.split()) :]) for f in framed):
            return False
    if i < len(toks) and (toks[i] in MANOEUVRES or toks[i] in {"don't", "do", "dont"}):
        return True
    if any(rest.startswith(c) for c in ASKING):  # "can you pull over", not "can you count"
        return any(t in MANOEUVRES for t in toks[i + 1 : i + 5])
    return not _np_first(toks[i:])


def _render(det: list[str], pre: list[str], noun: str, post: list[str]) -> str:
    """The text grounded: a quantifier kept ("all", "both"), any other determiner read as
    "the" ("that car", "my friend")."""
    quantified = det and det[0] in {"all", "both", "each", "every", "some", "any"}
    text = " ".join([*(det if quantified else ["the"]), *pre, noun, *post])
    return re.sub(r"\s+,", ",", text).strip()


_AHEAD = re.compile(r"\b(?:up ahead|up front|in front(?! of))\b", re.IGNORECASE)
"""People's "ahead" the generator never writes; read as its "in front of us"."""


def read_prompt(prompt: str, classes: ClassSet) -> Reading:
    """How ``prompt`` (already through the text policy) is grounded by a model of ``classes``."""
    reading = _read(prompt, classes)
    texts = tuple(_AHEAD.sub("in front of us", t) for t in reading.texts)
    return replace(reading, texts=texts) if texts != reading.texts else reading


def _read(prompt: str, classes: ClassSet) -> Reading:
    raw = prompt.strip()
    sentences = [t for t in (tokens(s) for s in SENTENCE.split(raw)) if t]
    if not sentences:
        return Reading((raw,))
    found = find_mentions(sentences)
    command = _is_command(sentences, raw)
    nouns = [m for m in found if not m.pronoun]
    if not command and _generator_only(nouns, sentences, classes.name):
        return Reading((raw,), single=_singular_description(sentences, nouns))
    if command and len(sentences) == 1:
        phrase = _template_phrase(raw)
        inner = [tokens(phrase)] if phrase is not None else []
        inner_found = find_mentions(inner)
        inner_nouns = [m for m in inner_found if not m.pronoun]
        if phrase is not None and inner_nouns:  # a command template around a noun phrase
            sentences, found, nouns = inner, inner_found, inner_nouns
            cues = _people_cues(sentences[0])
            if not cues and _generator_only(nouns, sentences, classes.name):  # the generator's
                options = classes_of(nouns[0].classes, classes.names)
                missing = "" if options else _words_of(sentences[0], nouns[0])
                return Reading((phrase,), not nouns[0].plural, True, options, missing)
    head = choose(found, sentences)
    names = classes.names
    talk = any(t in MANOEUVRES for s in sentences for t in s)  # a driving verb somewhere
    if head is None and not (command and talk):
        return Reading((raw,))  # nonsense, or a thing that is not a road user
    said = {t for s in sentences for t in s}
    person = bool(said & (PERSON_WORDS | PERSON_VERBS))  # "pick up tom", "stop next to her"
    if head is None and not person:
        other = _other_thing(sentences)
        if other:  # "park next to the fire hydrant": a thing, not a road user
            return Reading((raw,), single=True, command=True, missing=other)
    place = next((p for s in sentences if (p := _place_in(s))), [])  # "tom, to our left"
    if head is None or (head.pronoun and not head.classes):
        # no noun at all ("pull over here", "there is gary, stop next to him"): the most
        # plausible road user, a person where the sentence speaks of one
        options = classes_of(PERSON_CLASSES if person else (), names) or names
        return _reading(classes, options, [], [], place, False, True)
    toks = sentences[head.sentence]
    options = classes_of(head.classes, names)
    if not options:
        word = _words_of(toks, head)
        return Reading((raw,), single=not head.plural, command=command, missing=word)
    if head.pronoun:  # "let her cross": only where the sentences place her
        det, pre = ["the"], []
        post = cut_post(toks, head.end) if places(toks, head.end) else place
    else:
        det, pre = noun_words(toks, head)
        post = cut_post(toks, head.end)
    post += predicates(sentences, head)
    return _reading(classes, options, det, pre, post, head.plural, command)


PEOPLE_CUES = words(
    "wearing dressed carrying holding whose sidewalk pavement corner curb kerb shirt bench "
    "jacket coat hat vest station lot driveway"
)
"""Words people say around a referent that the generator never writes in a command's
description (what they wear, where they sit or stand): the phrase is then read, not taken as
written."""


def _people_cues(toks: list[str]) -> bool:
    """Whether a noun phrase says what the generator never says (:data:`PEOPLE_CUES`, or "with"
    that is not the generator's "with a speed of ...", "with the 2nd highest speed")."""
    for i, t in enumerate(toks):
        if t in PEOPLE_CUES:
            return True
        if t == "with" and "speed" not in toks[i + 1 : i + 5]:
            return True
    return False


def _place_in(toks: list[str]) -> list[str]:
    """The first place phrase of a sentence ("on the left", "to our right"), or []."""
    for i in range(len(toks)):
        if places(toks, i):
            n = phrase_at(toks, i)
            if n:
                return toks[i : i + n]
    return []


def _words_of(toks: list[str], mention: Mention) -> str:
    return " ".join(toks[mention.start : mention.end])


def _reading(
    classes: ClassSet,
    options: tuple[str, ...],
    det: list[str],
    pre: list[str],
    post: list[str],
    plural: bool,
    command: bool,
) -> Reading:
    nouns = (classes.get(c).plural if plural else classes.get(c).noun for c in options)
    texts = tuple(_render(det, pre, noun, post) for noun in nouns)
    counted = plural or (det and det[0] in {"all", "both", "each", "every"})
    return Reading(texts, single=not counted, command=command, classes=options)


def _other_thing(sentences: list[list[str]]) -> str:
    """The first thing the generator names that is not a road user ("fire hydrant"), or ""."""
    known = generator_nouns()
    for toks in sentences:
        for i in range(len(toks)):
            if i and toks[i - 1] not in DETERMINERS:  # a noun after "the", "a": not "can"
                continue
            for n in (3, 2, 1):
                word = " ".join(toks[i : i + n])
                if word in known and word not in lexicon():
                    return word
    return ""


@lru_cache(maxsize=1)
def _command_templates() -> tuple[re.Pattern[str], ...]:
    """The generator's command templates (:data:`scenes.language.prompts.commands.COMMAND_SLOTS`,
    every variant) as patterns that capture the description (``np``)."""
    from scenes.language.prompts.commands import COMMAND_SLOTS

    out = []
    for slot in COMMAND_SLOTS.values():
        for template in (*slot.core, *slot.more):
            parts = [re.escape(p) for p in template.split("{np}")]
            body = "(?P<np>.+?)".join(parts).replace(re.escape("{it}"), "(?:it|them|him|her)")
            out.append(re.compile(f"^{body}$", re.IGNORECASE))
    out.sort(key=lambda r: len(r.pattern), reverse=True)
    return tuple(out)


def _template_phrase(raw: str) -> str | None:
    """The description inside one of the generator's commands, or None."""
    text = re.sub(r"[\s.!?]+$", "", raw.strip())
    for pattern in _command_templates():
        m = pattern.match(text)
        if m:  # people point ("that car"); the generator says "the car"
            return re.sub(r"^(?:that|this)\b", "the", _one_clause(m.group("np").strip()))
    return None


def _one_clause(phrase: str) -> str:
    """``phrase`` up to a clause that is not the referent's ("that oncoming car, there is a
    bump behind it" -> "that oncoming car", "this car, but wait ..." -> "this car"): a comma or
    "but" / "so" / "because" before a word that opens a clause (:data:`CLAUSE_STARTS`); the
    generator's joiners (", on the right", "and 20 m ahead") go on with the phrase."""
    toks = tokens(phrase)
    for i, t in enumerate(toks):
        nxt = toks[i + 1] if i + 1 < len(toks) else ""
        if i and (t == "," or t in {"but", "so", "because"}) and nxt in CLAUSE_STARTS:
            return " ".join(toks[:i])
    return phrase


CLAUSE_STARTS = frozenset(
    ["there", "i", "we", "you", "it", "he", "she", "they", "this", "that", "but", "so", "wait"]
)
"""Words that open another clause after a comma ("..., there is a bump", "..., but wait")."""


def _generator_only(nouns: list[Mention], sentences: list[list[str]], class_set: str) -> bool:
    """Whether the sentence uses only words the generator writes (its nouns and no colours)."""
    known = generator_nouns(class_set)
    for m in nouns:
        if " ".join(sentences[m.sentence][m.start : m.end]) not in known:
            return False
    return not any(t in COLOURS for s in sentences for t in s)


def _singular_description(sentences: list[list[str]], nouns: list[Mention]) -> bool:
    """A description meaning one object: its first noun singular after "the" / "that" / "this"
    (or a superlative or ordinal), no count, no "all" / "both" / "each" / "every"."""
    if not nouns or len(sentences) != 1:
        return False
    head = nouns[0]
    toks = sentences[0]
    if head.plural:
        return False
    if any(
        t in {"all", "both", "each", "every", "any", "and", "or", "except", "but"} for t in toks
    ):
        return False
    det_at = start_of_phrase(toks, head.start)
    return det_at < head.start and toks[det_at] in {"the", "that", "this"}
