"""The one reading policy for every file the project reads, and the strict byte read under it.

:func:`read_file_bytes` reads point clouds and images; :func:`read_text_file` reads every text
file (labels, calibrations, split lists, pose files, prediction files, journals, the language
suite), :func:`read_json_file` every JSON file (sidecars, journals, reports, the language suite)
and :func:`read_prompt_file` a prompt file. One error type per kind of file, one line naming the
file (and its line where one applies). The policy, for files as people save them:

1. **A leading UTF-8 byte-order mark is removed**, and said once per root (a ``UserWarning``
   naming the root and the first such file; :func:`root_of` says which root a file is in: the
   nearest folder a reader opened as a root, :func:`claim_root`), not once per file: editors on Windows save one, and left in place it sticks to the first field
   (``'\\ufeffCar'``: a label's first object dropped, a prompt that the app refuses fed to
   training as it is).
2. **CRLF line ends are accepted** (read as LF).
3. **Anything else odd is refused**, naming the file, the line and the character: bytes that are
   not UTF-8, a NUL byte (a binary file), and every character :mod:`scenes.utils.text_policy` refuses
   in typed text (control characters, a lone carriage return, a byte-order mark anywhere else,
   zero-width and bidirectional formatting characters, line and paragraph separators) but the
   tab and the line feed. No file we read has a use for them; a reader that kept them would
   split lines where others do not (``str.splitlines`` breaks at ``\\x0b``, ``\\x85``,
   ``U+2028``) or compare names that look equal and are not.

A prompt file is then one sentence under :data:`scenes.utils.text_policy.PROMPT` (:func:`read_prompt_file`):
the same text the Query tab and the annotation store accept, so training, evaluation and the app
read one spelling of each prompt.

Decision: this module is the one home of the reading policy and :mod:`scenes.utils.text_policy` the
one home of what a character is allowed to be (typed text and files share its classification,
:func:`scenes.utils.text_policy.forbidden_at`).
"""

from __future__ import annotations

import json
import os
import threading
import warnings
from pathlib import Path

from scenes.utils.text_policy import (
    PROMPT,
    TextPolicyError,
    character_name,
    clean_text,
    forbidden_at,
)

BOM = b"\xef\xbb\xbf"
"""The UTF-8 byte-order mark."""

_BOM_ROOTS: set[Path] = set()
"""The roots whose byte-order marks were already said (this process)."""
_BOM_LOCK = threading.Lock()

_CLAIMED_ROOTS: set[Path] = set()
"""The folders readers opened as roots (this process): :func:`root_of` groups files by them."""


def read_file_bytes(path: str | Path, what: str, error: type[Exception]) -> bytes:
    """The bytes of ``path``.

    Args:
        path: The file.
        what: What it is, for the message (``"point-cloud file"``).
        error: The exception type to raise.

    Raises:
        error: the file is missing or unreadable (a folder, a symlink loop, no permission); the
            one-line message names the file.
    """
    path = Path(path)
    try:
        return path.read_bytes()
    except FileNotFoundError as exc:
        raise error(f"{path}: {what} not found") from exc
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from exc


def claim_root(path: str | Path) -> None:
    """Say that the files under ``path`` belong to one root (a dataset family's reader calls it
    when it opens a root), so that what is said once per root is said once for them all. This
    module knows no layout: which folder is a root is the family's to say."""
    with _BOM_LOCK:
        _CLAIMED_ROOTS.add(Path(os.path.abspath(path)))


def root_of(path: str | Path) -> Path:
    """The root a file belongs to, for saying things once per root: the nearest folder above it
    that a reader opened as a root (:func:`claim_root`); else the file's own folder (a file
    outside any opened root: a label folder scored alone, a suite, a report). Absolute, symlinks
    not resolved."""
    path = Path(os.path.abspath(path))
    with _BOM_LOCK:
        claimed = set(_CLAIMED_ROOTS)
    for folder in path.parents:
        if folder in claimed:
            return folder
    return path.parent


