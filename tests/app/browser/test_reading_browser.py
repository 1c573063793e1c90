"""One referent, one box (issue 49, item 3), in headless Chromium as a person sees it.

The served model lets many boxes through: the small referent-path TPCNet, untrained (weights
drawn from a fixed seed, Bi-GRU text encoder), whose operating threshold is 0, so that the Query
tab's *Score threshold* starts at 0 and every one of the detector's candidates is an answer. On
it, typed into the Query tab:

- a plural, "the cars", is answered with a set: more than one box drawn, and no "one object" line;
- a singular description, "the car closest to us", with exactly one box, and the panel says
  "One object is meant: the best box is the answer.";
- a command, "park behind the silver van on the left", with exactly one box, and the panel says
  "A command means one object: the best box is the answer." and what was grounded ("Read as").

The boxes are counted on the server (``session.pred_view.count``, what was drawn into this
browser's scene) and in the browser's own scene tree (one label node per box). Were
``TPCNet.ground`` to stop narrowing singular answers (``ranked=True``), the singular and the
command would get every candidate, as the plural does, and the test would fail.
"""

from __future__ import annotations

import pytest

from tests.browser_helpers import CHROMIUM_ARGS, PAGE_SIZE, labelled_field, poll, scene_has

TIMEOUT = 90.0
PLURAL = "the cars"
SINGULAR = "the car closest to us"
COMMAND = "park behind the silver van on the left"
ONE_BOX = "the best box is the answer"

PRED_LABELS = (
    "() => window.__viserSceneTree === undefined ? -1 : Object.keys("
    "window.__viserSceneTree.getState()).filter(k => k.startsWith('/pred/labels/')).length"
)
"""The answer's label nodes in the browser's scene tree (one per drawn box, up to 20)."""


def _open(page, app):
    """Load the page; the new browser's session once its frame is drawn."""
    before = set(app.sessions)
    page.goto(app.url)
    page.wait_for_function(scene_has("/scene/lidar"), timeout=TIMEOUT * 1000)
    poll(lambda: set(app.sessions) - before, TIMEOUT, "the session")
    session = app.sessions[max(set(app.sessions) - before)]
    poll(lambda: session.frame is not None and session.query is not None, TIMEOUT, "the frame")
    return session


def _ask(page, session, prompt: str) -> tuple[int, str]:
    """Type ``prompt`` into the Query tab and press Enter; ``(boxes drawn, panel text)`` once the
    browser shows the answer."""
    field = labelled_field(page, "Prompt")
    field.fill(prompt)
    field.press("Enter")
    poll(
        lambda: session.answer is not None and session.answer.prompt == prompt,
        TIMEOUT,
        f"the answer to {prompt!r}",
    )
    with session.lock:  # the answer is drawn and its panel text written under the lock
        drawn = session.pred_view.count
        content = session.query.results.content
    assert drawn == len(session.answer.predictions.boxes)
    page.wait_for_function(f"() => ({PRED_LABELS})() === {min(drawn, 20)}", timeout=TIMEOUT * 1000)
    # this answer's own summary ("N boxes in T ms (ground G ms"), as the page renders it
    summary = next(line for line in content.splitlines() if " ms** (ground " in line)
    summary = summary.replace("**", "").split(", scene")[0]
    page.wait_for_function(
        f"() => document.body.innerText.includes({summary!r})", timeout=TIMEOUT * 1000
    )
    return drawn, page.inner_text("body")


@pytest.mark.browser
def test_a_singular_description_and_a_command_get_one_box(
    tmp_path, chromium, write_tiny_root, torch_threads, serve_app, untrained_model
) -> None:
    from playwright.sync_api import sync_playwright

    root = write_tiny_root(tmp_path / "root", frames=1)
    with torch_threads(1):
        model = untrained_model(
            "referent", text_encoder="gru", head__score_threshold=0.0, operating_threshold=0.0
        )
        with (
            serve_app(root, model, warm_up=False) as app,
            sync_playwright() as p,
        ):
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": PAGE_SIZE[0], "height": PAGE_SIZE[1]})
                session = _open(page, app)
                assert session.query.threshold.value == 0.0  # every candidate passes

                boxes, text = _ask(page, session, PLURAL)
                assert boxes > 1, "a plural is answered with a set"
                assert ONE_BOX not in text

                boxes, text = _ask(page, session, SINGULAR)
                assert boxes == 1, f"{SINGULAR!r}: {boxes} boxes drawn"
                assert f"One object is meant: {ONE_BOX}." in text
                assert "A command means one object" not in text

                boxes, text = _ask(page, session, COMMAND)
                assert boxes == 1, f"{COMMAND!r}: {boxes} boxes drawn"
                assert f"A command means one object: {ONE_BOX}." in text
                assert "Read as" in text and "the car on the left" in text
            finally:
                browser.close()
