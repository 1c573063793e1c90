"""Reviews as idempotent, versioned requests (issue 39.4), through the app's websocket.

- Three Approve clicks (or Y presses) sent within milliseconds write one review line, say
  "approved" once, and the reviewer moves on by one pair: the next pair is reviewed in turn.
- A verdict on a version another reviewer decided after it was shown here is refused with who
  decided what, and nothing is written.
- The store's API: a repeated request key writes nothing and returns the first line.
"""

from __future__ import annotations

import pytest

from annotate import AnnotationStore, ConflictError, SourceFrame, default_box
from annotate.draft import Draft
from annotate.review import latest_review, record_review


def _store_with_pairs(root, count: int) -> list[str]:
    store = AnnotationStore(root)
    ids = []
    for i in range(count):
        x = 10.0 + 3.0 * i
        draft = Draft().add_box(default_box("Car", x, 2.0), "Car").set_prompt(f"the car at {x}")
        ids.append(store.save(draft, SourceFrame.from_root(root, 0), annotator="ada").sample_id)
    return ids


def test_a_repeated_review_request_writes_one_line(tmp_path, write_tiny_root) -> None:
    root = write_tiny_root(tmp_path / "root", frames=1)
    (a,) = _store_with_pairs(root, 1)
    store = AnnotationStore(root)
    first = record_review(store, a, "approved", "rita", version=1, seen=None, request="k1")
    again = record_review(store, a, "approved", "rita", version=1, seen=None, request="k1")
    assert not first.repeated and again.repeated and again.record.op == first.record.op
    assert len(store.manifest.reviews(a)) == 1
    with pytest.raises(ValueError, match="before for something else"):
        record_review(store, a, "rejected", "rita", version=1, seen=None, request="k1")
    # Another reviewer shown the pair before that verdict: refused, naming who decided what.
    with pytest.raises(ConflictError, match=r"approved by rita at .*nothing was recorded"):
        record_review(store, a, "rejected", "bob", version=1, seen=None, request="k2")
    seen = latest_review(store, a, 1).op
    assert record_review(store, a, "rejected", "bob", version=1, seen=seen).record.verdict == (
        "rejected"
    )
    assert len(store.manifest.reviews(a)) == 2


@pytest.fixture(scope="module")
def review_app(tmp_path_factory, write_tiny_root, torch_threads, serve_app, untrained_model):
    root = write_tiny_root(tmp_path_factory.mktemp("review") / "root", frames=1)
    ids = _store_with_pairs(root, 4)
    with torch_threads(1):
        model = untrained_model("referent", text_encoder="gru", head__score_threshold=0.0)
        with serve_app(root, model, warm_up=False) as app:
            yield app, ids


def _connect(app, ws_client):
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(lambda: "Save pair" in client.gui, 30, "the Annotate tab")
    client.pump_until(lambda: set(app.sessions) - before, 30, "the session")
    session = app.sessions[(set(app.sessions) - before).pop()]
    client.pump_until(lambda: any(p.session is session for p in app.annotations.panels()), 30, "")
    panel = next(p for p in app.annotations.panels() if p.session is session)
    client.pump_until(lambda: panel.frame is not None, 10, "the draft's frame")
    return client, panel


def _command(client, label: str) -> str:
    """The uuid of the latest command registered with ``label`` (what a key press triggers)."""
    return [
        m["uuid"]
        for m in client.messages
        if m["type"] == "RegisterCommandMessage" and m["props"]["label"] == label
    ][-1]


def _press(client, label: str) -> None:
    client._send({"type": "CommandTriggerMessage", "uuid": _command(client, label)})


def _review_status(client) -> str:
    """What the browser shows in the Review folder's status line."""
    uuid = next(
        m["uuid"]
        for m in client.messages
        if m["type"] == "GuiMarkdownMessage" and "Next opens the split" in m["props"]["_markdown"]
    )
    return client.markdown[uuid]


def _under_review(client, panel, sid: str) -> None:
    client.pump_until(
        lambda: panel.draft.sample_id == sid and f"{sid}" in _review_status(client),
        20,
        f"pair {sid} under review",
    )


def _approved(client) -> list[str]:
    return [t for t, _ in client.notifications if t.endswith(" approved")]


@pytest.mark.parametrize("how", ["clicks", "keys"])
def test_three_quick_approvals_write_one_line_and_move_on_by_one(review_app, ws_client, how):
    app, ids = review_app
    client, panel = _connect(app, ws_client)
    store = app.annotations.store
    try:
        client.click("Only not reviewed")  # the pairs without a verdict, in id order
        client.drain(0.3)
        client.click("Pairs", "Next")
        first = next(s for s in ids if not store.manifest.reviews(s))
        _under_review(client, panel, first)
        for _ in range(3):  # within milliseconds, before any answer arrives
            if how == "clicks":
                client.click("Approve")
            else:
                _press(client, "Approve the pair under review")
        following = ids[ids.index(first) + 1]
        _under_review(client, panel, following)
        client.drain(1.0)
        assert len(store.manifest.reviews(first)) == 1
        assert _approved(client) == [f"Pair {first} approved"]  # said once
        assert not store.manifest.reviews(following)  # the next pair is not skipped ...
        assert panel.draft.sample_id == following  # ... it is the one under review
        client.click("Approve")  # and it is reviewed in turn
        client.pump_until(lambda: len(store.manifest.reviews(following)) == 1, 20, "its verdict")
    finally:
        client.close()


def test_a_verdict_on_a_version_someone_decided_meanwhile_is_refused(review_app, ws_client):
    app, ids = review_app
    a, panel_a = _connect(app, ws_client)
    b, panel_b = _connect(app, ws_client)
    store = app.annotations.store
    try:
        for client, panel, name in ((a, panel_a, "ada"), (b, panel_b, "bob")):
            client.set("Annotator", name)
            client.click("Pairs", "Next")
            _under_review(client, panel, ids[0])
        lines = len(store.manifest.reviews(ids[0]))
        a.click("Approve")
        a.pump_until(lambda: len(store.manifest.reviews(ids[0])) == lines + 1, 20, "a's verdict")
        b.click("Reject")  # b was shown the pair before a's verdict
        title = "Not recorded: the pair changed meanwhile"
        b.pump_until(lambda: any(t == title for t, _ in b.notifications), 20, "the refusal")
        body = next(m for t, m in b.notifications if t == title)
        assert f"pair {ids[0]} version 1 was approved by ada" in body
        b.drain(0.5)
        assert len(store.manifest.reviews(ids[0])) == lines + 1  # nothing written for b
        assert panel_b.draft.sample_id == ids[0]  # b stays on it, shown a's verdict
        b.pump_until(lambda: "approved by ada" in _review_status(b), 10, "a's verdict shown")
    finally:
        a.close()
        b.close()
