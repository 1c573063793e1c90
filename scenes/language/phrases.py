"""The parts of a person's sentence :mod:`scenes.language.reading` reads: the words (tokens and
sentences), the road-user mentions (:mod:`scenes.language.words`), which mention is the referent,
and the referent's noun phrase with the modifiers a sensor can observe.

Every rule is about English words, written for this project (the word lists below); the module
docstring of :mod:`scenes.language.reading` says what a reading does with them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

from scenes.language.model_phrases import phrase_at
from scenes.language.words import PERSON_CLASSES, THING_CLASSES, lexicon, longest_word


def words(text: str) -> frozenset[str]:
    return frozenset(text.split())


# fmt: off
MANOEUVRES = words("""
park stop follow pull slow turn wait get go drop change let move take drive speed pick stay switch
pass keep watch merge catch continue overtake avoid yield give approach head steer brake back
reverse honk flash drift accelerate proceed halt tail chase trail hurry rush swerve veer cut
leave allow ride make bring meet queue line circle go u-turn overtake dodge mind pull
""")
"""Verbs that open a driving command."""
OPENERS = words("""
oh ok okay hey hi hello please so um uh well alright now yes yeah ah actually hmm and then
quickly carefully just also right wow look listen
""")
"""Words said before the verb ("ok, please park ...")."""
ASKING = ("can you", "could you", "would you", "will you", "i want", "i need", "we need",
          "you should", "you can", "you need", "i'd like", "let's", "let us", "i would")
"""Openings that ask for something: a command when a driving verb follows."""
DETERMINERS = words("the that this those these a an my our your his her their its some any "
                        "all both each every")
KEEP_BEFORE = words("""
moving parked stationary static stopped motionless approaching oncoming receding crossing
first second third fourth fifth last next nearest closest farthest furthest leftmost rightmost
1st 2nd 3rd 4th 5th
other only same two three four five six seven eight nine ten both all several walking standing
waiting driving riding turning incoming leading lone single
""")
"""Words before a noun that the model reads (motion, ordinals, superlatives, counts)."""
BOUNDARIES = words("""
and but or so because as since then when while until if once cause please i we you
""")
"""Words that end the referent's clause."""
BE = words("is are was were 's be")
RELATIVE = words("that who which")
PLACE_NOUNS = words("""
lane lanes stop stops station park lot lots rack racks path paths shelter wash dealership seat door
window space spot spots parking garage route ride driver drivers line depot
""")
"""Nouns that make a class word part of a place ("bus stop", "bike lane", "car park")."""
PERSON_WORDS = words("he she him her his hers")
"""Pronouns that say the referent is a person."""
PERSON_VERBS = words("pick talk ask wave greet meet say hi drop cross walk")
"""Verbs said of a person ("pick up tom", "let ann cross")."""
OBJECT_PRONOUNS = {"him": PERSON_CLASSES, "her": PERSON_CLASSES, "it": THING_CLASSES,
                   "them": ()}
SUBJECT_PRONOUNS = {"he": PERSON_CLASSES, "she": PERSON_CLASSES, "it": THING_CLASSES,
                    "they": ()}
BEFORE_OBJECT = words("""
behind near beside by around past after before of follow pass overtake approach towards toward for
to alongside with meet tail chase pick up let see passing following
""")
"""Words after which "it", "him", "her" is the object the command is about."""
DROP_STARTS = words("wearing dressed with carrying holding whose")
"""Post-modifiers about what no sensor observes ("wearing a white shirt", "with the hazards on")."""
RELATIONS = ("in front of", "next to", "close to", "across from", "behind", "beside", "near",
             "by", "alongside", "opposite", "after", "before", "past", "between", "outside")
KEEP_PLACES = re.compile(
    r"^(?:(?:on|to|at) (?:the|our|your|my) (?:left|right)|in front of (?:us|me)|"
    r"in (?:our|my|the same|this) lane|ahead|directly|straight|(?:on|to) (?:the )?(?:left|right)|"
    r"(?:left|right) of (?:us|me)|off to the|over on the)"
)
"""Place phrases the model reads (side of the road, ahead of us, our lane)."""
# fmt: on

