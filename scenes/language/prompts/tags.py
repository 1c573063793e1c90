"""Keyword type tags of a prompt and the left / right text flip, for generated and real text.

Both work on any text (generated prompts, real Talk2Radar prompts, what a person types), so they
hold no knowledge of the generator's tables; the generator's phrasings are written so that
:func:`infer_tags` gives a predicate's tags back from its sentence (tests check every variant).
"""

from __future__ import annotations

import re

TAGS: tuple[str, ...] = ("class", "depth", "velocity", "motion", "position")
"""Prompt type tags (the TPCNet paper's table III prompt types plus ``class``)."""

# --------------------------------------------------------------------------------------------
# Left / right flip
# --------------------------------------------------------------------------------------------

_LR_WORD = re.compile(r"\b(left|right)(most|wards?)?\b", re.IGNORECASE)
_ADVERBIAL_AFTER = re.compile(
    r"\s+(?:in front|ahead|behind|next to|beside|now|away|here|there)\b", re.IGNORECASE
)
_DIRECTION_BEFORE = re.compile(
    r"\b(?:the|our|your|their|his|her|its|my|to|far|and|or|from)\s+$", re.IGNORECASE
)


def _match_case(template: str, word: str) -> str:
    if len(template) > 1 and template.isupper():
        return word.upper()
    if template[:1].isupper():
        return word[:1].upper() + word[1:]
    return word


def flip_left_right(text: str) -> str:
    """Swap the words "left" and "right" in a sentence (for the y -> -y flip augmentation).

    Case is kept ("Left" -> "Right", "LEFT" -> "RIGHT"); whole words only, with the suffixes
    "most" and "ward(s)" ("leftmost" -> "rightmost"); hyphenated forms follow ("left-hand" ->
    "right-hand", "left-most" -> "right-most"). The adverb "right" ("right in front of us", "right
    ahead", "right behind", "right next to") is kept unless a determiner or preposition before it
    makes it a direction ("on the right in front of the bus" flips). The verb "left" ("the car that
    left") is not recognised and would be flipped; no generated prompt uses it.
    """

    def repl(m: re.Match[str]) -> str:
        word, suffix = m.group(1), m.group(2) or ""
        if word.lower() == "right" and not suffix:
            after = text[m.end() :]
            before = text[: m.start()]
            if _ADVERBIAL_AFTER.match(after) and not _DIRECTION_BEFORE.search(before):
                return m.group(0)
        new = "right" if word.lower() == "left" else "left"
        return _match_case(word, new) + suffix

    return _LR_WORD.sub(repl, text)


# --------------------------------------------------------------------------------------------
# Keyword tags
# --------------------------------------------------------------------------------------------

_WORD_DIGIT = (
    r"(?:zero|one|two|three|four|five|six|seven|eight|nine|ten|eleven|twelve|thirteen|fourteen"
    r"|fifteen|sixteen|seventeen|eighteen|nineteen|twenty|thirty|forty|fifty|sixty|seventy"
    r"|eighty|ninety)"
)
NUMBER_PATTERN = (
    rf"(?:\d+(?:\.\d+)?|\bhalf an?\b|\b{_WORD_DIGIT}(?:[- ]{_WORD_DIGIT})*"
    rf"(?: and a half| point {_WORD_DIGIT})?\b)"
)
"""A number as people type it: ``20``, ``2.5``, ``twenty``, ``twenty-five``, ``twenty five``,
``two and a half``, ``two point five``, ``half a`` (regular expression, lower case)."""

_SPEED_UNIT = (
    r"(?:km/h|m/s|(?<![a-z])(?:kmh|kph|mps|mph)\b|\bkm per hour\b"
    r"|\b(?:kilo)?met(?:er|re)s? (?:per|an?) (?:hour|second)\b|\bmiles? (?:per|an) hour\b)"
)
_SPEED_UNIT_RE = re.compile(_SPEED_UNIT)
_SPEED_PHRASE = re.compile(rf"(?:{NUMBER_PATTERN}\s*)?{_SPEED_UNIT}")
_LATERAL_EXTREME = re.compile(r"\b(?:farthest|furthest)\s+(?:to\s+(?:the|our)\s+)?(?:left|right)\b")
_EGO_PHRASE = re.compile(r"\bego[- ]?(?:car|vehicle)s?\b|\b(?:our|my) (?:car|vehicle)\b")
_DEPTH_HINT = re.compile(r"\d|\bm\b|met(?:er|re)|ahead|away")
_DEPTH_PHRASE = re.compile(
    rf"{NUMBER_PATTERN}\s*(?:m|meters?|metres?)\b(?!/)(?:\s+(?:ahead|away))?"
    r"|\d+(?:\.\d+)?\s+(?:ahead|away)\b"
    r"|\bfar away\b"
)
_DEPTH_WORDS = re.compile(
    r"\b(?:meters?|metres?|distance|distant|nearest|closest|farthest|furthest|depth)\b"
)
_VELOCITY_WORDS = re.compile(
    r"km/h|m/s|(?<![a-z])(?:kmh|kph|mps|mph)\b|\bspeed\w*|\bvelocit\w*|\bfast\w*|\bslow\w*"
    r"|\bquick\w*|\bper (?:hour|second)\b"
)
_MOTION_WORDS = re.compile(
    r"\bmov(?:e|es|ing)\b|\bstationary\b|\bparked\b|\bparking\b|\bstopped\b|\bstatic\b"
    r"|\bstanding still\b|\bstandstill\b|\bat rest\b|\bmotion\w*|\bapproach\w*|\btowards?\b"
    r"|\baway\b|\bcross(?:es|ing)?\b|\boncoming\b|\breced\w*|\bleaving\b|\bour way\b"
    r"|\bunderway\b|\bon the go\b|\bhalted\b|\bstanding\b|\bstood\b|\bsitting still\b"
    r"|\bnot going anywhere\b|\bat a stop\b|\bwaiting\b|\bcoming\b|\bclosing in\b"
    r"|\bour direction\b|\bacross\b|\bincoming\b|\bgetting closer\b"
)
_POSITION_WORDS = re.compile(
    r"\bleft\w*|\bright(?:most|wards?)?\b|\bfront\b|\bbehind\b|\bbeside\b|\bnext to\b"
    r"|\bahead\b|\blanes?\b|\bside\b|\bopposite\b"
)
_CLASS_WORDS = re.compile(
    r"\b(?:cars?|vehicles?|automobiles?|autos?|trucks?|vans?|bus(?:es)?|pedestrians?|persons?"
    r"|people|man|men|woman|women|child(?:ren)?|kids?|walkers?|cyclists?|bicyclists?|bicycles?"
    r"|bikes?|bikers?|riders?|motorcyclists?|motorbikes?|scooters?|sedans?|motorcars?|hatchbacks?"
    r"|humans?|individuals?|passers?-by|peds?)\b"
)


