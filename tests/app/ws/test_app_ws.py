"""Integration test: the app on port 0, driven through its websocket as a browser would.

The client (the ``ws_client`` fixture, :class:`tests.conftest.BrowserLikeClient`) speaks viser
1.1.1's protocol (spec §7): it registers with a ``ViewerCameraMessage``, then sends
``GuiUpdateMessage`` s (typing into the prompt box, clicking buttons) and decodes the server's
frames to track which scene nodes exist and which notifications were shown. The model is the real
small TPCNet with its default MiniLM text encoder, untrained (fixed seed), and every test runs on
both grounding paths (the ``grounding`` fixture): the paper's and the shipped referent path.
"""

from __future__ import annotations

import pytest

from app.query.answer_words import answer_sentence
from app.text import md_text
from scenes.talk2radar.layout import VELODYNE, sample_file, split_dir
from tests.app.ws.markdown_helpers import assert_only_text


@pytest.fixture(scope="module")
def running_app(
    tmp_path_factory, write_tiny_root, torch_threads, serve_app, untrained_model, grounding
):
    root = write_tiny_root(tmp_path_factory.mktemp("ws") / "root")
    with torch_threads(1):
        model = untrained_model(grounding)
        assert model.cfg.grounding == grounding
        with serve_app(root, model, model_note="test note") as app:
            yield app


def _connected(app, ws_client, timeout: float = 15.0):
    client = ws_client(app.port)
    client.pump_until(
        lambda: (
            "/scene/lidar" in client.nodes and "Run" in client.gui and "/gt/edges" in client.nodes
        ),
        timeout,
        "the scene and the panel",
    )
    return client


def _newest_session(app):
    """The session of the browser that connected last (``app.sessions`` keeps connection order):
    this test's, not an earlier test's whose disconnect the server may still be handling (such a
    session leaves the navigator, and stops being told of changes, at any moment)."""
    return [s for s in app.sessions.values() if s.nav is not None][-1]


def test_prompt_run_enter_and_empty_prompt(running_app, ws_client) -> None:
    app = running_app
    client = _connected(app, ws_client)
    try:
        assert {"/scene/radar", "/scene/rings", "/scene/ego"} <= set(client.nodes)
        assert any("test note" in text for text in client.markdown.values())
        # Type a prompt and press Run (threshold 0 so that the untrained model returns boxes).
        client.set("Score threshold", 0.0)
        client.set("Prompt", "the car about 15 m ahead")
        client.click("Run")

        def answered():  # the session that recorded this prompt's answer (the server records
            # it after the boxes go out: wait for both, under load they come apart)
            for s in list(app.sessions.values()):
                if s.answer is not None and s.answer.prompt == "the car about 15 m ahead":
                    return s
            return None

        client.pump_until(
            lambda: "/pred/edges" in client.nodes and "/heatmap" in client.nodes and answered(),
            30,
            "predicted boxes, the heatmap and the answer recorded",
        )
        session = answered()
        assert session is not None
        assert client.nodes["/heatmap"] == "ImageMessage"
        assert client.nodes["/pred/edges"] == "LineSegmentsMessage"
        assert "/pred/labels/0" in client.nodes
        assert session.answer is not None and session.answer.prompt == "the car about 15 m ahead"
        assert len(session.answer.predictions.boxes) == session.pred_view.count > 0
        assert session.query.history.options[0] == "the car about 15 m ahead"
        # The answer is said in words above the table, as the browser received it.
        said = md_text(answer_sentence(session.answer.prompt, session.answer.predictions.classes))
        client.pump_until(
            lambda: any(t.startswith(said) for t in client.markdown.values()), 10, "the words"
        )

        # Enter in the prompt box (a line break in the value) runs the new prompt.
        client.set("Prompt", "a cyclist on the left\n")
        client.pump_until(
            lambda: session.answer is not None and session.answer.prompt == "a cyclist on the left",
            30,
            "the prompt sent with Enter",
        )
        assert session.query.prompt.value == "a cyclist on the left"
        assert app.engine.encode_calls == 1  # the frame was encoded once, not per prompt

        # An empty prompt yields a notification, not a crash; the app keeps answering.
        client.set("Prompt", "   ")
        client.click("Run")
        client.pump_until(
            lambda: any(t == "Empty prompt" for t, _ in client.notifications), 10, "a notification"
        )
        client.set("Prompt", "the car\n")
        client.pump_until(
            lambda: session.answer is not None and session.answer.prompt == "the car",
            30,
            "an answer after the empty prompt",
        )
    finally:
        client.close()


