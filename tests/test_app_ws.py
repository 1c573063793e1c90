"""Integration test: the app on port 0, driven through its websocket as a browser would.

The client below speaks viser 1.1.1's protocol (spec §7): it registers with a
``ViewerCameraMessage``, then sends ``GuiUpdateMessage`` s (typing into the prompt box, clicking
buttons) and decodes the server's frames (``[u64 raw][u64 zstd][zstd(msgpack)][binary]``) to
track which scene nodes exist and which notifications were shown. The model is the real small
TPCNet with its default MiniLM text encoder, untrained.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import msgspec
import numpy as np
import pytest
import viser
import zstandard
from websockets.sync.client import connect

from scenes.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.root import Talk2RadarWriter

GT_BOX = np.array([15.0, 2.0, -0.95, 4.2, 1.8, 1.5, 0.1])
TIMEOUT_SCALE = float(os.environ.get("TALK2PC_TEST_TIMEOUT_SCALE", "4"))
"""Multiplies every wait's timeout (``pump_until``); waits end as soon as their condition holds."""


def write_tiny_root(path: Path, frames: int = 3, seed: int = 0) -> Path:
    """A Talk2Radar root with ``frames`` test samples: a flat ground at z = -1.7, a car-sized
    cluster of points around :data:`GT_BOX` (its label), sparse radar with velocities."""
    rng = np.random.default_rng(seed)
    writer = Talk2RadarWriter(path)
    ids = []
    for i in range(frames):
        ground = np.c_[
            rng.uniform([1.0, -20.0], [50.0, 20.0], size=(4000, 2)),
            rng.normal(-1.7, 0.01, 4000),
            rng.uniform(0, 60, 4000),
        ]
        box = GT_BOX + np.array([i * 2.0, 0, 0, 0, 0, 0, 0])
        car = np.c_[
            rng.uniform(box[:3] - box[3:6] / 2, box[:3] + box[3:6] / 2, size=(600, 3)),
            rng.uniform(100, 255, 600),
        ]
        radar = np.c_[
            rng.uniform([2.0, -15.0, -1.5], [45.0, 15.0, 0.5], size=(80, 3)),
            rng.normal(5, 5, 80),
            rng.normal(0, 4, (80, 2)),
            -rng.integers(0, 5, 80),
        ]
        files = writer.write_sensors(
            f"f{i}",
            np.r_[ground, car].astype(np.float32),
            radar.astype(np.float32),
            vod_lidar_calibration(),
            vod_radar_calibration(),
        )
        ids.append(writer.write_sample(i, files, box[None], ["Car"], "the car about 15 m ahead"))
    writer.write_image_sets({"test": ids, "train": ids[:1]})
    return path


def _decode(frame: bytes) -> list[dict]:
    raw_len = int.from_bytes(frame[:8], "little")
    zstd_len = int.from_bytes(frame[8:16], "little")
    payload = zstandard.ZstdDecompressor().decompress(
        frame[16 : 16 + zstd_len], max_output_size=raw_len
    )
    return msgspec.msgpack.decode(payload)["messages"]


