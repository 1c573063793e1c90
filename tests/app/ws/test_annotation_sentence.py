"""Sentence-first pairs on labelled frames (issue 19.2), through the app's websocket: typing the
sentence picks its referents among the frame's labelled boxes (the shipped referent-path
checkpoint, on a View-of-Delft root served directly); Enter never saves an unseen pick; a click
toggles a labelled box; choosing by hand stops the picks; a reopened pair keeps its boxes."""

from __future__ import annotations

import numpy as np
import pytest

from tests.vod_fixtures import GROUND_Z


@pytest.fixture(scope="module")
def labelled_app(tmp_path_factory, write_vod_root, torch_threads, serve_app):
    from model.checkpoint import load_checkpoint

    root = write_vod_root(tmp_path_factory.mktemp("sentence") / "vod", frames=2)
    with torch_threads(1):
        model = load_checkpoint("checkpoints/tpcnet-small.pt")
        pairs = root.with_name("vod-talk2radar")  # named: a release is never written beside
        with serve_app(root, model, split="val", warm_up=False, pairs_root=pairs) as app:
            yield app


def _connect(app, ws_client):
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(lambda: "Save pair" in client.gui, 30, "the panel")
    client.pump_until(lambda: set(app.sessions) - before, 30, "the session")
    session = app.sessions[(set(app.sessions) - before).pop()]
    client.pump_until(lambda: any(p.session is session for p in app.annotations.panels()), 30, "")
    panel = next(p for p in app.annotations.panels() if p.session is session)
    client.pump_until(lambda: panel.frame is not None, 10, "the frame")
    return client, panel


def test_typing_picks_enter_waits_for_the_pick_and_clicks_toggle(labelled_app, ws_client):
    app = labelled_app
    client, panel = _connect(app, ws_client)
    store = app.annotations.store
    try:
        labelled = panel.labelled()
        assert labelled is not None and labelled.classes == (
            "Car",
            "Pedestrian",
            "Cyclist",
        )  # not 60 m
        client.pump_until(lambda: len(panel.ready_boxes) == 3, 10, "the labelled boxes offered")

        # Enter right away: the pick is made and shown, nothing is saved yet.
        saved = len(store.pairs())
        client.set("Pair prompt", "the pedestrian\n")
        client.pump_until(lambda: panel.referents_for() == "the pedestrian", 90, "the pick")
        client.drain(0.5)
        assert len(store.pairs()) == saved
        assert any(title == "Referents picked" for title, _ in client.notifications)
        picked = [labelled.index_of(b.box) for b in panel.draft.boxes]
        assert None not in picked  # only labelled boxes, exactly
        # The pick: the labelled boxes at or above the operating threshold (asked directly).
        session, sample = panel.session, panel.frame.sample
        engine = session.engine
        answer = engine.answer(
            sample,
            engine.modalities[0],
            "the pedestrian",
            0.0,
            session.options.labelled_boxes(sample),
        )
        expected = {
            labelled.index_of(b)
            for b, score in zip(answer.predictions.boxes, answer.predictions.scores, strict=True)
            if score >= session.options.score_threshold
        } - {None}
        assert set(picked) == expected

        # A click on a labelled box toggles it: in, then out; typing then picks no more.
        car = labelled.boxes[0]
        inside = labelled.index_of(car) in picked
        client.click_ground(float(car[0]), float(car[1]), GROUND_Z)
        client.pump_until(
            lambda: any(labelled.index_of(b.box) == 0 for b in panel.draft.boxes) != inside,
            10,
            "the toggle",
        )
        client.click_ground(float(car[0]), float(car[1]), GROUND_Z)
        client.pump_until(
            lambda: any(labelled.index_of(b.box) == 0 for b in panel.draft.boxes) == inside,
            10,
            "the toggle back",
        )
        if not inside:  # the car in the pair, so that it can be saved
            client.click_ground(float(car[0]), float(car[1]), GROUND_Z)
            client.pump_until(lambda: len(panel.draft.boxes) == len(picked) + 1, 10, "the car")
        boxes = panel.draft.box_array.copy()
        client.set("Pair prompt", "the pedestrian on the right")
        client.drain(1.5)
        np.testing.assert_array_equal(panel.draft.box_array, boxes)  # chosen by hand: kept

        # Enter saves what is shown (the choice is the annotator's now).
        client.set("Pair prompt", "the pedestrian on the right\n")
        client.pump_until(lambda: len(store.pairs()) == saved + 1, 30, "the save")
        pair = max(store.pairs(), key=lambda x: x.sample_id)
        reopened = store.open(pair.sample_id)
        np.testing.assert_allclose(
            np.sort(reopened.box_array, axis=0), np.sort(boxes, axis=0), atol=1e-4
        )
    finally:
        client.close()


def test_use_predictions_picks_among_the_labelled_boxes(labelled_app, ws_client):
    client, panel = _connect(labelled_app, ws_client)
    try:
        client.pump_until(lambda: not panel.w.use_predictions.disabled, 10, "Use predictions")
        client.click("Use predictions")
        client.pump_until(
            lambda: any(t == "Write the sentence first" for t, _ in client.notifications), 10, ""
        )
        client.set("Pair prompt", "the car")
        client.pump_until(lambda: panel.referents_for() == "the car", 90, "the pick as typed")
        client.click("Use predictions")
        client.pump_until(
            lambda: sum(t == "Referents picked" for t, _ in client.notifications) >= 1, 60, ""
        )
        assert all(panel.labelled().index_of(b.box) is not None for b in panel.draft.boxes)
    finally:
        client.close()


@pytest.mark.parametrize("offset", [(0.0, -1.0), (1.2, 0.0), (-0.9, 0.9)])
def test_a_near_miss_places_nothing_and_shift_click_places_a_box(labelled_app, ws_client, offset):
    """Issue 39.6: a click close to but not on a labelled box changes nothing and says so (the
    status still tells the truth); placing a box there is Shift+click, and then the boxes are
    the annotator's."""
    client, panel = _connect(labelled_app, ws_client)
    try:
        labelled = panel.labelled()
        client.set("Pair prompt", "the pedestrian")
        client.pump_until(  # the pick, then its status line (written after it)
            lambda: (
                panel.referents_for() == "the pedestrian"
                and "picked by the model" in panel.w.status.content
            ),
            90,
            "the pick and its status",
        )
        boxes = panel.draft.box_array.copy()
        pedestrian = labelled.boxes[labelled.classes.index("Pedestrian")]
        x, y = float(pedestrian[0] + offset[0]), float(pedestrian[1] + offset[1])
        client.click_ground(x, y, GROUND_Z)  # beside the pedestrian, on no box
        client.pump_until(
            lambda: any(t == "Nothing to pick there" for t, _ in client.notifications), 10, ""
        )
        body = next(b for t, b in client.notifications if t == "Nothing to pick there")
        assert "Shift+click" in body
        client.drain(0.5)
        np.testing.assert_array_equal(panel.draft.box_array, boxes)  # no silent new box
        assert "picked by the model" in panel.w.status.content

        client.click_ground(x, y, GROUND_Z, modifier="shift")  # the explicit act
        client.pump_until(lambda: len(panel.draft.boxes) == len(boxes) + 1, 10, "the new box")
        placed = panel.draft.boxes[-1]
        assert placed.cls == panel.w.cls.value
        np.testing.assert_allclose(placed.box[:2], [x, y], atol=0.05)  # on the ground estimate
        client.pump_until(lambda: "chosen by hand" in panel.w.status.content, 10, "the status")
    finally:
        client.close()
