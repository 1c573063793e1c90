"""Several browsers and forged messages, through the app's websocket (issue 21).

- a prompt being typed in one browser is never written over by another browser's navigation;
- two save requests for one draft version save one pair;
- control characters and over-long text are refused on every path (Query tab, Annotate save);
- forged numbers (NaN, infinities, negative, 1e308, wrong types) are clamped or refused with one
  rate-limited warning line, never a traceback, and the browser's view keeps working;
- a few hundred connections leave the server's memory flat (the soak).

The client is :class:`tests.conftest.BrowserLikeClient` (viser 1.1.1's protocol); it sends each
message at once, without the web client's 50 ms throttle, which is how a script or a forged
client behaves. The model is the small TPCNet with the Bi-GRU text encoder, untrained, with a
score threshold of 0.
"""

from __future__ import annotations

import logging
import time
import weakref

import pytest

from annotate import AnnotationStore
from scenes.talk2radar.layout import PROMPT, sample_file
from scenes.talk2radar.root import Talk2RadarRoot

FRAMES = 3


def _frame_prompt(i: int) -> str:
    return f"the car about {15 + 2 * i} m ahead in frame {i}"


@pytest.fixture(scope="module")
def app(tmp_path_factory, write_tiny_root, torch_threads, serve_app, untrained_model, grounding):
    """The app on a tiny root whose frames have prompts of their own, on each grounding path."""
    path = write_tiny_root(tmp_path_factory.mktemp("reliability") / "root", frames=FRAMES)
    root = Talk2RadarRoot(path)
    for i, sid in enumerate(root.ids("test")):
        for tree in (root.lidar_dir, root.radar_dir):
            sample_file(tree, PROMPT, sid).write_text(_frame_prompt(i) + "\n")
    with torch_threads(1):
        model = untrained_model(grounding, text_encoder="gru", head__score_threshold=0.0)
        with serve_app(path, model) as running:
            yield running


def _connect(app, ws_client):
    """A browser, its session and its Annotate panel."""
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(
        lambda: "/scene/lidar" in client.nodes and "Save pair" in client.gui, 15, "the panel"
    )
    session = app.sessions[(set(app.sessions) - before).pop()]
    panel = next(p for p in app.annotations.panels() if p.session is session)
    client.pump_until(lambda: panel.frame is not None, 5, "the draft's frame")
    client.pump_until(  # the connection's own writes have arrived
        lambda: _shown(client, "Prompt") == session.query.prompt.value, 5, "the prompt box"
    )
    return client, session, panel


def _shown(client, label: str) -> object:
    """The value the browser shows in the widget ``label``: its creation's, then the last the
    server wrote."""
    uuid, value = client.gui[label], None
    for m in client.messages:
        if m.get("uuid") != uuid:
            continue
        if m["type"] == "GuiUpdateMessage" and "value" in m["updates"]:
            value = m["updates"]["value"]
        elif m["type"] != "GuiUpdateMessage" and "value" in m:
            value = m["value"]
    return value


def _writes(client, label: str, since: int) -> list[object]:
    """The values the server wrote into the widget ``label`` of ``client`` since message
    ``since``."""
    uuid = client.gui[label]
    return [
        m["updates"]["value"]
        for m in client.messages[since:]
        if m["type"] == "GuiUpdateMessage" and m["uuid"] == uuid and "value" in m["updates"]
    ]


def _next_frame(app, session, client, start: int) -> None:
    client.pump_until(lambda: session.frame.index == (start + 1) % FRAMES, 10, "the next frame")


# ---------------------------------------------------------------------------- the prompt box


