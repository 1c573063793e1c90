"""What the server writes into the Annotate tab's edit widgets: :class:`ServerWrites`.

viser runs a browser's widget callbacks on worker threads, and they read the widget's value
when they run; a value the browser sent whose callback is still queued is a *pending edit*.
Writing the draft's older value over it would silently undo what the person typed, so every
write of the tab into an edit widget goes through :class:`ServerWrites`, which remembers what it
last wrote into each widget and leaves a widget alone while the browser's value differs from it.
"""

from __future__ import annotations

import viser


class ServerWrites:
    """The values the server last wrote into each edit widget of one tab (by ``id``).

    Not thread-safe by itself: the panel calls it holding ``session.lock``.
    """

    def __init__(self) -> None:
        self._shown: dict[int, object] = {}

    def pending(self, handle: viser.GuiInputHandle) -> bool:
        """Whether the browser changed ``handle`` since the server last wrote it."""
        key = id(handle)
        return key in self._shown and handle.value != self._shown[key]

    def show(self, handle: viser.GuiInputHandle, value: object) -> None:
        """Write the draft's ``value`` into ``handle`` unless an edit of the browser is pending."""
        if self.pending(handle):
            return
        handle.value = value
        self._shown[id(handle)] = handle.value

    def show_choice(
        self, handle: viser.GuiDropdownHandle, options: tuple[str, ...], value: str
    ) -> None:
        """New ``options`` for a dropdown and the draft's ``value`` in it, as :meth:`show`: the
        browser's pending choice is kept while it is still offered. viser puts a dropdown whose
        value is no longer offered on its first option; that is the server's write, not the
        browser's, so the draft's value is written after it (the *Box* list names the selected
        box however its entry's text changed: "#1 Car · 14.1 m" becomes "... 15.1 m")."""
        browser, pending = handle.value, self.pending(handle)
        handle.options = options
        if pending and browser in options:
            return
        handle.value = value
        self._shown[id(handle)] = handle.value

    def accept(self, handle: viser.GuiInputHandle) -> None:
        """The browser's value of ``handle`` is being applied now: it is no longer pending."""
        self._shown[id(handle)] = handle.value