SENTENCE = re.compile(r"(?<!\d)[.!?;\n]+(?!\d)")
_TOKEN = re.compile(r"\d+(?:\.\d+)?(?:[a-z/]+)?|[a-z]+(?:['’/-][a-z]+)*|,")


@dataclass(frozen=True)
class Mention:
    """A road-user word (or a pronoun) in a sentence: tokens ``[start, end)``."""

    sentence: int
    start: int
    end: int
    classes: tuple[str, ...]
    plural: bool
    pronoun: bool = False


_CONTRACTIONS = {
    "that's": ("that", "is"), "who's": ("who", "is"), "which's": ("which", "is"),
    "there's": ("there", "is"), "it's": ("it", "is"), "he's": ("he", "is"),
    "she's": ("she", "is"), "what's": ("what", "is"), "where's": ("where", "is"),
    "here's": ("here", "is"), "they're": ("they", "are"), "who're": ("who", "are"),
    "isn't": ("is", "not"), "aren't": ("are", "not"),
}  # fmt: skip
"""Contractions read as their words (not as a possessive: "the car that's nearest")."""


_TWO_WHEELS = ("Cyclist", "Bicycle", "Motorcycle")
_RIDDEN = {
    "bike": _TWO_WHEELS, "bicycle": ("Cyclist", "Bicycle"), "cycle": ("Cyclist", "Bicycle"),
    "motorbike": ("Motorcycle",), "motorcycle": ("Motorcycle",), "scooter": ("Motorcycle",),
    "moped": ("Motorcycle",),
}  # fmt: skip
"""What a person rides ("the man on the bike"): the classes the rider is."""


def tokens(sentence: str) -> list[str]:
    """A sentence's words, lower case (contractions spelt out, commas kept as tokens)."""
    out: list[str] = []
    for t in _TOKEN.findall(sentence.lower().replace("’", "'")):
        out.extend(_CONTRACTIONS.get(t, (t,)))
    return out


def find_mentions(sentences: list[list[str]]) -> list[Mention]:
    table, longest = lexicon(), longest_word()
    out: list[Mention] = []
    for s, toks in enumerate(sentences):
        i = 0
        while i < len(toks):
            hit = None
            for n in range(min(longest, len(toks) - i), 0, -1):
                entry = table.get(" ".join(toks[i : i + n]))
                if entry is not None:
                    hit = (n, entry)
                    break
            if hit is None:
                pron = toks[i]
                before = toks[i - 1] if i else ""
                if pron in OBJECT_PRONOUNS and before in BEFORE_OBJECT:
                    out.append(Mention(s, i, i + 1, OBJECT_PRONOUNS[pron], pron == "them", True))
                i += 1
                continue
            n, (classes, plural) = hit
            after = toks[i + n] if i + n < len(toks) else ""
            before = toks[i - 1] if i else ""
            owners = {"my", "our", "ego"} | ({"the"} if ego_verb(toks, i) else set())
            ego = "Car" in classes and (before in owners or before.startswith("ego"))
            rides = toks[i + n : i + n + 3]
            if (
                classes == ("Pedestrian",)
                and rides[:1] == ["on"]
                and rides[2:]
                and (rides[1] in {"a", "the", "his", "her"} and rides[2] in _RIDDEN)
            ):  # "the guy on the bike": a rider
                classes, n = _RIDDEN[rides[2]], n + 3
                after = toks[i + n] if i + n < len(toks) else ""
            if after not in PLACE_NOUNS and not after.endswith("'s") and not ego:
                out.append(Mention(s, i, i + n, classes, plural))
            i += n
    return out


def ego_verb(toks: list[str], i: int) -> bool:
    """ "park the car behind ...": the car is ours."""
    return i >= 2 and toks[i - 2] in {"park", "pull", "move", "stop", "turn", "bring", "put"}


def content_start(toks: list[str]) -> int:
    i = 0
    while i < len(toks) and (toks[i] in OPENERS or toks[i] == ","):
        i += 1
    return i