def test_model_error_is_a_notification(running_app, monkeypatch, ws_client) -> None:
    app = running_app
    client = _connected(app, ws_client)
    try:

        def broken(*args, **kwargs):
            raise RuntimeError("simulated model failure")

        monkeypatch.setattr(app.engine.model, "ground", broken)
        client.set("Prompt", "the car\n")
        client.pump_until(
            lambda: any(t == "Model error" for t, _ in client.notifications), 20, "the error"
        )
        assert any("simulated model failure" in body for _, body in client.notifications)
        monkeypatch.undo()
        client.set("Prompt", "the car ahead\n")
        client.pump_until(lambda: "/pred/edges" in client.nodes, 30, "boxes after the error")
    finally:
        client.close()


def test_two_browsers_share_the_scene_not_the_answers(running_app, ws_client) -> None:
    app = running_app
    before = set(app.sessions)
    a = _connected(app, ws_client)
    session_a = app.sessions[(set(app.sessions) - before).pop()]
    b = _connected(app, ws_client)
    try:
        # While A's prompt waits for the model (its lock held here), B's GUI stays responsive.
        lock = app.engine._model_lock
        lock.acquire()
        try:
            a.set("Score threshold", 0.0)
            a.set("Prompt", "the car ahead\n")
            b.pump_until(lambda: b.visible.get("/scene/lidar") is True, 5, "B's scene")
            b.set("Show LiDAR", False)
            b.pump_until(lambda: b.visible.get("/scene/lidar") is False, 3, "B's layer toggle")
        finally:
            lock.release()
        a.pump_until(  # the boxes reach the browser as the server records the answer
            lambda: "/pred/edges" in a.nodes and session_a.answer is not None, 30, "A's answer"
        )
        b.drain(0.5)
        assert "/pred/edges" not in b.nodes  # answers are per browser

        # Navigation is shared: B clicks Next, both browsers get the next frame.
        start = app.frame.index
        a_points = sum(m.get("name") == "/scene/lidar" for m in a.messages)
        b.click("Frame", "Next")
        a.pump_until(
            lambda: sum(m.get("name") == "/scene/lidar" for m in a.messages) > a_points,
            10,
            "A's new frame",
        )
        assert app.frame.index == (start + 1) % len(app.frames)
        assert "/pred/edges" not in a.nodes  # A's old answer is cleared with the frame
        assert session_a.frame.index == app.frame.index

        # A frame number out of range is clamped to the split on the server (as the browser's
        # own field does when it loses focus), and the clamped value is sent back to it.
        b.set("Frame #", 99)
        last = len(app.frames)
        b.pump_until(lambda: app.frame.index == last - 1, 10, "the last frame")
        b.pump_until(
            lambda: any(
                m["type"] == "GuiUpdateMessage"
                and m["uuid"] == b.gui["Frame #"]
                and m["updates"].get("value") == last
                for m in b.messages
            ),
            10,
            "the clamped frame number",
        )
    finally:
        a.close()
        b.close()