def note_bom(path: str | Path, what: str) -> None:
    """Warn (``UserWarning``) that ``path``'s root has files beginning with a byte-order mark,
    which readers remove: once per root and process (:func:`root_of`)."""
    path = Path(path)
    root = root_of(path)
    with _BOM_LOCK:
        if root in _BOM_ROOTS:
            return
        _BOM_ROOTS.add(root)
    warnings.warn(
        f"{root}: files begin with a UTF-8 byte-order mark (the first: the {what} {path}); "
        "the mark is ignored here and in every other file of this root",
        UserWarning,
        stacklevel=4,
    )


def decode_text(raw: bytes, path: str | Path, what: str, error: type[Exception]) -> str:
    """``raw`` read under the module's policy: a leading byte-order mark removed (and said once
    per root), CRLF made LF, anything else odd refused.

    Raises:
        error: ``path``'s bytes are not UTF-8, hold a NUL byte or a character the policy refuses;
            the one-line message names the file, the line and the byte or character.
    """
    path = Path(path)
    if raw.startswith(BOM):
        raw = raw[len(BOM) :]
        note_bom(path, what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise error(
            f"{path}: the {what} is not UTF-8 text (line {line}: byte {raw[exc.start]:#04x})"
        ) from exc
    if "\0" in text:
        at = text.index("\0")
        raise error(
            f"{path}: the {what} is binary, not text (a NUL byte on line {_line(text, at)})"
        )
    if "\r" in text:
        text = text.replace("\r\n", "\n")
    at = forbidden_at(text, allowed="\t\n")
    if at is not None:
        char = text[at]
        what_char = "a carriage return without a line feed" if char == "\r" else "a character"
        raise error(
            f"{path}:{_line(text, at)}: the {what} holds {what_char} not allowed in a text "
            f"file ({character_name(char)}); remove it"
        )
    return text


def _line(text: str, index: int) -> int:
    return text.count("\n", 0, index) + 1


def read_text_file(path: str | Path, what: str, error: type[Exception]) -> str:
    """The text of ``path`` under the module's policy.

    Args:
        path: The file.
        what: What it is, for the message (``"label file"``).
        error: The exception type to raise (e.g. :class:`scenes.frame.kitti.LabelError`).

    Raises:
        error: the file is missing, unreadable (a folder, a symlink loop, no permission), not
            UTF-8, binary (it holds a NUL byte) or holds a character the policy refuses; the
            one-line message names the file.
    """
    path = Path(path)
    return decode_text(read_file_bytes(path, what, error), path, what, error)


def read_json_file(path: str | Path, what: str, error: type[Exception]) -> object:
    """The JSON value of ``path`` (text under the module's policy).

    Raises:
        error: as :func:`read_text_file`, or the text is not JSON (``path:line:`` and the
            parser's reason).
    """
    path = Path(path)
    text = read_text_file(path, what, error)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{path}:{exc.lineno}: the {what} is not valid JSON ({exc.msg})") from exc
    except RecursionError as exc:
        raise error(f"{path}: the {what} is not valid JSON (nested too deeply)") from exc


def read_prompt_file(path: str | Path, error: type[Exception], what: str = "prompt file") -> str:
    """The sentence of a prompt file: its text under the module's policy, then
    :func:`scenes.utils.text_policy.clean_text` under :data:`~scenes.utils.text_policy.PROMPT` (NFKC, spaces
    collapsed, one line, 500 characters at most), the rule the app and the store apply. A final
    line end is not part of the sentence. May return ``""`` (the caller says what an empty prompt
    means).

    Raises:
        error: as :func:`read_text_file`, or the prompt breaks the prompt rule (more than one
            line, too long); the message names the file.
    """
    path = Path(path)
    text = read_text_file(path, what, error).strip(" \t\n")
    try:
        return clean_text(text, PROMPT)
    except TextPolicyError as exc:
        raise error(f"{path}: {exc}") from exc


__all__ = [
    "BOM",
    "claim_root",
    "decode_text",
    "note_bom",
    "read_file_bytes",
    "read_json_file",
    "read_prompt_file",
    "read_text_file",
    "root_of",
]
