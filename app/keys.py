"""A keyboard helper the viser 1.1.1 client lacks: **Esc leaves a text field**.

viser's hotkeys (``gui.add_command``: the Annotate tab's undo, redo, delete, save) act only while
no text field has the focus, and the client offers no key to leave a field: the way out was a
click elsewhere, and a click in the 3D view is a click on the scene (the Annotate tab places a
box there). Tab moves the focus on to the next control, which Enter or Space would then press.

:func:`add_escape_leaves_fields` adds, to one browser's page, a listener that takes the focus
away from the focused text field (``input`` or ``textarea``) when Esc is pressed, so the next
keys reach the hotkeys and the next click reaches the scene as before. How: ``gui.add_html``
renders raw HTML, so a hidden image with an empty ``data:`` source fails to load and runs its
``onerror`` handler. The handler is this module's constant (no text from a user or a file is
in it) and installs the listener once per page (a flag on ``window``), however often it runs.
"""

from __future__ import annotations

import viser

ESCAPE_LISTENER = (
    "if(!window.__talk2pcEscape){window.__talk2pcEscape=true;"
    "document.addEventListener('keydown',function(e){var t=e.target;"
    "if(e.key==='Escape'&&t&&(t.tagName==='TEXTAREA'||t.tagName==='INPUT')){t.blur();}},true);}"
)
"""The page-side code: blur the focused text field on Esc (installed once per page)."""

ESCAPE_HTML = f'<img alt="" src="data:," style="display:none" onerror="{ESCAPE_LISTENER}">'
"""The element that runs :data:`ESCAPE_LISTENER` in the browser."""


def add_escape_leaves_fields(gui: viser.GuiApi) -> viser.GuiHtmlHandle:
    """Make Esc leave a text field in this browser (see the module docstring)."""
    return gui.add_html(ESCAPE_HTML)