class BrowserLikeClient:
    """A websocket client that behaves like the viser web client, minus the rendering."""

    def __init__(self, port: int) -> None:
        self.ws = connect(
            f"ws://127.0.0.1:{port}",
            subprotocols=[f"viser-v{viser.__version__}"],
            max_size=None,
        )
        self.nodes: dict[str, str] = {}  # scene node name -> message type
        self.visible: dict[str, bool] = {}
        self.gui: dict[str, str] = {}  # label -> uuid
        self.notifications: list[tuple[str, str]] = []
        self.markdown: dict[str, str] = {}  # uuid -> content
        self.messages: list[dict] = []
        self._send(
            {
                "type": "ViewerCameraMessage",
                "wxyz": [1.0, 0.0, 0.0, 0.0],
                "position": [-10.0, 0.0, 5.0],
                "fov": 1.0,
                "near": 0.01,
                "far": 1000.0,
                "image_height": 600,
                "image_width": 800,
                "look_at": [10.0, 0.0, 0.0],
                "up_direction": [0.0, 0.0, 1.0],
            }
        )

    def _send(self, message: dict) -> None:
        self.ws.send(msgspec.msgpack.encode(message))

    def _handle(self, m: dict) -> None:
        self.messages.append(m)
        kind = m["type"]
        if kind == "RemoveSceneNodeMessage":
            for name in [n for n in self.nodes if n == m["name"] or n.startswith(m["name"] + "/")]:
                del self.nodes[name]
        elif kind == "SetSceneNodeVisibilityMessage":
            self.visible[m["name"]] = m["visible"]
        elif "name" in m and kind.endswith("Message") and "props" in m:
            self.nodes[m["name"]] = kind
        if kind == "NotificationShowMessage":
            self.notifications.append((m["props"]["title"], m["props"]["body"]))
        props = m.get("props")
        if kind.startswith("Gui") and isinstance(props, dict) and props.get("label"):
            self.gui[props["label"]] = m["uuid"]
        if kind == "GuiMarkdownMessage":
            self.markdown[m["uuid"]] = props["_markdown"]
        if kind == "GuiUpdateMessage" and "_markdown" in m.get("updates", {}):
            self.markdown[m["uuid"]] = m["updates"]["_markdown"]

    def pump_until(self, condition: Callable[[], bool], timeout: float, what: str) -> None:
        """Read messages until ``condition()`` holds; fail after ``timeout`` seconds, scaled by
        ``TIMEOUT_SCALE`` (a bound for a stalled server, not a speed check: a machine whose cores
        are busy with other jobs can be many times slower than an idle one)."""
        timeout *= TIMEOUT_SCALE
        deadline = time.monotonic() + timeout
        while not condition():
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"timed out after {timeout} s waiting for {what}")
            try:
                frame = self.ws.recv(timeout=min(left, 0.2))
            except TimeoutError:
                continue
            for m in _decode(frame):
                self._handle(m)

    def set(self, label: str, value: object) -> None:
        """Change an input as a user would (typing, selecting, dragging)."""
        self._send(
            {"type": "GuiUpdateMessage", "uuid": self.gui[label], "updates": {"value": value}}
        )

    def click(self, label: str, option: object = True) -> None:
        """Click a button (or one button of a button group)."""
        self.set(label, option)

    def drain(self, seconds: float) -> None:
        """Read whatever arrives during ``seconds``."""
        deadline = time.monotonic() + seconds
        self.pump_until(lambda: time.monotonic() >= deadline, seconds + 1.0, "nothing")

    def close(self) -> None:
        self.ws.close()


