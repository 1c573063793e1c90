"""The Query tab's answer after a refused prompt, and the threshold it opens at (issue 39.8),
through the app's websocket.

- A refused prompt (empty, control characters, over-long, invisible characters) removes the
  previous answer from the view: its boxes, its heatmap, its camera boxes and its summary; the
  summary says why nothing ran. An answer still running for the previous prompt is not drawn.
- The app opens at the checkpoint's operating threshold, and docs/APP.md states that figure for
  the shipped checkpoint.
"""

from __future__ import annotations

import re

import pytest

from tests.paths import REPO

REFUSED = ("\n", "the car\x00 ahead\n", "the car\u200b ahead\n", "x" * 501 + "\n", "  \t \n")
"""Prompts the Query tab refuses (Enter included): empty, NUL, a zero-width space, too long,
blank."""


@pytest.fixture(scope="module")
def query_app(tmp_path_factory, write_tiny_root, torch_threads, serve_app, untrained_model):
    root = write_tiny_root(tmp_path_factory.mktemp("refusals") / "root", frames=1)
    with torch_threads(1):
        model = untrained_model(
            "tpcnet", text_encoder="gru", head__score_threshold=0.0, operating_threshold=0.0
        )
        with serve_app(root, model) as app:
            yield app


def _connect(app, ws_client):
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(lambda: "/scene/lidar" in client.nodes and "Prompt" in client.gui, 30, "")
    client.pump_until(lambda: set(app.sessions) - before, 30, "the session")
    session = app.sessions[(set(app.sessions) - before).pop()]
    client.pump_until(lambda: session.frame is not None, 10, "the frame")
    return client, session


def _answer_nodes(client) -> list[str]:
    """The answer's boxes, labels and heatmap in the browser's scene (not their group frames)."""
    return [
        n
        for n, kind in client.nodes.items()
        if n.startswith(("/pred", "/heatmap")) and kind != "FrameMessage"
    ]


@pytest.mark.parametrize("refused", REFUSED, ids=["empty", "nul", "zwsp", "long", "blank"])
def test_a_refused_prompt_clears_the_previous_answer(query_app, ws_client, refused) -> None:
    client, session = _connect(query_app, ws_client)
    try:
        client.set("Prompt", "the car ahead\n")
        client.pump_until(lambda: session.answer is not None, 60, "the answer")
        client.pump_until(lambda: bool(_answer_nodes(client)), 10, "its boxes and heatmap")
        camera = session.camera
        assert camera is not None and camera.layer("pred") is not None
        client.set("Prompt", refused)
        client.pump_until(
            lambda: any(t in ("Empty prompt", "Prompt not run") for t, _ in client.notifications),
            10,
            "the refusal",
        )
        client.pump_until(lambda: not _answer_nodes(client), 10, "the answer removed")
        assert session.answer is None and camera.layer("pred") is None
        assert "Not run" in session.query.results.content
        assert "the car ahead" not in session.query.results.content
    finally:
        client.close()


def test_a_refusal_drops_the_answer_still_running(query_app, ws_client) -> None:
    client, session = _connect(query_app, ws_client)
    try:
        client.set("Prompt", "the cyclist on the left\n")
        client.pump_until(
            lambda: session.query.results.content.startswith("*Running:*"), 10, "the run"
        )
        client.set("Prompt", "\n")  # as a rule before the first answer comes back
        client.pump_until(
            lambda: any(t == "Empty prompt" for t, _ in client.notifications), 10, "the refusal"
        )
        client.drain(3.0)  # the first prompt's answer would have been drawn by now
        assert session.answer is None and not _answer_nodes(client)
    finally:
        client.close()


def test_the_app_opens_at_the_calibrated_threshold_the_docs_state(
    tmp_path, write_tiny_root, torch_threads, serve_app, ws_client
) -> None:
    from model import operating_threshold
    from model.checkpoint import load_checkpoint

    text = (REPO / "docs" / "APP.md").read_text()
    stated = re.search(r"([0-9.]+) for the shipped\s+referent checkpoint", text)
    assert stated is not None, "docs/APP.md no longer states the shipped checkpoint's threshold"
    root = write_tiny_root(tmp_path / "root", frames=1)
    with torch_threads(1):
        model = load_checkpoint(REPO / "checkpoints" / "tpcnet-small.pt")
        calibrated = operating_threshold(model)
        with serve_app(root, model, warm_up=False) as app:
            client = ws_client(app.port)
            try:
                client.pump_until(lambda: "Score threshold" in client.gui, 30, "the slider")
                uuid = client.gui["Score threshold"]
                shown = next(
                    m["value"]
                    for m in client.messages
                    if m.get("uuid") == uuid and m["type"] == "GuiSliderMessage"
                )
            finally:
                client.close()
    assert shown == pytest.approx(calibrated) == pytest.approx(float(stated.group(1)))
