"""The one text policy (issue 21): :mod:`scenes.utils.text_policy`."""

from __future__ import annotations

import pytest

from scenes.utils.text_policy import (
    ANNOTATOR,
    PROMPT,
    TextPolicyError,
    character_name,
    clean_text,
    collapse_spaces,
    forbidden_characters,
)

SPLITLINES_BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
"""Every character ``str.splitlines`` breaks at."""


def test_every_line_break_splitlines_sees_is_refused_by_name() -> None:
    for char in SPLITLINES_BREAKS:
        assert len(f"a{char}b".splitlines()) == 2
        with pytest.raises(TextPolicyError) as err:
            clean_text(f"the car{char}ahead", PROMPT)
        assert f"U+{ord(char):04X}" in str(err.value), char


@pytest.mark.parametrize(
    "char, name",
    [
        ("\x00", "U+0000 (NUL)"),
        ("\x0b", "U+000B (VT)"),
        ("\x0c", "U+000C (FF)"),
        ("\x1c", "U+001C (FS)"),
        ("\x1f", "U+001F (US)"),
        ("\x7f", "U+007F (DEL)"),
        ("\x85", "U+0085 (NEL)"),
        ("\x9b", "U+009B (C1 control)"),
        ("\u200b", "U+200B (ZERO WIDTH SPACE)"),
        ("\u202e", "U+202E (RIGHT-TO-LEFT OVERRIDE)"),
        ("\ufeff", "U+FEFF (ZERO WIDTH NO-BREAK SPACE)"),
        ("\u2028", "U+2028 (LINE SEPARATOR)"),
        ("\u2029", "U+2029 (PARAGRAPH SEPARATOR)"),
        ("\ud800", "U+D800 (lone surrogate)"),
    ],
)
def test_forbidden_characters_are_named(char: str, name: str) -> None:
    assert character_name(char) == name
    with pytest.raises(TextPolicyError) as err:
        clean_text(f"ada{char}bob", ANNOTATOR)
    assert str(err.value).startswith("the annotator name contains") and name in str(err.value)


def test_a_message_names_each_character_once_and_counts_the_rest() -> None:
    text = "a\x00b\x00c\x01d\x02e\x03f\x04g\x05"
    assert forbidden_characters(text) == tuple("\x00\x01\x02\x03\x04\x05")
    with pytest.raises(TextPolicyError) as err:
        clean_text(text, PROMPT)
    message = str(err.value)
    assert message.count("U+0000") == 1 and "and 1 more" in message
    assert "\n" not in message


def test_nfkc_and_spaces() -> None:
    assert clean_text("  the   car\tabout １５ m ahead ", PROMPT) == "the car about 15 m ahead"
    assert clean_text("the\u00a0car", PROMPT) == "the car"  # a no-break space
    assert clean_text("cafe\u0301", PROMPT) == "café"  # composed
    assert clean_text("   ", PROMPT) == ""
    assert collapse_spaces("\t a  b \t") == "a b"


def test_length_caps() -> None:
    assert clean_text("x" * 500, PROMPT) == "x" * 500
    with pytest.raises(TextPolicyError, match="has 501 characters; at most 500"):
        clean_text("x" * 501, PROMPT)
    assert clean_text("a" * 64, ANNOTATOR) == "a" * 64
    with pytest.raises(TextPolicyError, match="annotator name has 65 characters; at most 64"):
        clean_text("a" * 65, ANNOTATOR)
    with pytest.raises(TextPolicyError, match="has 1,000,000 characters"):  # refused unscanned
        clean_text("\x00" * 1_000_000, PROMPT)
    assert clean_text(" " * 600 + "car", PROMPT) == "car"  # the cap counts what is kept


def test_not_text() -> None:
    for value in (None, 5, b"the car", ["the car"]):
        with pytest.raises(TextPolicyError, match="is not text"):
            clean_text(value, PROMPT)