def choose(mentions: list[Mention], sentences: list[list[str]]) -> Mention | None:
    """The referent's mention (module docstring): in the last sentence that has one, the first
    after the sentence's first driving verb (else its first); a pronoun there points back to the
    nearest earlier mention it can mean."""
    if not mentions:
        return None
    last = max(m.sentence for m in mentions)
    here = [m for m in mentions if m.sentence == last]
    verb = next((i for i, t in enumerate(sentences[last]) if t in MANOEUVRES), None)
    after = [m for m in here if verb is not None and m.start > verb]
    pick = (after or [m for m in here if not m.pronoun] or here)[0]
    if not pick.pronoun:
        return pick
    earlier = [
        m
        for m in mentions
        if not m.pronoun and (m.sentence < last or (m.sentence == last and m.start < pick.start))
    ]
    # the nearest sentence first, and in it the first mention (the one it is about)
    earlier.sort(key=lambda m: (-m.sentence, m.start))
    for m in earlier:
        if not m.classes and pick.classes:  # "the object ... move around it": what "it" can be
            return replace(m, classes=pick.classes)
        if not pick.classes or set(m.classes) & set(pick.classes):
            return m
    return pick


def start_of_phrase(toks: list[str], head: int) -> int:
    """Index of the noun phrase's first token (its determiner, or the first modifier)."""
    i = head
    while i > 0 and head - i < 5:
        t = toks[i - 1]
        if t in DETERMINERS:
            return i - 1
        if t == "," or t in MANOEUVRES or t in BEFORE_OBJECT or t in BOUNDARIES or t in BE:
            return i
        i -= 1
    return i


RANKING = words(
    "furthest farthest nearest closest slowest fastest quickest first second third fourth fifth "
    "last 2nd 3rd 4th 5th leftmost rightmost most least slowest-moving fastest-moving "
    "quickest-moving"
)
"""Ranking words a person puts after the noun ("the car furthest ahead of us")."""
PLACE_WORDS = words(
    "away ahead from of to us me our the on at in left right far side front behind going "
    "driving moving than less more m metres meters km/h kph mph m/s"
)
MOTION = words(
    "crossing parked moving stopped approaching oncoming walking standing waiting receding "
    "stationary going driving travelling"
)
"""Motion words a person puts after the noun ("the cyclist crossing")."""
QUANTITY = words("less more within under over")
"""Words that open a distance or speed ("less than 10 m away")."""
"""Words that go on a ranking phrase ("furthest away from us", "going the slowest")."""

_AHEAD = {"up ahead": 2, "up front": 2, "in front": 2, "ahead": 1}
"""People's "ahead" (without "of ...") and how many tokens it takes."""


