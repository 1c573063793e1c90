"""Real-browser test: Debian's headless Chromium, driven by Playwright, uses the app like a person.

It opens the page, types a prompt into the prompt box, presses Enter and waits until the
predicted-box node exists in the browser's own scene tree (``window.__viserSceneTree``, a hook the
viser 1.1.1 client exposes) and on the server; it saves a screenshot to ``artifacts/``. It skips
only where no Chromium exists (``apt-get install chromium``; never ``playwright install``).
The browser is driven by :func:`app.browser.drive`, the same steps that make the documentation
pictures (``python -m app.screenshots``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from app.browser import drive
from scenes.frame import Sample
from tests.browser_helpers import ARTIFACTS, REPO, find_chromium

PROMPT = "the car about 15 m ahead"


@pytest.mark.browser
def test_browser_types_prompt_and_sees_boxes(
    tmp_path, chromium, write_tiny_root, torch_threads
) -> None:
    root = write_tiny_root(tmp_path / "root", frames=2)
    with torch_threads(1):
        _run_browser_test(root, chromium)


def _run_browser_test(root: Path, chromium: str) -> None:
    from app import AppConfig, Talk2PCApp
    from model import build_model

    # Threshold 0: the untrained model's scores hover around 0.1, and the test needs boxes. The
    # Bi-GRU text encoder skips MiniLM's loading time (the websocket test covers MiniLM).
    model = build_model("small", text_encoder="gru", head__score_threshold=0.0).eval()
    app = Talk2PCApp(root, model, AppConfig(port=0)).start()
    try:
        app.wait_ready(timeout=60)

        # What the answering session drew, read while the page is open (a closed browser's
        # session is released, its answer with it).
        seen: list[tuple[int, int]] = []

        def answered() -> bool:
            for s in list(app.sessions.values()):
                answer = s.answer
                if answer is not None and answer.prompt == PROMPT:
                    seen.append((s.pred_view.count, len(answer.predictions.boxes)))
            return bool(seen)

        shot = ARTIFACTS / "app-browser.png"
        drive(app.url, shot, PROMPT, chromium, wait_answer=answered)
        assert seen, "the server never drew an answer for the typed prompt"
        drawn, boxes = seen[0]
        assert drawn == boxes > 0
        assert shot.is_file() and shot.stat().st_size > 10_000
    finally:
        app.stop()


def _attribute_sample(root: Path) -> tuple[int, Sample] | None:
    """``(frame index, sample)`` of the first test-split sample whose prompt names an attribute
    and whose frame holds same-class actors that are *not* referents (so a class-only answer
    would be wrong). Chosen from the data alone, never from what the model answers."""
    from scenes.talk2radar.root import Talk2RadarRoot

    r = Talk2RadarRoot(root)
    for index, sid in enumerate(r.ids("test")):
        sample = r.load(sid)
        if not sample.meta or not (sample.meta.tags - {"class"}) or not len(sample.boxes):
            continue
        cls = set(sample.classes)
        others = [
            a
            for a in sample.meta.actors
            if a.cls in cls and a.actor_id not in sample.meta.referent_ids and 0 < a.box[0] < 50
        ]
        if others:
            return index, sample
    return None


@pytest.mark.browser
@pytest.mark.slow
def test_browser_attribute_prompt_shows_the_models_answer(tmp_path) -> None:
    """With the shipped checkpoint, a typed attribute prompt on a frame with distractors (picked
    from the data, not from the model's answer) shows in the browser exactly what the model
    returns for it called directly: the same boxes, all of them drawn, none when it returns none."""
    chromium = find_chromium()
    if chromium is None:
        pytest.skip("no Chromium found (/usr/bin/chromium): install Debian's `chromium` package")
    import numpy as np
    import torch

    from app import AppConfig, Talk2PCApp
    from model.checkpoint import load_checkpoint
    from scenes.synth.generate import SynthSettings, generate_root

    root = tmp_path / "root"
    generate_root(root, 16, SynthSettings(seed=404), split_fractions=(0.0, 0.0, 1.0))
    model = load_checkpoint(REPO / "checkpoints" / "tpcnet-small.pt")
    assert model.cfg.grounding == "referent"
    found = _attribute_sample(root)
    assert found is not None, "no attribute prompt with same-class distractors in the root"
    index, sample = found
    app = Talk2PCApp(root, model, AppConfig(port=0, split="test"))
    with torch.no_grad():  # what the model returns at the app's initial threshold
        expected = model.ground(
            model.encode_scene(sample.lidar, sample.radar),
            sample.prompt,
            score_threshold=app.score_threshold,
        )
    app.start()
    try:
        app.wait_ready(timeout=120)
        assert app.go_to(index) is not None
        seen = []  # (answer, boxes drawn), read while the page is open

        def answered() -> bool:
            for s in list(app.sessions.values()):
                answer = s.answer
                if answer is not None and answer.prompt == sample.prompt:
                    seen.append((answer, s.pred_view.count))
            return bool(seen)

        drive(
            app.url,
            ARTIFACTS / "app-referents.png",
            sample.prompt,
            chromium,
            wait_answer=answered,
            expect_boxes=len(expected.boxes) > 0,
        )
        assert seen, "the server never drew an answer for the typed prompt"
        answer, drawn = seen[0]
        assert answer.sample_id == sample.sample_id
        assert answer.score_threshold == app.score_threshold
        got = answer.predictions
        assert drawn == len(got.boxes) == len(expected.boxes)
        assert tuple(got.classes) == tuple(expected.classes)
        np.testing.assert_allclose(got.boxes, expected.boxes, atol=1e-5)
        np.testing.assert_allclose(got.scores, expected.scores, atol=1e-5)
    finally:
        app.stop()


@pytest.mark.browser
def test_browser_camera_panel_shows_projected_boxes(
    tmp_path, chromium, write_vod_root, torch_threads
) -> None:
    """On a View-of-Delft-layout root: the camera panel shows the image with the answer, the
    ground truth and the draft projected (screenshot ``artifacts/camera-browser.png``; the docs'
    ``docs/images/camera.png`` comes from ``python -m tools.camera_shot``); *Save pair* is in
    sight at 1400 x 860 and disabled for an empty draft; Esc leaves *Pair prompt*; Enter saves."""
    from app import AppConfig, Talk2PCApp
    from model import build_model
    from scenes.talk2radar.root import Talk2RadarRoot
    from tools.camera_shot import drive_camera

    root = write_vod_root(tmp_path / "vod", frames=1, splits={"val": [0]})
    with torch_threads(1):
        model = build_model("small", text_encoder="gru", head__score_threshold=0.0).eval()
        pairs = tmp_path / "vod-talk2radar"  # named: a release is never written beside
        config = AppConfig(port=0, split="val", warm_up=False, pairs_root=pairs)
        app = Talk2PCApp(root, model, config).start()
        try:
            shot = ARTIFACTS / "camera-browser.png"
            run = drive_camera(app, chromium, shot, "the car ahead", "the pedestrian on the right")
            assert run.save_bottom <= 860 and run.save_disabled
            assert run.focus_after_escape == "BODY"
            assert run.shown_width == 968  # VoD's 1936 px image, halved
            assert shot.is_file() and shot.stat().st_size > 20_000
            pairs = Talk2RadarRoot(tmp_path / "vod-talk2radar").load(run.sample_id)
            assert pairs.prompt == "the pedestrian on the right"
            assert pairs.classes == ("Pedestrian",)
        finally:
            app.stop()