def test_another_browsers_navigation_leaves_the_typed_prompt_alone(app, ws_client) -> None:
    a, _, _ = _connect(app, ws_client)
    b, session_b, _ = _connect(app, ws_client)
    try:
        for trial in range(3):
            typed = f"typed prompt number {trial}"
            start, since = app.frame.index, len(b.messages)
            b.set("Prompt", typed)  # no pause: the keystroke and the click race
            a.click("Frame", "Next")
            _next_frame(app, session_b, b, start)
            b.drain(0.3)
            assert _writes(b, "Prompt", since) == []  # the field was left alone
            assert session_b.query.prompt.value == typed
        b.set("Prompt", typed + " ahead\n")  # the person finishes and runs it
        b.pump_until(
            lambda: session_b.answer is not None and session_b.answer.prompt == typed + " ahead",
            30,
            "the typed prompt's answer",
        )
        since = len(b.messages)
        b.click("Use the frame's prompt")  # the frame's own prompt, when the person asks
        b.pump_until(lambda: _frame_prompt(app.frame.index) in _writes(b, "Prompt", since), 5, "")
    finally:
        a.close()
        b.close()


def test_own_navigation_fills_only_an_untouched_box(app, ws_client) -> None:
    b, session_b, _ = _connect(app, ws_client)
    try:
        start, since = app.frame.index, len(b.messages)
        b.click("Frame", "Next")  # untouched box: it takes the new frame's prompt
        _next_frame(app, session_b, b, start)
        b.pump_until(lambda: _frame_prompt(app.frame.index) in _writes(b, "Prompt", since), 5, "")
        b.set("Prompt", "half typed")
        b.pump_until(lambda: session_b.query.prompt.value == "half typed", 5, "the typing")
        start, since = app.frame.index, len(b.messages)
        b.click("Frame", "Next")  # edited box: kept
        _next_frame(app, session_b, b, start)
        b.drain(0.3)
        assert _writes(b, "Prompt", since) == [] and session_b.query.prompt.value == "half typed"
    finally:
        b.close()


# ---------------------------------------------------------------------------- saves


def _ready_draft(client, panel, gt_box) -> None:
    """A valid draft: the tiny root's car and a prompt."""
    client.click_ground(float(gt_box[0]), float(gt_box[1]), panel.frame.ground_z)
    client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "the box")
    client.set("Pair prompt", "the car ahead")
    client.pump_until(lambda: panel.draft.prompt == "the car ahead" and panel.report.ok, 5, "")


def test_a_scripted_double_save_saves_one_pair(app, ws_client, gt_box) -> None:
    client, session, panel = _connect(app, ws_client)
    try:
        app.go_to(0)
        client.pump_until(lambda: session.frame.index == 0 and panel.frame.name, 5, "frame 0")
        store = app.annotations.store
        before = len(store.pairs())
        _ready_draft(client, panel, gt_box)
        client.click("Save pair")
        client.click("Save pair")  # the same draft version, within a millisecond

        def saved() -> list[str]:
            return [t for t, _ in client.notifications if t.startswith("Saved pair")]

        client.pump_until(lambda: len(saved()) == 2, 20, "both answers")
        assert len(set(saved())) == 1  # the same pair both times
        assert len(AnnotationStore(store.path).pairs()) == before + 1
        client.click("Save pair")  # nothing edited since: answered, not saved again
        client.pump_until(lambda: len(saved()) == 3, 10, "the third answer")
        assert len(AnnotationStore(store.path).pairs()) == before + 1
        assert "Already saved" in client.notifications[-1][1]
    finally:
        client.close()


# ---------------------------------------------------------------------------- text policy