@contextlib.contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run with ``count`` torch CPU threads, as ``launch.py`` does (restored afterwards)."""
    import torch

    old = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(old)


@pytest.fixture(scope="module")
def running_app(tmp_path_factory):
    from app import AppConfig, Talk2PCApp
    from model import build_model

    root = write_tiny_root(tmp_path_factory.mktemp("ws") / "root")
    with torch_threads(1):
        model = build_model("small").eval()
        app = Talk2PCApp(root, model, AppConfig(port=0, model_note="test note"))
        app.start()
        try:
            app.wait_ready(timeout=60)
            yield app
        finally:
            app.stop()


def _connected(app, timeout: float = 15.0) -> BrowserLikeClient:
    client = BrowserLikeClient(app.port)
    client.pump_until(
        lambda: (
            "/scene/lidar" in client.nodes and "Run" in client.gui and "/gt/edges" in client.nodes
        ),
        timeout,
        "the scene and the panel",
    )
    return client


def test_prompt_run_enter_and_empty_prompt(running_app) -> None:
    app = running_app
    client = _connected(app)
    try:
        assert {"/scene/radar", "/scene/rings", "/scene/ego"} <= set(client.nodes)
        assert any("test note" in text for text in client.markdown.values())
        session = next(iter(app.sessions.values()))
        # Type a prompt and press Run (threshold 0 so that the untrained model returns boxes).
        client.set("Score threshold", 0.0)
        client.set("Prompt", "the car about 15 m ahead")
        client.click("Run")
        client.pump_until(
            lambda: "/pred/edges" in client.nodes and "/heatmap" in client.nodes,
            30,
            "predicted boxes and the heatmap",
        )
        assert client.nodes["/heatmap"] == "ImageMessage"
        assert client.nodes["/pred/edges"] == "LineSegmentsMessage"
        assert "/pred/labels/0" in client.nodes
        assert session.answer is not None and session.answer.prompt == "the car about 15 m ahead"
        assert len(session.answer.predictions.boxes) == session.pred_view.count > 0
        assert session.query.history.options[0] == "the car about 15 m ahead"

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


def test_model_error_is_a_notification(running_app, monkeypatch) -> None:
    app = running_app
    client = _connected(app)
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


def test_two_browsers_share_the_scene_not_the_answers(running_app) -> None:
    app = running_app
    before = set(app.sessions)
    a = _connected(app)
    session_a = app.sessions[(set(app.sessions) - before).pop()]
    b = _connected(app)
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
        a.pump_until(lambda: "/pred/edges" in a.nodes, 30, "A's boxes")
        assert session_a.answer is not None
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

        # A frame number out of range is a notification for the one who typed it.
        b.set("Frame #", 99)
        b.pump_until(lambda: any(t == "No such frame" for t, _ in b.notifications), 10, "notice")
        assert app.frame.index == (start + 1) % len(app.frames)
    finally:
        a.close()
        b.close()


def test_reload_frames_updates_the_panels(running_app) -> None:
    app = running_app
    client = _connected(app)
    try:
        session = next(s for s in app.sessions.values() if s.nav is not None)
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


def test_failed_load_is_a_notification(running_app) -> None:
    app = running_app
    client = _connected(app)
    try:
        target = (app.frame.index + 1) % len(app.frames)
        bad_id = app.frames.ids[target]
        app.frames._cache.pop(target, None)
        velodyne = app.frames.root.lidar_dir / "training" / "velodyne" / f"{bad_id}.bin"
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


def _assert_only_text(markdown: str) -> None:
    """The markdown, rendered as viser does (CommonMark, raw HTML on), holds no tag of the text."""
    from tests.test_reliability_html import OWN_TAGS, _render, _tags

    rendered = _render(markdown)
    assert _tags(rendered) <= OWN_TAGS, rendered


def test_a_hostile_prompt_is_shown_as_text(running_app) -> None:
    app = running_app
    client = _connected(app)
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
            _assert_only_text(text)
    finally:
        client.close()


def test_stored_text_and_forged_splits(running_app) -> None:
    """A saved pair's prompt and annotator are shown as text in the Annotate table; a split name
    forged through the websocket is refused by the server and saving keeps working."""
    from annotate import AnnotationStore, Draft, SourceFrame

    app = running_app
    root = app.frames.root
    store = app.annotations.store
    assert store is not None
    pair = Draft().set_prompt(HOSTILE_TEXT).add_box(GT_BOX, "Car")
    store.create(pair, SourceFrame.from_root(root, root.ids("test")[0]), annotator=HOSTILE_TEXT)
    before = set(app.sessions)
    client = _connected(app)
    try:
        session = app.sessions[(set(app.sessions) - before).pop()]
        panel = next(p for p in app.annotations.panels() if p.session is session)
        client.pump_until(lambda: "Save pair" in client.gui and panel.frame is not None, 15, "tab")
        tables = [text for text in client.markdown.values() if "saved pair(s)" in text]
        assert tables and "onerror" in tables[0]
        _assert_only_text(tables[0])

        lists = sorted((root.lidar_dir / "ImageSets").iterdir())
        with session.lock:
            panel.editor.reset(Draft().set_prompt("the car ahead").add_box(GT_BOX, "Car"))
        client.set("Split", "a" * 300)  # not an option: only a forged message can send it
        client.click("Save pair")
        client.pump_until(
            lambda: any(t == "Save failed" for t, _ in client.notifications), 10, "the refusal"
        )
        body = next(b for t, b in client.notifications if t == "Save failed")
        assert "invalid split name" in body
        assert sorted((root.lidar_dir / "ImageSets").iterdir()) == lists  # no junk list
        client.set("Split", "train")
        client.click("Save pair")
        client.pump_until(
            lambda: any(t.startswith("Saved pair") for t, _ in client.notifications), 10, "saved"
        )
        assert len(AnnotationStore(root.path).pairs()) == 2
    finally:
        client.close()