def cut_post(toks: list[str], start: int) -> list[str]:
    """The referent's post-modifiers from ``start`` to the end of its clause, keeping only what
    the model reads: the generator's own phrases (:func:`scenes.language.model_phrases.phrase_at`:
    side, ahead, motion, heading, speed, distance, ranking) and relations to another road user
    ("next to the truck"); what no sensor observes ("wearing a white shirt", "near the tree") is
    dropped. "the car is parked on the left" reads as "the car that is parked on the left"."""
    out: list[str] = []
    i = start
    while i < len(toks):
        t = toks[i]
        nxt = toks[i + 1] if i + 1 < len(toks) else ""
        if t in {",", "and"} and phrase_at(toks, i + 1):
            out.append(t)  # the generator's joiners: "..., on the right", "... and 20 m ahead"
            i += 1
            continue
        if t == "," or t in BOUNDARIES or (t in RELATIVE and nxt not in BE):
            break  # another clause ("and wait", "that looks like mine")
        ahead = _AHEAD.get(" ".join(toks[i : i + 2])) or _AHEAD.get(t)
        if ahead and toks[i + ahead : i + ahead + 1] != ["of"]:
            out += ["in", "front", "of", "us"]  # "the car up ahead": the generator's words
            i += ahead
            continue
        if t == "to" and nxt and not (nxt in DETERMINERS or nxt in {"us", "me", "left", "right"}):
            break  # "wait for the man to cross": a purpose, not a place
        if t in BE and not (out and out[-1] in RELATIVE):
            n = phrase_at(["that", "is", *toks[i + 1 :]], 0)
            if n <= 2 and set(toks[i + 1 : i + 4]) & (RANKING | MOTION):
                out += ["that", "is"]  # "the car that's third nearest", "who is going slowest"
                i += 1
                continue
            if n <= 2:
                break  # "the truck has passed", "is my friend's": not a modifier
            out += ["that", "is", *toks[i + 1 : i + n - 1]]
            i += n - 1
            continue
        n = phrase_at(toks, i)
        if n:
            out += toks[i : i + n]
            i += n
            continue
        rel = relation_at(toks, i)
        end = landmark_end(toks, i + rel) if rel else None
        if end is not None:
            out += toks[i:end]
            i = end
            continue
        if i == start and t not in DROP_STARTS | SEGMENT_STARTS | RANKING | MOTION | QUANTITY:
            break  # "the man crossed the street", "this man pass": a verb, not a modifier
        kept = out and (
            out[-1] in RANKING | PLACE_WORDS | MOTION | QUANTITY or out[-1][:1].isdigit()
        )
        if t in RANKING | MOTION | QUANTITY or (kept and (t in PLACE_WORDS or t[:1].isdigit())):
            out.append(t)  # "furthest away from us", "crossing", "less than 10 m away"
        i += 1  # else a word the model does not read: dropped
        continue
    while out and out[-1] in RELATIVE | BE | {"the", "a", "an", "to", "of", ",", "and"}:
        out.pop()
    return out


def relation_at(toks: list[str], i: int) -> int:
    joined = " ".join(toks[i : i + 3])
    for r in RELATIONS:
        if joined == r or joined.startswith(r + " "):
            if toks[i + len(r.split()) : i + len(r.split()) + 1] in (["us"], ["me"]):
                return 0
            return len(r.split())
    return 0


def landmark_end(toks: list[str], i: int) -> int | None:
    """End of a relation's landmark when it is a road user ("the truck"), else None."""
    table = lexicon()
    for j in range(i, min(i + 5, len(toks))):
        if toks[j] in table:
            return j + 1
        if toks[j] in BOUNDARIES or toks[j] == ",":
            return None
    return None


SEGMENT_STARTS = words(
    "on in at to near next behind beside by that who which parked moving stopped crossing "
    "walking standing waiting coming approaching driving ahead closest nearest about around "
    "roughly approximately faster slower within between beyond up directly straight from "
    "further farther more less going heading travelling riding"
)


def noun_words(toks: list[str], head: Mention) -> tuple[list[str], list[str]]:
    """The kept words before the head noun, and the determiner."""
    start = start_of_phrase(toks, head.start)
    words = toks[start : head.start]
    det: list[str] = []
    if words and words[0] in DETERMINERS:
        det, words = [words[0]], words[1:]
    kept = [w for w in words if w in KEEP_BEFORE | RANKING or w.isdigit()]
    return det, kept


def places(toks: list[str], start: int) -> bool:
    return bool(KEEP_PLACES.match(" ".join(toks[start:])))


def predicates(sentences: list[list[str]], head: Mention) -> list[str]:
    """Place phrases said of the referent in a later sentence ("he is on the left")."""
    out: list[str] = []
    for toks in sentences[head.sentence + 1 :]:
        i = content_start(toks)
        if i + 2 < len(toks) and toks[i] in SUBJECT_PRONOUNS and toks[i + 1] in BE:
            phrase = cut_post(toks, i + 2)
            if phrase and KEEP_PLACES.match(" ".join(phrase)):
                out += phrase
    return out


COLOURS = words("""
red white black silver grey gray blue green yellow orange brown pink purple dark light beige tan
gold golden maroon navy teal turquoise cream colored coloured
""")
"""Colour words (no sensor here observes colour)."""
