"""Rewrite a JSON file's object keeping the bytes of what did not change (issue 50 item 1: a
pairs file keeps every key it did not write, byte for byte where untouched).

:func:`splice_object` takes a file's text (a JSON object) and the object to write in its place,
and returns text in which every member whose value is unchanged keeps its original bytes
(spacing, number spelling, escapes, key order); a list that only gained or lost items keeps the
bytes of each item it kept, a new item is written in the file's own style (indented like its
neighbours, or compact in a compact file); other changed values and new keys are written in that
style too. Whatever the text around the object holds (a final line end) is kept. The result is
checked: it must parse to the new object, else None is returned and the caller writes the whole
object afresh (a file with ``NaN``, say). Used by :func:`scenes.nuscenes.talk2car.
write_command_file`.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["splice_object"]

_WS = " \t\n\r"
_DECODER = json.JSONDecoder()


def _skip(text: str, i: int) -> int:
    while i < len(text) and text[i] in _WS:
        i += 1
    return i


def _members(text: str, start: int) -> tuple[int, list[tuple[str, int, int, int]]]:
    """The members of the object opening at ``start``: ``(close, [(key, key_start,
    value_start, value_end), ...])``, ``close`` the index of its ``}``.

    Raises:
        ValueError: not an object (or not JSON).
    """
    if text[start] != "{":
        raise ValueError("not an object")
    i, out = _skip(text, start + 1), []
    if text[i] == "}":
        return i, out
    while True:
        key, j = _DECODER.raw_decode(text, i)
        j = _skip(text, j)
        if not isinstance(key, str) or text[j] != ":":
            raise ValueError("not an object member")
        value_start = _skip(text, j + 1)
        _, value_end = _DECODER.raw_decode(text, value_start)
        out.append((key, i, value_start, value_end))
        k = _skip(text, value_end)
        if text[k] == "}":
            return k, out
        if text[k] != ",":
            raise ValueError("expected , or }")
        i = _skip(text, k + 1)


def _items(text: str, start: int) -> tuple[int, list[tuple[int, int]]]:
    """The items of the array opening at ``start``: ``(close, [(item_start, item_end), ...])``.

    Raises:
        ValueError: not an array (or not JSON).
    """
    if text[start] != "[":
        raise ValueError("not an array")
    i, out = _skip(text, start + 1), []
    if text[i] == "]":
        return i, out
    while True:
        _, end = _DECODER.raw_decode(text, i)
        out.append((i, end))
        k = _skip(text, end)
        if text[k] == "]":
            return k, out
        if text[k] != ",":
            raise ValueError("expected , or ]")
        i = _skip(text, k + 1)


def _indent_at(text: str, i: int) -> str | None:
    """The whitespace that starts the line of index ``i`` when only whitespace precedes ``i`` on
    it (an indented layout), else None (a compact one)."""
    line_start = text.rfind("\n", 0, i) + 1
    head = text[line_start:i]
    return head if line_start > 0 and not head.strip(_WS) else None


def _dump(value: Any, indent: str | None) -> str:
    """``value`` as JSON in the layout found: indented by one space a level, its later lines
    starting with ``indent`` (the line's own whitespace); compact when ``indent`` is None."""
    if indent is None:
        return json.dumps(value)
    return json.dumps(value, indent=1).replace("\n", "\n" + indent)


def _join(
    text: str,
    open_: int,
    close: int,
    spans: list[tuple[int, int]],
    pieces: list[str],
    indent: str | None,
) -> str:
    """The container from ``open_`` to ``close`` (inclusive) holding ``pieces`` in order: the
    original's opening and closing whitespace and its first separator between every two; for a
    container that was empty, one piece a line below ``indent`` (its line's whitespace), or one
    line when the layout is compact (``indent`` None)."""
    if not pieces:
        return text[open_] + text[close]
    if not spans:
        if indent is None:
            return text[open_] + ", ".join(pieces) + text[close]
        inner = indent + " "
        body = (",\n" + inner).join(pieces)
        return f"{text[open_]}\n{inner}{body}\n{indent}{text[close]}"
    head = text[open_ : spans[0][0]]
    tail = text[spans[-1][1] : close + 1]
    if len(spans) > 1:
        sep = text[spans[0][1] : spans[1][0]]
    else:
        sep = "," + head[1:] if "\n" in head else ", "
    return head + sep.join(pieces) + tail


def _value(text: str, start: int, end: int, old: Any, new: Any, indent: str | None) -> str:
    """The text of a value that was ``old`` (at ``text[start:end]``, on a line indented by
    ``indent``, None: compact) and is to be ``new``."""
    if _same(old, new):
        return text[start:end]
    if isinstance(old, list) and isinstance(new, list):
        kept = _kept(old, new)
        if kept is not None:
            close, spans = _items(text, start)
            if spans:
                inner = _indent_at(text, spans[0][0])
            else:
                inner = None if indent is None else indent + " "
            pieces = [
                text[spans[k][0] : spans[k][1]] if k is not None else _dump(v, inner)
                for k, v in zip(kept, new, strict=True)
            ]
            return _join(text, start, close, spans, pieces, indent)
    return _dump(new, indent)


def _kept(old: list, new: list) -> list[int | None] | None:
    """For each item of ``new``, the index of the ``old`` item it is (None: a new item), when
    ``new`` is ``old`` with items removed and then items appended; else None."""
    out: list[int | None] = []
    k = 0
    for v in new:
        while k < len(old) and not _same(old[k], v):
            k += 1
        if k == len(old):
            break
        out.append(k)
        k += 1
    out += [None] * (len(new) - len(out))
    return out if len(out) == len(new) else None


def _same(a: Any, b: Any) -> bool:
    """JSON equality (``1 == 1.0`` but ``True != 1``)."""
    return type(a) is type(b) and a == b if isinstance(a, bool) or isinstance(b, bool) else a == b


def splice_object(text: str, new: dict) -> str | None:
    """``text`` (a JSON object, whatever whitespace around it) rewritten to hold ``new``,
    keeping the bytes of what did not change (module docstring); None when that cannot be done
    (not an object, or a result that would not read back as ``new``)."""
    try:
        start = _skip(text, 0)
        close, members = _members(text, start)
        old = json.loads(text)
        if not isinstance(old, dict):
            return None
        pieces, seen = [], set()
        for key, key_start, value_start, value_end in members:
            if key not in new or key in seen:
                continue  # a key dropped (or a repeated one, which reads as its last)
            seen.add(key)
            indent = _indent_at(text, key_start)
            value = _value(text, value_start, value_end, old[key], new[key], indent)
            pieces.append(text[key_start:value_start] + value)
        indent = _indent_at(text, members[0][1]) if members else None
        for key, value in new.items():
            if key not in seen:
                pieces.append(json.dumps(key) + ": " + _dump(value, indent))
        spans = [(m[1], m[3]) for m in members]
        body = _join(text, start, close, spans, pieces, _indent_at(text, start))
        result = text[:start] + body + text[close + 1 :]
        return result if json.loads(result) == new else None
    except (ValueError, IndexError, RecursionError):
        return None
