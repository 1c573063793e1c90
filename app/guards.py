"""Forged or malformed messages from a browser: refused or clamped on the server, one warning
line per connection, never a traceback.

What viser 1.1.1 does with a browser's ``GuiUpdateMessage`` on its own: it casts the value to the
type of the widget's value (``float("abc")`` raises, ``bool([1, 2])`` is True, ``str(None)`` is
``"None"``, ``int(nan)`` raises), sets any property the message names (``min``, ``options``,
``disabled``: the web client only ever sends ``value``), and has no notion of a widget's range, so
a forged NaN, -1 or 1e308 reaches the app's callbacks. A handler that raises is logged by asyncio
as a full traceback ("Task exception was never retrieved"), from any connection, for every message.

So every handler viser registers for a connection's messages is wrapped (:func:`guard_client`,
and :func:`guard_server` for the server-wide ones) by our code, without touching viser's files:

- **GUI updates are checked before viser applies them** (:func:`check_gui_update`): only
  ``value`` may change; a button takes ``True``, a button group and a dropdown one of their
  options, a checkbox a bool, a text field a string of at most :data:`MAX_TEXT_CHARS`, a slider or
  number field a finite real number (not a bool), **clamped to the widget's own min..max** and
  made an integer for an integer field. Every numeric widget of the app declares its range where
  it is built (``add_slider``, ``add_number``), so the range lives in one place per widget. A
  refused update is dropped; a clamped one is applied clamped. Either way the widget's value is
  sent back to that browser, so its view shows a valid value again.
- **Scene messages** (clicks, gizmo drags, the camera) holding a number that is not finite or is
  larger than :data:`MAX_COORDINATE` metres are dropped, and so is a camera report viser could
  not turn into a pose (:func:`check_camera`).
- **A handler that raises anyway** is reported as one warning line, not a traceback.

Warnings go through :class:`InputWarnings`: the first refusal of a connection is logged at once as
one line (which widget, what was wrong, the value cut to :data:`SHOWN_VALUE_CHARS`), later ones at
most every :data:`WARNING_INTERVAL` seconds with a count of those not logged, so 2,000 forged
messages cost a line or two of log. Two safety nets take what the wrappers cannot see: the event
loop's exception handler (a task that raised, e.g. in a handler registered later) and a filter on
the ``websockets.server`` logger (a message that does not even decode closes its connection, and
websockets would log the traceback): both write one rate-limited line (:class:`LogGuards`).
"""

from __future__ import annotations

import asyncio
import dataclasses
import inspect
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import viser
from viser import _messages as messages

log = logging.getLogger(__name__)

MAX_TEXT_CHARS = 10_000
"""The longest value a text field takes (the text policy caps prompts at 500, names at 64)."""

MAX_COORDINATE = 1.0e6
"""Largest magnitude (metres, or any number) a scene message may hold."""

WARNING_INTERVAL = 10.0
"""Seconds between two warning lines of one connection."""

MAX_SOURCES = 1024
"""Connections :class:`InputWarnings` remembers (the oldest are forgotten beyond)."""

SHOWN_VALUE_CHARS = 60
"""A forged value is shown in the log cut to this many characters."""

GUARDED = "_talk2pc_guarded"
"""Attribute set on a wrapped handler (a handler is never wrapped twice)."""

SCENE_MESSAGES = (
    messages.ScenePointerMessage,
    messages.SceneNodeClickMessage,
    messages.TransformControlsUpdateMessage,
    messages.ViewerCameraMessage,
)
"""Messages whose numbers are checked (:func:`check_numbers`)."""


