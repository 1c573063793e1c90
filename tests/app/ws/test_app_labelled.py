"""The Query tab's "Candidates: Labelled boxes" on a View-of-Delft root served directly, with the
shipped (referent-path) checkpoint: the answer is chosen among the frame's labelled boxes."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def labelled_app(tmp_path_factory, write_vod_root, torch_threads, serve_app):
    from model.checkpoint import load_checkpoint

    root = write_vod_root(tmp_path_factory.mktemp("labelled") / "vod", frames=2)
    with torch_threads(1):
        model = load_checkpoint("checkpoints/tpcnet-small.pt")
        with serve_app(root, model, split="val", warm_up=False) as app:
            yield app


def test_candidates_labelled_boxes_answer_among_the_labels(labelled_app, ws_client):
    app = labelled_app
    before = set(app.sessions)
    client = ws_client(app.port)
    try:
        client.pump_until(
            lambda: "/scene/lidar" in client.nodes and "Save pair" in client.gui, 30, "the panel"
        )
        session = app.sessions[(set(app.sessions) - before).pop()]
        assert client.dropdown("Candidates") == ("Detector proposals", "Labelled boxes")
        client.set("Candidates", "Labelled boxes")
        client.set("Score threshold", 0.0)
        client.set("Prompt", "the pedestrians")
        client.click("Run")
        client.pump_until(
            lambda: (
                (session.answer is not None and session.answer.prompt == "the pedestrians")
                or client.notifications
            ),
            60,
            "the answer",
        )
        assert not client.notifications, client.notifications
        sample = session.frame.sample
        boxes = session.answer.predictions.boxes
        assert len(boxes) == len(sample.boxes)  # every labelled box scored, none other
        for box in boxes:
            assert np.min(np.abs(sample.boxes - box).sum(axis=1)) < 1e-9
        top = session.answer.predictions.classes[int(np.argmax(session.answer.predictions.scores))]
        assert top == "Pedestrian"
    finally:
        client.close()


def test_no_candidates_control_without_labels(
    tmp_path, write_tiny_root, serve_app, ws_client, untrained_model, grounding
):
    root = write_tiny_root(tmp_path / "t2r", frames=1)
    model = untrained_model(grounding, text_encoder="gru")
    with serve_app(root, model, split="test", warm_up=False) as app:
        client = ws_client(app.port)
        try:
            client.pump_until(lambda: "Save pair" in client.gui, 30, "the panel")
            assert "Candidates" not in client.gui
        finally:
            client.close()
