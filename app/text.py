"""The one escaping helper: text that came from a user or a file, made safe for viser markdown.

viser 1.1.1 renders ``gui.add_markdown`` content with react-markdown, GitHub-flavoured markdown
and *raw HTML* (its ``rehypeRawDom`` parses embedded HTML unsanitised, ``<script>`` included), so
a prompt such as ``<img src=x onerror=...>`` or ``![t](http://host/x.png)`` saved by one browser
would run or fetch in every browser that shows it. Every piece of text that did not come from
this code (prompts, annotator names, class names of a draft, split names of the manifest, file
paths, exception messages) goes through :func:`md_text` before it is put into markdown.

How: CommonMark lets a backslash escape any ASCII punctuation character, and an escaped character
is always shown literally. So every ASCII punctuation character is escaped, which disarms HTML
tags and entities (``<``, ``&``), links and images (``!``, ``[``, ``]``, ``(``), emphasis (``*``,
``_``, ``~``), code spans (`````), table cells (``|``), headings, lists and quotes at a line's
start (``#``, ``-``, ``+``, ``>``, ``1.``) and GFM's bare-URL autolinks (``www.``, ``http:``, an
``@``). Line breaks become spaces (a line break could end a table row or start a block).
Letters, digits and non-ASCII text are kept as they are, so the text reads the same.
"""

from __future__ import annotations

import string

_ESCAPES = str.maketrans(
    {c: "\\" + c for c in string.punctuation} | {"\r": " ", "\n": " ", "\0": " "}
)


def md_text(text: object) -> str:
    """``str(text)`` shown literally inside viser markdown (inline: one line, any context, also a
    table cell); see the module docstring."""
    return str(text).translate(_ESCAPES)


__all__ = ["md_text"]
