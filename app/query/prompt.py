"""The Query tab's prompt policy, applied once where text enters: :func:`read_prompt`.

Text enters the Query tab through one door, :meth:`app.session.ClientSession.run_prompt`: the
prompt box (Enter, *Run*), *Re-run* (the *History* entry), and a frame's command clicked
(:mod:`app.serving.frame_commands`, run as if typed). There, once, :func:`read_prompt` turns the
text into either a :class:`Prompt` (what the text policy accepted) or a :class:`Refused` (why it
cannot run, and what the prompt box shows). Everything after the door (the request, the engine,
the history, the answer shown) takes the :class:`Prompt` as it is and never cleans it again; the
model's own check at its public entry (``model.nets.text.validate_prompt``: not empty) is a
library's and changes nothing on a prompt read here.

The rule, in order: the line breaks of the multi-line prompt box (Enter, a pasted line) become
spaces (:func:`one_line`); then :func:`scenes.utils.text_policy.clean_text` under
:data:`~scenes.utils.text_policy.PROMPT` (NFKC, control and line-separator characters refused
by name, spaces collapsed, at most 500 characters); an empty result is refused with an example.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NewType

from scenes.utils.text_policy import PROMPT, TextPolicyError, clean_text, collapse_spaces

Prompt = NewType("Prompt", str)
"""A prompt :func:`read_prompt` accepted: one line, NFKC, spaces collapsed, 1 to 500 characters.
Made only there (and for a prompt already read: the last one run, re-run after a setting
changed); trusted after."""

EXAMPLE_PROMPT = "the car about 15 metres ahead"
"""Suggested in the empty-prompt notification."""


@dataclass(frozen=True)
class Refused:
    """Why a text cannot run, as the notification says it, and the prompt box's text.

    Attributes:
        title: The notification's title ("Prompt not run", "Empty prompt").
        body: Its sentence (the text policy's, naming a refused character or the length).
        shown: The text as the prompt box shows it when the server writes it back: as typed,
            line breaks and runs of spaces made one space.
    """

    title: str
    body: str
    shown: str


def read_prompt(typed: str | None) -> Prompt | Refused:
    """The prompt a text runs as, or why it cannot run (see the module docstring)."""
    line = one_line(typed or "")
    try:
        text = clean_text(line, PROMPT)
    except TextPolicyError as exc:
        return Refused("Prompt not run", exc.sentence, collapse_spaces(line))
    if not text:
        example = f'Type a sentence describing the objects to find, e.g. "{EXAMPLE_PROMPT}".'
        return Refused("Empty prompt", example, collapse_spaces(line))
    return Prompt(text)


def entered(value: str) -> bool:
    """Whether the prompt box's value holds a line break: Enter was pressed (or a line pasted)."""
    return "\n" in value or "\r" in value


def submitted_prompt(value: str) -> str | None:
    """The text to submit when a multi-line box's value holds a line break (Enter), else None
    (the Annotate tab's pair prompt box).

    The line breaks become spaces and runs of spaces collapse (:func:`one_line`,
    :func:`scenes.utils.text_policy.collapse_spaces`): ``"the car\\n"`` gives ``"the car"``; ``"\\n"``
    gives ``""``. Other control characters are left for the text policy to refuse by name.
    """
    if not entered(value):
        return None
    return collapse_spaces(one_line(value))


def one_line(value: str) -> str:
    """``value`` with each line break of a multi-line field (``\\r\\n``, ``\\n``, ``\\r``: Enter
    or a pasted line) made a space; the text policy refuses every other line separator."""
    return value.replace("\r\n", " ").replace("\n", " ").replace("\r", " ")


__all__ = [
    "EXAMPLE_PROMPT",
    "Prompt",
    "Refused",
    "entered",
    "one_line",
    "read_prompt",
    "submitted_prompt",
]