def test_control_characters_and_long_text_are_refused_on_every_path(app, ws_client, gt_box) -> None:
    client, session, panel = _connect(app, ws_client)
    store = app.annotations.store
    before = len(store.pairs())
    try:
        client.set("Prompt", "the car\x00ahead\n")  # the Query tab
        client.pump_until(
            lambda: any(t == "Prompt not run" for t, _ in client.notifications), 5, ""
        )
        assert "U+0000 (NUL)" in client.notifications[-1][1] and session.answer is None
        client.set("Prompt", "x" * 600 + "\n")
        client.pump_until(lambda: "at most 500" in client.notifications[-1][1], 5, "the cap")

        _ready_draft(client, panel, gt_box)  # the Annotate tab: the prompt
        client.set("Pair prompt", "the car\u2028ahead")
        client.pump_until(lambda: not panel.report.ok, 5, "the check")
        assert any("U+2028 (LINE SEPARATOR)" in m for m in panel.report.messages())
        client.click("Save pair")  # forged: the button is disabled
        client.pump_until(
            lambda: any(t == "Cannot save the pair" for t, _ in client.notifications), 5, ""
        )
        client.set("Pair prompt", "the car ahead")  # and the annotator
        client.set("Annotator", "ada\x00bob")
        client.pump_until(lambda: panel.w.annotator.value == "ada\x00bob", 5, "the name")
        count = len(client.notifications)
        client.click("Save pair")
        client.pump_until(lambda: len(client.notifications) > count, 5, "the refusal")
        title, body = client.notifications[-1]
        assert title == "Cannot save the pair" and "U+0000 (NUL)" in body
        client.set("Annotator", "a" * 1000)
        client.pump_until(lambda: len(panel.w.annotator.value) == 1000, 5, "the long name")
        client.click("Save pair")
        client.pump_until(lambda: "at most 64" in client.notifications[-1][1], 5, "the cap")
        assert len(AnnotationStore(store.path).pairs()) == before  # nothing was saved
    finally:
        client.close()


# ---------------------------------------------------------------------------- forged numbers


def _no_traceback(caplog, capfd) -> list[str]:
    """The warning lines of :mod:`app.guards`; fails on any traceback in the log or stderr."""
    err = capfd.readouterr().err
    assert "Traceback" not in err and "Task failed" not in err, err[-2000:]
    for record in caplog.records:
        assert record.exc_info is None, record.getMessage()
        assert "Traceback" not in record.getMessage()
    return [r.getMessage() for r in caplog.records if r.name == "app.guards"]


def test_forged_numbers_are_clamped_or_refused(app, ws_client, gt_box, caplog, capfd) -> None:
    caplog.set_level(logging.INFO)
    client, session, panel = _connect(app, ws_client)
    try:
        client.click_ground(float(gt_box[0]), float(gt_box[1]), panel.frame.ground_z)
        client.pump_until(lambda: panel.selected is not None, 5, "a selected box")
        forged = [
            ("Score threshold", float("nan")),
            ("Score threshold", -1.0),
            ("Score threshold", 1e308),
            ("Radar v scale", 0.0),
            ("Radar v scale", -5.0),
            ("Radar v scale", float("inf")),
            ("Length (m)", 1e308),
            ("Width (m)", -3.0),
            ("Yaw (deg)", float("-inf")),
            ("Heatmap opacity", 7.0),
            ("Frame #", float("nan")),
            ("LiDAR size", True),
        ]
        for label, value in forged:
            client.set(label, value)
        client.drain(1.0)
        q, v = session.query, session.view
        assert 0.0 <= q.threshold.value <= 0.95 and 1.0 <= v.velocity_range.value <= 20.0
        assert 0.0 <= q.opacity.value <= 1.0 and 0.01 <= v.lidar_size.value <= 0.3
        box = panel.draft.boxes[0].box
        assert 0.1 <= box[3] <= 20.0 and 0.1 <= box[4] <= 20.0
        start = app.frame.index
        lidar = sum(m.get("name") == "/scene/lidar" for m in client.messages)
        client.click("Frame", "Next")  # the view still draws frames ...
        client.pump_until(
            lambda: sum(m.get("name") == "/scene/lidar" for m in client.messages) > lidar, 10, ""
        )
        assert session.frame.index == (start + 1) % FRAMES
        client.set("Prompt", "the car ahead\n")  # ... and answers prompts
        client.pump_until(lambda: session.answer is not None, 30, "an answer")
        lines = _no_traceback(caplog, capfd)
        assert 1 <= len(lines) <= 2, lines  # one line, rate-limited
        assert all(line.startswith(f"client {session.client_id}: ") for line in lines)
    finally:
        client.close()


