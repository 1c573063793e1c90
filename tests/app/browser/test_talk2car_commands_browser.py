"""Commands first-class in the app (issue 48.5), in headless Chromium as a person uses it: a
nuScenes root with its Talk2Car commands opens on a frame that lists its commands (no "this root
has no prompts"), a click on the second command runs it (the prompt box shows it, the answer
comes), its referred object is the one box labelled "(referent)" and drawn apart, and unticking
*Other annotations* hides every other annotation's label while the referent's stays; screenshot
``artifacts/talk2car-commands.png``."""

from __future__ import annotations

import numpy as np
import pytest

from app.serving.frame_commands import button_label
from tests.browser_helpers import (
    CHROMIUM_ARGS,
    labelled_field,
    open_session_page,
    poll,
    screenshot,
)

TIMEOUT = 90.0

SHOWN_LABELS = """() => { const s = window.__viserSceneTree.getState();
    return Object.keys(s).filter(k => k.startsWith('/gt/labels/'))
        .filter(k => s[k].effectiveVisibility !== false && s[k].visibility !== false)
        .map(k => s[k].message.props.text); }"""
"""The texts of the ground truth's labels the browser's scene tree shows (they are drawn into the
canvas, not the page's text)."""


@pytest.mark.browser
def test_commands_listed_clicked_and_the_referent_apart(serve_nuscenes, chromium) -> None:
    from playwright.sync_api import sync_playwright

    with serve_nuscenes("all") as app, sync_playwright() as p:
        commands = app.frames.root.commands(app.frame.sample_id)
        assert len(commands) >= 2
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        try:
            page, session = open_session_page(browser, app, "/gt/referents/edges", TIMEOUT)

            # The first frame lists its commands, each a button; no "no prompts" line.
            page.get_by_text(f"Commands ({len(commands)}):").first.wait_for(timeout=20_000)
            second = page.get_by_role("button", name=button_label(1, commands[1].command.text))
            second.wait_for(timeout=20_000)
            assert "this root has no prompts" not in page.inner_text("body")

            # A click runs it as if typed: the prompt box shows it, the answer comes.
            second.click()
            text = commands[1].command.text
            poll(
                lambda: session.answer is not None and session.answer.prompt == text,
                TIMEOUT,
                "the command's answer",
            )
            poll(
                lambda: labelled_field(page, "Prompt").input_value() == text,
                TIMEOUT,
                "the prompt box",
            )
            # Its referred object is the one referent, labelled apart.
            referent = session.objects.boxes[np.asarray(session.objects.referent)]
            assert len(referent) == 1
            np.testing.assert_allclose(referent[0], commands[1].box, atol=1e-9)
            number = session.objects.referent.index(True) + 1
            shown = f"#{number} {commands[1].cls} (referent)"
            page.wait_for_function(
                f"() => ({SHOWN_LABELS})().includes({shown!r})", timeout=TIMEOUT * 1000
            )
            labels = page.evaluate(SHOWN_LABELS)
            assert [t for t in labels if "(referent)" in t] == [shown]
            assert len(labels) > 1  # the other annotations' labels too

            # *Other annotations*: one control hides them all; the referent stays.
            page.get_by_text("Other annotations", exact=True).click()
            poll(lambda: not session.gt_view.others_visible, TIMEOUT, "the others hidden")
            page.wait_for_function(f"() => ({SHOWN_LABELS})().length === 1", timeout=TIMEOUT * 1000)
            assert page.evaluate(SHOWN_LABELS) == [shown]
            screenshot(page, "talk2car-commands.png")
        finally:
            browser.close()