def test_reload_frames_updates_the_panels(running_app, ws_client, write_tiny_root) -> None:
    app = running_app
    client = _connected(app, ws_client)
    try:
        session = _newest_session(app)
        count = len(app.frames)
        write_tiny_root(app.frames.root.path, frames=count + 1)
        app.reload_frames()
        assert len(app.frames) == count + 1
        assert session.nav.frame_number.max == count + 1
        app.go_to(count)  # the new frame
        client.pump_until(lambda: session.frame.index == count, 10, "the new frame")
        app.go_to(0)
    finally:
        client.close()


def test_failed_load_is_a_notification(running_app, ws_client) -> None:
    app = running_app
    client = _connected(app, ws_client)
    try:
        target = (app.frame.index + 1) % len(app.frames)
        bad_id = app.frames.ids[target]
        app.frames._cache.pop(target, None)
        velodyne = sample_file(app.frames.root.lidar_dir, VELODYNE, bad_id)
        original = velodyne.read_bytes()
        velodyne.write_bytes(original[:-3])  # not a multiple of 4 floats any more
        try:
            before = app.frame.index
            client.click("Frame", "Next")
            client.pump_until(
                lambda: any(t.startswith("Could not load frame") for t, _ in client.notifications),
                10,
                "the load error",
            )
            assert app.frame.index == before
        finally:
            velodyne.write_bytes(original)
        client.click("Frame", "Next")
        client.pump_until(lambda: app.frame.index == target, 10, "the repaired frame")
    finally:
        client.close()


# ---------------------------------------------------------------------------- reliability (issue 11)

HOSTILE_TEXT = "<img src=x onerror=alert(1)> <b>b</b> ![t](http://host/x.png)"


def test_a_hostile_prompt_is_shown_as_text(running_app, ws_client) -> None:
    app = running_app
    client = _connected(app, ws_client)
    try:
        client.set("Prompt", HOSTILE_TEXT + "\n")

        def running() -> list[str]:
            return [
                m["updates"]["_markdown"]
                for m in client.messages
                if m["type"] == "GuiUpdateMessage"
                and "Running" in m["updates"].get("_markdown", "")
            ]

        client.pump_until(lambda: bool(running()), 30, "the Running: line")
        lines = running()
        assert lines and all("onerror" in text for text in lines)
        for text in lines:
            assert_only_text(text)
    finally:
        client.close()


def test_stored_text_and_forged_splits(running_app, ws_client, gt_box) -> None:
    """A saved pair's prompt and annotator are shown as text in the Annotate table; a split name
    forged through the websocket is refused by the server and saving keeps working."""
    from annotate import AnnotationStore, Draft, SourceFrame

    app = running_app
    root = app.frames.root
    store = app.annotations.store
    assert store is not None
    pair = Draft().set_prompt(HOSTILE_TEXT).add_box(gt_box, "Car")
    store.create(pair, SourceFrame.from_root(root, root.ids("test")[0]), annotator=HOSTILE_TEXT)
    before = set(app.sessions)
    client = _connected(app, ws_client)
    try:
        session = app.sessions[(set(app.sessions) - before).pop()]
        panel = next(p for p in app.annotations.panels() if p.session is session)
        client.pump_until(lambda: "Save pair" in client.gui and panel.frame is not None, 15, "tab")
        tables = [text for text in client.markdown.values() if "saved pair(s)" in text]
        assert tables and "onerror" in tables[0]
        assert_only_text(tables[0])

        lists = sorted(split_dir(root.lidar_dir).iterdir())
        with session.lock:
            panel.editor.reset(Draft().set_prompt("the car ahead").add_box(gt_box, "Car"))
        # Not an option: only a forged message can send it, and the server refuses it (the
        # dropdown keeps an offered split; the store would refuse the name too).
        client.set("Split", "a" * 300)
        client.click("Save pair")
        client.pump_until(
            lambda: any(t.startswith("Saved pair") for t, _ in client.notifications), 10, "saved"
        )
        assert panel.w.split.value == "train"
        assert sorted(split_dir(root.lidar_dir).iterdir()) == lists  # no junk list
        assert len(AnnotationStore(root.path).pairs()) == 2
    finally:
        client.close()
