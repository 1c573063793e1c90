"""Ground truth one can compare with (issue 51.1), in headless Chromium as a person sees it.

- On a synthetic frame (its sidecar lists every road user), the *Ground truth* layer draws every
  labelled object of the frame, numbered from the nearest, and the referents of the frame's own
  prompt apart; a prompt of one's own gets a table whose every row names the labelled object its
  box overlaps most (class and 3D IoU), computed here from the sidecar's actors directly.
- On a frame without any label (no sidecar, an empty ``label_2``), the answer table has no overlap
  column at all (rather than a column of zeros or dashes).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from scenes.geometry.boxes import iou3d
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.talk2radar.root import Talk2RadarWriter
from tests.browser_helpers import CHROMIUM_ARGS, PAGE_SIZE, labelled_field, poll, scene_has

TIMEOUT = 90.0
PROMPT = "all the cars and pedestrians"
OVERLAP_COLUMN = "labelled object it overlaps"
"""The answer table's column header (what a person reads: :data:`app.query.answer.OVERLAP_COLUMN`)."""


def _open(page, app):
    """Load the page; the new browser's session once its frame is drawn."""
    before = set(app.sessions)
    page.goto(app.url)
    page.wait_for_function(scene_has("/scene/lidar"), timeout=TIMEOUT * 1000)
    poll(lambda: set(app.sessions) - before, TIMEOUT, "the session")
    session = app.sessions[max(set(app.sessions) - before)]
    poll(lambda: session.frame is not None, TIMEOUT, "the frame")
    return session


def _ask(page, session, prompt: str):
    """Type ``prompt`` into the Query tab and press Enter; the answer drawn for it."""
    field = labelled_field(page, "Prompt")
    field.fill("")
    field.type(prompt)
    field.press("Enter")
    poll(
        lambda: session.answer is not None and session.answer.prompt == prompt,
        TIMEOUT,
        "the answer",
    )
    return session.answer


def _table_rows(page) -> list[list[str]]:
    """The cells of the answer table's body rows, as the page shows them."""
    return page.evaluate(
        "() => [...document.querySelectorAll('table')].filter(t => t.innerText.includes('score'))"
        ".flatMap(t => [...t.querySelectorAll('tbody tr')])"
        ".map(r => [...r.querySelectorAll('td')].map(c => c.innerText.trim()))"
    )


def _header(page) -> list[str]:
    return page.evaluate(
        "() => [...document.querySelectorAll('table')].filter(t => t.innerText.includes('score'))"
        ".flatMap(t => [...t.querySelectorAll('th')]).map(c => c.innerText.trim())"
    )


@pytest.mark.browser
def test_every_labelled_object_is_shown_and_each_answer_row_names_its_overlap(
    tmp_path, chromium, real_format_source, torch_threads, serve_app
) -> None:
    from playwright.sync_api import sync_playwright

    from model.checkpoint import load_checkpoint

    with torch_threads(1):
        model = load_checkpoint("checkpoints/tpcnet-small.pt")
        with (
            serve_app(real_format_source, model, split="train", pairs_root=tmp_path / "p") as app,
            sync_playwright() as p,
        ):
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": PAGE_SIZE[0], "height": PAGE_SIZE[1]})
                session = _open(page, app)
                sample = session.frame.sample
                actors = sample.meta.actors
                assert len(actors) > len(sample.boxes) >= 1  # more objects than referents
                # The layer: one numbered label per actor, and the referents apart.
                labels = f"/gt/labels/{len(actors) - 1}"
                page.wait_for_function(scene_has(labels), timeout=TIMEOUT * 1000)
                page.wait_for_function(scene_has("/gt/referents/edges"), timeout=TIMEOUT * 1000)
                shown = page.evaluate(
                    "() => Object.keys(window.__viserSceneTree.getState())"
                    ".filter(k => k.startsWith('/gt/labels/')).length"
                )
                assert shown == len(actors)

                answer = _ask(page, session, PROMPT)
                boxes = np.asarray(answer.predictions.boxes).reshape(-1, 7)
                assert len(boxes), "the shipped model found none of the frame's cars"
                page.wait_for_function(
                    "(h) => document.body.innerText.includes(h)", arg=OVERLAP_COLUMN
                )
                assert _header(page)[-1] == OVERLAP_COLUMN
                rows = _table_rows(page)
                assert len(rows) == min(len(boxes), 10)

                # What each row must say, from the sidecar's actors (nearest first = #1).
                truth = np.array([a.box for a in actors])
                order = np.argsort(np.hypot(truth[:, 0], truth[:, 1]), kind="stable")
                ious = np.asarray(iou3d(boxes, truth[order]))
                named = 0
                for row, iou in zip(rows, ious, strict=False):
                    best = int(np.argmax(iou))
                    if iou[best] <= 0:
                        assert row[-1] == "none"
                        continue
                    named += 1
                    found = re.fullmatch(r"#(\d+) (\w+), IoU ([0-9.]+)( \(referent\))?", row[-1])
                    assert found, row
                    assert int(found.group(1)) == best + 1
                    assert found.group(2) == actors[order[best]].cls
                    assert float(found.group(3)) == pytest.approx(iou[best], abs=0.006)
                assert named >= 1, "no answer box overlaps a labelled object"
            finally:
                browser.close()


def _root_without_labels(path):
    """A Talk2Radar root of one frame whose prompt refers to nothing (empty ``label_2``) and that
    has no sidecar: nothing on it is labelled."""
    rng = np.random.default_rng(4)
    writer = Talk2RadarWriter(path)
    ground = np.c_[rng.uniform([1, -20], [50, 20], (4000, 2)), np.full(4000, -1.7), np.ones(4000)]
    car = np.c_[rng.uniform([14, 1, -1.7], [18, 3, -0.2], (600, 3)), np.ones(600)]
    radar = np.c_[rng.uniform([2, -15, -1.5], [45, 15, 0.5], (80, 3)), rng.normal(0, 3, (80, 4))]
    files = writer.write_sensors(
        "f0",
        np.r_[ground, car].astype(np.float32),
        radar.astype(np.float32),
        vod_lidar_calibration(),
        vod_radar_calibration(),
    )
    sid = writer.write_sample(0, files, np.zeros((0, 7)), [], "the bus on the left")
    writer.write_image_sets({"test": [sid]})
    return path


@pytest.mark.browser
def test_a_frame_without_labels_has_no_overlap_column(
    tmp_path, chromium, untrained_model, torch_threads, serve_app
) -> None:
    from playwright.sync_api import sync_playwright

    root = _root_without_labels(tmp_path / "root")
    model = untrained_model(
        "referent", text_encoder="gru", head__score_threshold=0.0, operating_threshold=0.0
    )
    with torch_threads(1), serve_app(root, model, warm_up=False) as app, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": PAGE_SIZE[0], "height": PAGE_SIZE[1]})
            session = _open(page, app)
            answer = _ask(page, session, "the car ahead")
            assert len(answer.predictions.boxes), "threshold 0: every candidate is an answer"
            page.wait_for_function("() => document.body.innerText.includes('score')")
            assert _header(page) == ["#", "class", "score"]
            assert all(len(row) == 3 for row in _table_rows(page))
            assert "IoU" not in page.inner_text("body")
        finally:
            browser.close()
