"""Nothing is written until the person saves (issue 39.7), through the app's websocket.

- A browser that connects, looks, opens the Review folder's queue and makes an invalid draft
  writes nothing into the served root: no ``annotations/`` (lock, pending), no split list.
- With ``--pairs DIR`` the folder, its lock and both trees' ImageSets appear with the first save.
- A View-of-Delft release served directly (no prompts) is never written beside: without
  ``--pairs`` no ``<release>-talk2radar`` folder appears, neither when a browser connects nor when
  Enter is pressed on a valid draft, and the tab says how to name the pairs folder.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from scenes.talk2radar.layout import manifest_file
from tests.vod_fixtures import GROUND_Z


def _tree(root: Path) -> dict[str, tuple[int, int]]:
    """Every file and folder under ``root`` with its size and modification time."""
    out = {}
    for folder, dirs, names in os.walk(root):
        for name in (*dirs, *names):
            path = Path(folder) / name
            st = path.stat()
            out[str(path.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


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


@pytest.fixture(scope="module")
def model(untrained_model, torch_threads):
    with torch_threads(1):
        return untrained_model("referent", text_encoder="gru", head__score_threshold=0.0)


def test_looking_writes_nothing_and_the_first_save_creates_the_pairs_folder(
    tmp_path, write_tiny_root, serve_app, ws_client, model, gt_box
) -> None:
    served = write_tiny_root(tmp_path / "root", frames=1)
    pairs = tmp_path / "pairs"
    before = _tree(served)
    with serve_app(served, model, warm_up=False, pairs_root=pairs) as app:
        client, panel = _connect(app, ws_client)
        try:
            client.click("Pairs", "Next")  # the Review queue reads the store
            client.pump_until(
                lambda: (
                    "No pair to review" in panel.w.status.content
                    or any("No pair to review" in m for m in client.markdown.values())
                ),
                10,
                "the empty review queue",
            )
            client.set("Pair prompt", "the car\n")  # refused: no box yet
            client.pump_until(
                lambda: any(t == "Not saved yet" for t, _ in client.notifications), 10, ""
            )
            client.drain(0.3)
            assert not pairs.exists()  # nothing written before a save
            assert _tree(served) == before
            assert app.annotations.store is not None and app.annotations.store.pairs() == ()
            assert not pairs.exists()

            client.click_ground(float(gt_box[0]), float(gt_box[1]), panel.frame.ground_z)
            client.pump_until(lambda: len(panel.draft.boxes) == 1, 10, "the box")
            client.set("Pair prompt", "the car ahead\n")
            client.pump_until(lambda: "Saved pair" in panel.w.status.content, 30, "the save")
        finally:
            client.close()
    assert (pairs / "annotations" / ".lock").is_file() and manifest_file(pairs).is_file()
    assert (pairs / "lidar" / "ImageSets" / "train.txt").read_text() == "00000\n"
    radar = next(p for p in pairs.iterdir() if p.name.startswith("radar"))
    assert (radar / "ImageSets" / "train.txt").read_text() == "00000\n"
    assert _tree(served) == before  # the served root was only read


def test_a_release_served_directly_is_never_written_beside(
    tmp_path, write_vod_root, serve_app, ws_client, model
) -> None:
    release = write_vod_root(tmp_path / "vod", frames=1)
    before = _tree(tmp_path)
    with serve_app(release, model, split="val", warm_up=False) as app:
        client, panel = _connect(app, ws_client)
        try:
            client.drain(0.3)
            assert _tree(tmp_path) == before  # no <release>-talk2radar on connect
            assert app.annotations.store is None
            status = panel.w.status.content
            assert "Saving is unavailable" in status and "\\-\\-pairs" in status
            car = panel.frame.sample.boxes[0]  # a valid draft, then Enter
            client.click_ground(float(car[0]), float(car[1]), GROUND_Z)
            client.pump_until(lambda: len(panel.draft.boxes) == 1, 10, "the car")
            client.set("Pair prompt", "the car ahead\n")
            client.pump_until(
                lambda: any(t == "Not saved yet" for t, _ in client.notifications), 10, ""
            )
            body = next(b for t, b in client.notifications if t == "Not saved yet")
            assert "--pairs" in body and "vod-talk2radar" in body
            assert panel.w.save.disabled
            client.drain(0.3)
        finally:
            client.close()
    assert _tree(tmp_path) == before
