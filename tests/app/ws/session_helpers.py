"""Connecting a websocket client to a served app the way the Annotate-tab tests need it: the
scene drawn, the tab built, the server's session and that session's annotation panel."""

from __future__ import annotations

from collections.abc import Iterable


def connect_annotating(app, ws_client, nodes: Iterable[str], what: str):
    """A client on ``app`` once its scene holds ``nodes`` and the Annotate tab is built, with the
    server's session of it and that session's panel (its draft on a frame): ``(client, session,
    panel)``."""
    wanted = set(nodes)
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(lambda: wanted <= set(client.nodes) and "Save pair" in client.gui, 20, what)
    session = app.sessions[(set(app.sessions) - before).pop()]
    panel = next(p for p in app.annotations.panels() if p.session is session)
    client.pump_until(lambda: panel.frame is not None, 5, "the draft's frame")
    return client, session, panel
