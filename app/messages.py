"""Messages in one browser: a notification, and an error logged on the server and shown.

The one place that calls viser's ``client.add_notification``: a browser that has left (its
connection closed) cannot take one, which is logged as one line, never raised.
"""

from __future__ import annotations

import logging

import viser

log = logging.getLogger(__name__)


def notify(
    client: viser.ClientHandle,
    title: str,
    body: str,
    *,
    color: str | None = None,
    auto_close_seconds: float | None = 6.0,
) -> None:
    """Show a notification in ``client``'s browser (a closed connection logs one line)."""
    try:
        client.add_notification(
            title,
            body,
            color=color,  # type: ignore[arg-type]
            auto_close_seconds=auto_close_seconds,
        )
    except Exception:  # The connection may be gone; the log keeps the message.
        log.warning("client %s: could not show notification %r", client.client_id, title)


def error_body(client: viser.ClientHandle, title: str, error: BaseException | str) -> str:
    """Log ``error`` (with its traceback when it is an exception: a bug, not a user's input) and
    return the notification body that shows it."""
    if isinstance(error, BaseException):
        log.error("client %s: %s: %s", client.client_id, title, error, exc_info=error)
        return f"{type(error).__name__}: {error}"
    log.error("client %s: %s: %s", client.client_id, title, error)
    return error