_ROAD_USER_WORDS = re.compile(
    r"\b(?:lorr(?:y|ies)|coach(?:es)?|(?:semi-)?trailers?|construction (?:machine|vehicle)s?"
    r"|motorcycles?|motor bikes?|pushbikes?|push bikes?|two-wheelers?|(?:traffic |road |safety )?"
    r"cones?|barriers?)\b"
)
"""The nouns of the ``nuscenes`` class set's road users that :data:`_CLASS_WORDS` lacks: class
words when ``infer_tags`` is told the text is about that set (with the ``vod`` set a lorry or a
cone is an out-of-class thing, and its tags stay what they always were)."""


_TRAVEL = re.compile(
    r"\b(?:same|opposite) (?:way|direction)\b|\bother way\b|\bdirection of travel\b"
    r"|\bgoing our way\b"
)

_COUNT_QUESTION = re.compile(r"\bhow many\b|\bcount\b|\bnumber of\b")


def is_count_question(text: str) -> bool:
    """Whether a text asks for a count ("how many cars are parked?", "count the cyclists",
    "number of pedestrians on the left?"): the words "how many", "count" (not "counting") or
    "number of", any case. Works on any typed text; the referents of a count
    question are the counted objects, and the answer says their number."""
    return _COUNT_QUESTION.search(text.lower()) is not None


def infer_tags(text: str, classes: str = "vod") -> frozenset[str]:
    """Prompt type tags from keywords; works on generated and real Talk2Radar prompts.

    Rules, applied in this order to the lower-cased text after "ego car" / "ego vehicle" /
    "our car" is removed (numbers may be digits or words, see :data:`NUMBER_PATTERN`):

    * velocity: a speed with its unit ("30 km/h", "fifteen kilometres per hour", "3 mps",
      "2 metres per second"); the phrase is removed, so its "metres" is not a depth. Also the
      words speed*, velocity, fast*, slow*, quick*, per hour / second, kph, kmh, mph, mps.
    * position: "farthest / furthest (to the) left / right" (removed, so it is not a depth).
    * motion: a direction of travel ("the same way / direction", "the opposite way / direction",
      "the other way", "direction of travel", "going our way"; removed, so "opposite" is not a
      position).
    * depth: a number with a metre unit ("20 m", "15 meters", "twenty metres away"), a number
      followed by "ahead"/"away", "far away", or the words metres/distance/distant/nearest/
      closest/farthest/furthest. These depth phrases are removed before the rules below, so
      "20 m away" is not motion and "20 m ahead" is not position.
    * motion: moving, move(s), stationary, parked, stopped, static, standing still, standstill,
      at rest, motion*, approach*, towards, away, crossing, oncoming, receding, leaving, our way.
    * position: left*, right, front, behind, beside, next to, ahead (not after a distance), lane,
      side, opposite.
    * class: car, vehicle, automobile, truck, van, bus, pedestrian, person, people, cyclist,
      bicycle, bike, rider, ... (the ego vehicle excluded); with ``classes`` another set than
      ``vod`` also the nouns of its road users (:data:`_ROAD_USER_WORDS`: lorry, coach, trailer,
      motorcycle, cone, barrier, ...).
    """
    s = _EGO_PHRASE.sub(" ego ", text.lower())
    tags: set[str] = set()
    if _SPEED_UNIT_RE.search(s):
        tags.add("velocity")
        s = _SPEED_PHRASE.sub(" ", s)
    if _LATERAL_EXTREME.search(s):
        tags.add("position")
        s = _LATERAL_EXTREME.sub(" ", s)
    if _TRAVEL.search(s):
        tags.add("motion")
        s = _TRAVEL.sub(" ", s)
    if _DEPTH_HINT.search(s) and _DEPTH_PHRASE.search(s):
        tags.add("depth")
        s = _DEPTH_PHRASE.sub(" ", s)
    if _DEPTH_WORDS.search(s):
        tags.add("depth")
    if _VELOCITY_WORDS.search(s):
        tags.add("velocity")
    if _MOTION_WORDS.search(s):
        tags.add("motion")
    if _POSITION_WORDS.search(s):
        tags.add("position")
    if _CLASS_WORDS.search(s) or (classes != "vod" and _ROAD_USER_WORDS.search(s)):
        tags.add("class")
    return frozenset(tags)
