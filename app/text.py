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

One more step: remark-gfm links bare URLs and e-mail addresses *after* parsing, on the text with
its escapes already resolved, so ``http\\://host`` would still become a link. An empty HTML comment
(:data:`BREAK`, our own constant, invisible) after every ``:`` and ``@`` and after a ``www`` before
a dot splits the text where those links would start.
"""

from __future__ import annotations

import re
import string

_ESCAPES = str.maketrans(
    {c: "\\" + c for c in string.punctuation} | {"\r": " ", "\n": " ", "\0": " "}
)

BREAK = "<!-- -->"
"""Invisible; splits a text node so that GFM's bare-URL and e-mail autolinks cannot start."""

_AUTOLINK_STARTS = re.compile(r"(\\[:@]|(?i:www)(?=\\\.))")


def md_text(text: object) -> str:
    """``str(text)`` shown literally inside viser markdown (inline: one line, any context, also a
    table cell); see the module docstring."""
    return _AUTOLINK_STARTS.sub(lambda m: m.group(0) + BREAK, str(text).translate(_ESCAPES))


__all__ = ["BREAK", "md_text"]
