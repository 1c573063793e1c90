"""The one text policy for what a person types that becomes a file or a table cell: prompts and
annotator names.

Every path that takes such text applies :func:`clean_text` on the server: the Query tab before a
prompt runs (:mod:`app.query.prompt`), :func:`annotate.validation.validate` for a draft's prompt (the
Annotate tab's live checks and every save) and :class:`annotate.AnnotationStore` for what it
writes (the prompt file, the sidecar, the manifest's prompt and annotator), and
:func:`annotate.review.record_review` for a reviewer's name and note. The rule:

1. **Unicode NFKC.** Compatibility forms become their plain equivalents (full-width ``１５`` is
   ``15``, a no-break space is a space, ``ﬁ`` is ``fi``), so the file, the text encoder and the
   numeral reader see one spelling of each sentence, and two prompts that look the same are the
   same string.
2. **Forbidden characters are refused, with a message naming each one** (``U+0000 (NUL)``,
   ``U+2028 (LINE SEPARATOR)``): every control character (Unicode category Cc: C0, DEL and C1,
   ``\\x85`` included) but the tab, every format character (Cf: zero-width spaces and joiners,
   bidirectional overrides, the byte-order mark, the soft hyphen), the line and paragraph
   separators (Zl, Zp) and lone surrogates (Cs, which UTF-8 cannot write). That is every
   character ``str.splitlines`` breaks at (so a saved prompt file is one line for every reader)
   and every one that is invisible or reorders text in a table cell. A line break is refused
   too: a Talk2Radar prompt is one sentence. (The GUI's multi-line fields turn the line break of
   Enter into a space before this rule sees the text: :func:`app.query.prompt.one_line`.)
3. **Spaces collapse**: runs of spaces and tabs become one space, and the ends are stripped
   (:func:`collapse_spaces`).
4. **Length caps** (after 1-3): :data:`PROMPT` 500 characters (a Talk2Radar prompt has about 30
   words, 200 characters at most), :data:`ANNOTATOR` 64, :data:`NOTE` 500. Longer text is refused, not cut, so
   nothing is saved that the person did not see.

The files the project reads share this classification (:func:`forbidden_at`, with the line feed
allowed: :mod:`scenes.utils.textfile`, the one reading policy), and a prompt file is read under
:data:`PROMPT` there. A Talk2Car command file is JSON, whose escapes (``"\\u0000"``) reach past
the file's check: each command's text goes through :func:`clean_text` under :data:`COMMAND`
(:func:`scenes.nuscenes.talk2car.read_commands`; a refused command is skipped, counted and named).

Decision: refuse rather than silently drop forbidden characters. A NUL or a line separator in a
prompt is a paste or a forged message, never meant; dropping it could join two words
(``the car\\x00ahead``) into a sentence nobody typed.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass

_C0_NAMES = (
    "NUL", "SOH", "STX", "ETX", "EOT", "ENQ", "ACK", "BEL", "BS", "TAB", "LF", "VT", "FF", "CR",
    "SO", "SI", "DLE", "DC1", "DC2", "DC3", "DC4", "NAK", "SYN", "ETB", "CAN", "EM", "SUB", "ESC",
    "FS", "GS", "RS", "US",
)  # fmt: skip
"""Names of the C0 control characters (``unicodedata.name`` has none)."""

_FORBIDDEN_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})
"""Unicode categories refused (the tab, a Cc character, is collapsed to a space instead)."""

_SPACES = re.compile(r"[ \t]+")

RAW_FACTOR = 8
"""Text longer than this many times a rule's cap is refused before it is normalised (NFKC and
collapsing spaces shrink text by far less), so a forged megabyte costs nothing to refuse."""

SHOWN_CHARACTERS = 5
"""Distinct forbidden characters named in a message (then "and N more")."""


@dataclass(frozen=True)
class TextRule:
    """What one kind of text may be.

    Attributes:
        what: How messages name it ("prompt", "annotator name").
        max_chars: The most characters it may have once normalised.
    """

    what: str
    max_chars: int


PROMPT = TextRule("prompt", 500)
"""A prompt (the Query tab, a pair's prompt file)."""

ANNOTATOR = TextRule("annotator name", 64)
"""The annotator name recorded with a pair."""

NOTE = TextRule("review note", 500)
"""A reviewer's note on a pair (:mod:`annotate.review`)."""

COMMAND = TextRule("command", PROMPT.max_chars)
"""A Talk2Car command read from a command file (:func:`scenes.nuscenes.talk2car.read_commands`):
a prompt by another name, fed to the model, the app and training as one, under the same cap."""


class TextPolicyError(ValueError):
    """Text that the policy refuses; the message is one sentence naming the problem (the
    forbidden characters, or the length and the cap). :attr:`rule` says which text it was."""

    def __init__(self, rule: TextRule, message: str) -> None:
        super().__init__(message)
        self.rule = rule

    @property
    def sentence(self) -> str:
        """The message with a capital first letter (a notification's body)."""
        text = str(self)
        return text[:1].upper() + text[1:]


def character_name(char: str) -> str:
    """``U+0000 (NUL)``, ``U+2028 (LINE SEPARATOR)``: a character as messages name it."""
    code = ord(char)
    if code < 0x20:
        name = _C0_NAMES[code]
    elif code == 0x7F:
        name = "DEL"
    elif code == 0x85:
        name = "NEL"
    elif 0x80 <= code < 0xA0:
        name = "C1 control"
    elif 0xD800 <= code < 0xE000:
        name = "lone surrogate"
    else:
        name = unicodedata.name(char, unicodedata.category(char))
    return f"U+{code:04X} ({name})"


def forbidden_characters(text: str) -> tuple[str, ...]:
    """The distinct characters of ``text`` that the policy refuses, in order of appearance."""
    seen = dict.fromkeys(
        c for c in text if c != "\t" and unicodedata.category(c) in _FORBIDDEN_CATEGORIES
    )
    return tuple(seen)


_ASCII_FORBIDDEN = re.compile(r"[\x00-\x1f\x7f]")
"""The ASCII characters of a forbidden category (C0 controls and DEL)."""
_NON_ASCII = re.compile(r"[^\x00-\x7f]")


def forbidden_at(text: str, allowed: str = "\t") -> int | None:
    """The index of the first character of ``text`` that the policy refuses, the characters of
    ``allowed`` excepted (files allow the line feed too: :mod:`scenes.utils.textfile`); None when there
    is none. The same classification as :func:`forbidden_characters`, quick on ASCII text."""
    first = None
    for match in _ASCII_FORBIDDEN.finditer(text):
        if match.group() not in allowed:
            first = match.start()
            break
    if text.isascii():
        return first
    for match in _NON_ASCII.finditer(text, 0, len(text) if first is None else first):
        char = match.group()
        if char not in allowed and unicodedata.category(char) in _FORBIDDEN_CATEGORIES:
            return match.start()
    return first


def collapse_spaces(text: str) -> str:
    """``text`` with each run of spaces and tabs made one space and the ends stripped (no other
    character is touched: :func:`clean_text` refuses line breaks and controls)."""
    return _SPACES.sub(" ", text).strip(" ")


def clean_text(text: object, rule: TextRule) -> str:
    """``text`` made what may be saved or run under ``rule`` (see the module docstring):
    NFKC-normalised, spaces collapsed and stripped. May return ``""`` (the caller decides what an
    empty prompt or name means).

    Raises:
        TextPolicyError: ``text`` is not a string, holds a forbidden character (the message names
            them) or is longer than ``rule.max_chars`` once normalised.
    """
    if not isinstance(text, str):
        raise TextPolicyError(rule, f"the {rule.what} is not text ({type(text).__name__})")
    if len(text) > RAW_FACTOR * rule.max_chars:  # cannot fit once normalised: do not scan it
        raise _too_long(rule, len(text))
    normal = unicodedata.normalize("NFKC", text)
    bad = forbidden_characters(normal)
    if bad:
        shown = ", ".join(character_name(c) for c in bad[:SHOWN_CHARACTERS])
        more = f" and {len(bad) - SHOWN_CHARACTERS} more" if len(bad) > SHOWN_CHARACTERS else ""
        kind = "a character" if len(bad) == 1 else "characters"
        raise TextPolicyError(
            rule,
            f"the {rule.what} contains {kind} not allowed (control, invisible or line "
            f"break): {shown}{more}; remove {'it' if len(bad) == 1 else 'them'}",
        )
    clean = collapse_spaces(normal)
    if len(clean) > rule.max_chars:
        raise _too_long(rule, len(clean))
    return clean


def _too_long(rule: TextRule, length: int) -> TextPolicyError:
    return TextPolicyError(
        rule, f"the {rule.what} has {length:,} characters; at most {rule.max_chars} are allowed"
    )


__all__ = [
    "ANNOTATOR",
    "COMMAND",
    "NOTE",
    "PROMPT",
    "TextPolicyError",
    "TextRule",
    "character_name",
    "clean_text",
    "collapse_spaces",
    "forbidden_at",
    "forbidden_characters",
]