class InputWarnings:
    """Rate-limited warning lines, one stream per connection (see the module docstring).

    Args:
        interval: Seconds between two lines of one connection.
        clock: Monotonic seconds (tests pass their own).
    """

    def __init__(
        self, interval: float = WARNING_INTERVAL, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.interval = interval
        self.clock = clock
        self._last: dict[object, float] = {}
        self._held: dict[object, int] = {}
        self._lock = threading.Lock()

    def warn(self, source: object, text: str) -> bool:
        """Log ``"<source>: <text>"`` unless ``source`` logged a line less than
        :attr:`interval` seconds ago (then it is counted into the next line). Returns whether
        a line was written."""
        with self._lock:
            now = self.clock()
            last = self._last.get(source)
            if last is not None and now - last < self.interval:
                self._held[source] = self._held.get(source, 0) + 1
                return False
            self._last.pop(source, None)  # (re)inserted last: the oldest are dropped first
            self._last[source] = now
            while len(self._last) > MAX_SOURCES:
                oldest = next(iter(self._last))
                del self._last[oldest]
                self._held.pop(oldest, None)
            held = self._held.pop(source, 0)
        more = f" ({held} more refused since the last line)" if held else ""
        log.warning("%s: %s%s", source, text, more)
        return True

    def forget(self, source: object) -> None:
        """Drop what is kept about ``source`` (its connection closed)."""
        with self._lock:
            self._last.pop(source, None)
            self._held.pop(source, None)


def shown(value: object) -> str:
    """``repr(value)`` cut to :data:`SHOWN_VALUE_CHARS` characters (a forged value may be huge)."""
    text = repr(value) if not isinstance(value, str) or len(value) < 1000 else repr(value[:100])
    return text if len(text) <= SHOWN_VALUE_CHARS else text[: SHOWN_VALUE_CHARS - 3] + "..."


@dataclasses.dataclass(frozen=True)
class Checked:
    """What :func:`check_gui_update` decided: the value to apply (None: refuse) and, when the
    value was refused or changed, why (one clause for the warning line)."""

    value: object | None
    problem: str | None = None


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def check_gui_update(handle: viser.GuiInputHandle, updates: object) -> Checked:
    """Check a browser's update of ``handle`` (see the module docstring)."""
    if not isinstance(updates, dict) or set(updates) != {"value"}:
        keys = sorted(map(str, updates)) if isinstance(updates, dict) else updates
        return Checked(None, f"only the value may change, not {shown(keys)}")
    value = updates["value"]
    if isinstance(handle, viser.GuiButtonHandle):
        return Checked(True) if value is True else Checked(None, f"a button got {shown(value)}")
    if isinstance(handle, viser.GuiButtonGroupHandle | viser.GuiDropdownHandle):
        if isinstance(value, str) and value in handle.options:
            return Checked(value)
        return Checked(None, f"{shown(value)} is not one of its options")
    if isinstance(handle, viser.GuiCheckboxHandle):
        return Checked(value) if isinstance(value, bool) else Checked(None, "not a bool")
    if isinstance(handle, viser.GuiTextHandle):
        if not isinstance(value, str):
            return Checked(None, f"not text: {shown(value)}")
        if len(value) > MAX_TEXT_CHARS:
            return Checked(None, f"{len(value):,} characters, at most {MAX_TEXT_CHARS:,}")
        return Checked(value)
    if isinstance(handle, viser.GuiSliderHandle | viser.GuiNumberHandle):
        return _check_number(handle, value)
    return Checked(value)


def _check_number(handle: viser.GuiSliderHandle | viser.GuiNumberHandle, value: object) -> Checked:
    number = _number(value)
    if number is None or not math.isfinite(number):
        return Checked(None, f"not a finite number: {shown(value)}")
    low, high = handle.min, handle.max
    clamped = number
    if low is not None:
        clamped = max(clamped, float(low))
    if high is not None:
        clamped = min(clamped, float(high))
    if abs(clamped) > MAX_COORDINATE:
        return Checked(None, f"{shown(value)} is out of range")
    result: float | int = round(clamped) if isinstance(handle.value, int) else clamped
    if clamped != number:
        return Checked(result, f"{shown(value)} clamped to {result} (range {low}..{high})")
    return Checked(result)


def check_numbers(message: object) -> str | None:
    """Why a scene message is refused (a number that is not finite or is too large), or None."""

    def bad(value: object) -> bool:
        if isinstance(value, tuple | list):
            return any(bad(v) for v in value)
        number = _number(value)
        return number is not None and not (math.isfinite(number) and abs(number) <= MAX_COORDINATE)

    for field in dataclasses.fields(message):  # type: ignore[arg-type]
        value = getattr(message, field.name, None)
        if bad(value):
            return f"{field.name} = {shown(value)} is not a finite number within {MAX_COORDINATE:g}"
    return None


def check_camera(message: messages.ViewerCameraMessage) -> str | None:
    """Why a camera report is refused (one viser cannot turn into a camera pose: the position on
    the look-at point, a zero up or rotation, a field of view outside ``(0, pi)``, clipping
    planes not ``0 < near < far``, an empty image), or None."""

    def norm(v: object) -> float:
        return math.sqrt(sum(float(x) ** 2 for x in v))  # type: ignore[union-attr]

    m = message
    try:
        offset = [float(a) - float(b) for a, b in zip(m.position, m.look_at, strict=True)]
        if norm(offset) < 1e-9 or norm(m.up_direction) < 1e-9 or norm(m.wxyz) < 1e-9:
            return "a degenerate camera (zero look distance, up or rotation)"
        if not (0.0 < float(m.fov) < math.pi and 0.0 < float(m.near) < float(m.far)):
            return f"fov {shown(m.fov)}, near {shown(m.near)}, far {shown(m.far)}"
        if int(m.image_width) < 1 or int(m.image_height) < 1:
            return f"an image of {shown(m.image_width)} x {shown(m.image_height)} pixels"
    except (TypeError, ValueError):
        return "a camera field that is not a number or not three numbers"
    return None


def _send_value(handle: viser.GuiInputHandle, value: object) -> None:
    """Send ``value`` as the widget's value to the browser(s) its GUI belongs to (viser sends
    nothing back to the browser whose update it applies)."""
    impl = handle._impl
    impl.gui_api._websock_interface.queue_message(
        messages.GuiUpdateMessage(impl.uuid, {"value": value})
    )


Vetted = tuple[Any, Callable[[], None] | None]
"""What a vetter returns: the message to handle (None: drop it) and what to do after."""


def _wrap(
    handler: Callable[..., Any],
    vet: Callable[[int, Any], Vetted],
    warnings: InputWarnings,
    describe: Callable[[int], object],
) -> Callable[..., Any]:
    """``handler(client_id, message)`` run on what ``vet(client_id, message)`` returns (None:
    drop it), then its ``after()``; an exception becomes one warning line."""
    if getattr(handler, GUARDED, False):
        return handler

    def failed(client_id: int, message: object, exc: Exception) -> None:
        warnings.warn(
            describe(client_id),
            f"{type(message).__name__} failed: {type(exc).__name__}: {shown(str(exc))}",
        )

    if inspect.iscoroutinefunction(handler):

        async def guarded(client_id: int, message: object) -> None:
            try:
                vetted, after = vet(client_id, message)
                if vetted is not None:
                    await handler(client_id, vetted)
                if after is not None:
                    after()
            except Exception as exc:
                failed(client_id, message, exc)

    else:

        def guarded(client_id: int, message: object) -> None:  # type: ignore[misc]
            try:
                vetted, after = vet(client_id, message)
                if vetted is not None:
                    handler(client_id, vetted)
                if after is not None:
                    after()
            except Exception as exc:
                failed(client_id, message, exc)

    setattr(guarded, GUARDED, True)
    return guarded


class MessageGuard:
    """Wraps the message handlers of one viser scope (a connection, or the server) with the
    checks of the module docstring.

    Args:
        gui: The scope's GUI (``client.gui`` or ``server.gui``): where widgets are looked up.
        warnings: Where refusals are reported.
        describe: The name of a connection in warning lines (``"client 3"``).
    """

    def __init__(
        self,
        gui: viser.GuiApi,
        warnings: InputWarnings,
        describe: Callable[[int], object] = lambda cid: f"client {cid}",
    ) -> None:
        self.gui = gui
        self.warnings = warnings
        self.describe = describe

    def install(self, handlers: dict[type, list[Callable[..., Any]]]) -> None:
        """Wrap every handler in ``handlers`` (viser's table: message type -> callbacks)."""
        for kind, callbacks in list(handlers.items()):
            callbacks[:] = [
                _wrap(cb, self._vetter(kind), self.warnings, self.describe) for cb in callbacks
            ]

    def _vetter(self, kind: type) -> Callable[[int, Any], Vetted]:
        if kind is messages.GuiUpdateMessage:
            return self.vet_gui_update
        if kind in SCENE_MESSAGES:
            return self.vet_scene
        return lambda _client_id, message: (message, None)

    def vet_scene(self, client_id: int, message: Any) -> Vetted:
        problem = check_numbers(message)
        if problem is None and isinstance(message, messages.ViewerCameraMessage):
            problem = check_camera(message)
        if problem is None:
            return message, None
        self.warnings.warn(self.describe(client_id), f"{type(message).__name__} refused: {problem}")
        return None, None

    def vet_gui_update(self, client_id: int, message: Any) -> Vetted:
        """The update as applied (refused: None, clamped: a new message) and, when it was not
        applied as sent, sending the widget's value back to the browser after viser applied it
        (viser's own echo to the other browsers would otherwise replace ours in the buffer)."""
        uuid = message.uuid
        if not isinstance(uuid, str):
            self.warnings.warn(self.describe(client_id), f"GUI update with uuid {shown(uuid)}")
            return None, None
        handle = self.gui._gui_input_handle_from_uuid.get(uuid)
        if handle is None:
            return message, None  # another scope's widget (or one removed): viser ignores it
        checked = check_gui_update(handle, message.updates)
        if checked.problem is None:
            return messages.GuiUpdateMessage(uuid, {"value": checked.value}), None
        self.warnings.warn(
            self.describe(client_id),
            f"GUI update of {shown(handle.label)} "
            f"{'refused' if checked.value is None else 'clamped'}: {checked.problem}",
        )
        echo = lambda: _send_value(handle, handle.value)  # noqa: E731
        if checked.value is None:
            return None, echo
        return messages.GuiUpdateMessage(uuid, {"value": checked.value}), echo


def guard_client(client: viser.ClientHandle, warnings: InputWarnings) -> None:
    """Wrap the handlers viser registered for ``client``'s connection (call it when the client
    connects; the handlers exist by then)."""
    MessageGuard(client.gui, warnings).install(client._websock_connection._incoming_handlers)


def guard_server(server: viser.ViserServer, warnings: InputWarnings) -> None:
    """Wrap the server-wide handlers (they see every connection's messages)."""
    MessageGuard(server.gui, warnings).install(server._websock_server._incoming_handlers)


class _HandlerFailedFilter(logging.Filter):
    """websockets' "connection handler failed" (a message that does not decode: the connection
    closes) as one rate-limited line instead of a traceback."""

    def __init__(self, warnings: InputWarnings) -> None:
        super().__init__()
        self.warnings = warnings

    def filter(self, record: logging.LogRecord) -> bool:
        if record.msg != "connection handler failed" or not record.exc_info:
            return True
        exc = record.exc_info[1]
        peer = getattr(getattr(record, "websocket", None), "remote_address", None)
        source = f"connection {peer[0]}:{peer[1]}" if isinstance(peer, tuple) else "a connection"
        self.warnings.warn(
            source, f"closed on a bad message: {type(exc).__name__}: {shown(str(exc))}"
        )
        return False


class LogGuards:
    """The safety nets of the module docstring, for one server: installed by :meth:`install`,
    removed by :meth:`remove` (the websockets logger is the process's)."""

    def __init__(self, warnings: InputWarnings) -> None:
        self.warnings = warnings
        self._filter = _HandlerFailedFilter(warnings)
        self._logger = logging.getLogger("websockets.server")

    def install(self, server: viser.ViserServer) -> None:
        self._logger.addFilter(self._filter)
        loop = server._websock_server._background_event_loop
        if loop is not None:
            loop.call_soon_threadsafe(loop.set_exception_handler, self._loop_exception)

    def remove(self) -> None:
        self._logger.removeFilter(self._filter)

    def _loop_exception(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        exc = context.get("exception")
        if not isinstance(exc, Exception):
            loop.default_exception_handler(context)
            return
        what = context.get("message", "a task failed")
        self.warnings.warn("server", f"{what}: {type(exc).__name__}: {shown(str(exc))}")