def test_a_flood_of_wrong_types_writes_one_line(app, ws_client, caplog, capfd) -> None:
    caplog.set_level(logging.INFO)
    client, session, _ = _connect(app, ws_client)
    try:
        values = ("abc", {"a": 1}, [1, 2], None, "nan", 1e400, {"value": 1})
        labels = ("Score threshold", "Show LiDAR", "Prompt", "Frame #", "Sensors", "Run")
        for i in range(2000):
            label = labels[i % len(labels)]
            client._send(
                {
                    "type": "GuiUpdateMessage",
                    "uuid": client.gui[label],
                    "updates": {"value": values[i % len(values)]} if i % 50 else {"max": 1},
                }
            )
        client.set("Prompt", "the car ahead\n")
        client.pump_until(lambda: session.answer is not None, 60, "an answer after the flood")
        lines = _no_traceback(caplog, capfd)
        assert 1 <= len(lines) <= 2, lines
        assert session.query.prompt.value == "the car ahead"
    finally:
        client.close()


# ---------------------------------------------------------------------------- the soak


def _rss_mb() -> float:
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS")


SOAK_CYCLES = 200
SOAK_CHECK_EVERY = 50
SOAK_BOUND_MB = 40.0
"""RSS may grow at most this much from the first check to the last. Here (tiny frames, no camera
image, this process's own allocations triggering full collections now and then) the code before
the fix kept 8 to 30 departed sessions in memory at the checks and grew by about 18 MB; the
long measurement with camera images: ``python -m bench.perf.soak`` (docs/PERFORMANCE.md)."""

REAP_SECONDS = 10.0
"""How long a check waits for the departed sessions to be collected (the app's reaper runs 0.5 s
after a disconnect, at most every 2 s)."""


def _reaped(sessions: list[weakref.ref]) -> int:
    """Waits (without collecting: the app must) until at most one departed session is in
    memory; returns how many are."""
    deadline = time.monotonic() + REAP_SECONDS
    while sum(r() is not None for r in sessions) > 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    return sum(r() is not None for r in sessions)


@pytest.mark.slow
def test_connect_disconnect_soak_keeps_memory_flat(app, ws_client) -> None:
    """A few hundred connections, one after the other: every check finds the departed sessions
    collected and the server's memory (this process's RSS) flat."""
    sessions: list[weakref.ref] = []
    rss: dict[int, float] = {}
    alive: dict[int, int] = {}
    start = time.monotonic()
    for cycle in range(1, SOAK_CYCLES + 1):
        before = set(app.sessions)
        client = ws_client(app.port)
        client.pump_until(lambda c=client: "/scene/lidar" in c.nodes, 15, "the scene")
        sessions.extend(weakref.ref(app.sessions[i]) for i in set(app.sessions) - before)
        client.close()
        deadline = time.monotonic() + 10
        while any(r() is not None and not r().closed for r in sessions[-1:]):
            assert time.monotonic() < deadline, "the session did not close"
            time.sleep(0.005)
        if cycle % SOAK_CHECK_EVERY == 0:
            alive[cycle] = _reaped(sessions)
            rss[cycle] = _rss_mb()
    grown = rss[SOAK_CYCLES] - rss[SOAK_CHECK_EVERY]
    print(f"soak: {SOAK_CYCLES} cycles in {time.monotonic() - start:.1f} s; {rss=}; {alive=}")
    assert len(sessions) == SOAK_CYCLES
    assert max(alive.values()) <= 1, f"departed sessions still in memory: {alive}"
    assert grown <= SOAK_BOUND_MB, f"RSS grew {grown:.0f} MB: {rss}"
