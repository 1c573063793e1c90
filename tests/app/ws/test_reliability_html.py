"""No stored text renders as HTML or markdown (issue 11): every text that came from a user or a file
reaches viser's markdown elements through :func:`app.text.md_text`.

viser renders markdown with CommonMark + GFM tables and raw HTML; here the markdown is rendered
with markdown-it-py (CommonMark, raw HTML on, tables on), and the rendered HTML may hold no tag
but the ones the app's own markdown makes, while the text reads exactly as typed.
"""

from __future__ import annotations

import numpy as np
import pytest

from annotate import Draft, PairInfo
from annotate.evidence import BoxEvidence, Motion
from annotate.validation import Issue, Severity, ValidationReport
from app.annotate_tab.formatting import checks_markdown, evidence_markdown, pairs_markdown
from app.serving.navigation import Frame, frame_markdown
from app.text import md_text
from scenes.frame import Sample
from scenes.geometry.calib import vod_lidar_calibration
from tests.app.ws.markdown_helpers import OWN_TAGS, render, tags, visible

HOSTILE = (
    "<img src=x onerror=alert(1)>",
    "<b>bold</b> <script>alert(1)</script>",
    "![t](http://host/x.png) and [click](javascript:alert(1))",
    "<http://host/x> &lt;img src=x&gt; &#60;b&#62;",
    "<!-- hidden --> <div\nonclick=alert(1)>x</div>",
    "| a | b |\n|---|---|\n| c | d |",
    "# heading\n- item\n> quote\n1. one\n```\ncode\n```",
    "`code` **bold** _em_ ~~strike~~ \\<i>escaped\\</i> trailing \\",
)
"""Prompts and names a hostile but fair user could save."""


def _shown_as_text(markdown: str, text: str) -> None:
    rendered = render(markdown)
    assert tags(rendered) <= OWN_TAGS, rendered
    assert " ".join(text.split()) in visible(rendered), rendered


@pytest.mark.parametrize("text", HOSTILE)
def test_md_text_is_shown_literally(text: str) -> None:
    escaped = md_text(text)
    assert "\n" not in escaped
    _shown_as_text(escaped, text)
    _shown_as_text(f"*Running:* {escaped}", text)
    _shown_as_text(f"| a |\n| --- |\n| {escaped} |", text)
    _shown_as_text(f"- {escaped}", text)


def test_md_text_keeps_plain_text() -> None:
    assert md_text("the car about 15 m ahead") == "the car about 15 m ahead"
    assert md_text("ünïcode – ok 42") == "ünïcode – ok 42"
    assert md_text(None) == "None"


@pytest.mark.parametrize("text", HOSTILE)
def test_saved_pairs_table(text: str) -> None:
    pairs = [
        PairInfo("00042", 2, ("train",), text, 1, text, "2026-01-01T00:00:00", None),
        PairInfo("00043", 1, (text,), "plain", 0, "ada", "2026-01-02T00:00:00", None),
    ]
    markdown = pairs_markdown(pairs, root=f"/data/{text}")
    _shown_as_text(markdown, text)
    rendered = render(markdown)
    assert rendered.count("<tr>") == 3  # header and two rows: the table is not broken
    assert all(row.count("<td") == 6 for row in rendered.split("<tr>")[2:])
    _shown_as_text(pairs_markdown([], root=text), text)


@pytest.mark.parametrize("text", HOSTILE)
def test_frame_info(text: str) -> None:
    sample = Sample(
        sample_id="00001",
        lidar=np.zeros((0, 4), np.float32),
        radar=np.zeros((0, 7), np.float32),
        boxes=np.zeros((0, 7)),
        classes=(),
        prompt=text,
        calib=vod_lidar_calibration(),
    )
    _shown_as_text(frame_markdown(Frame(index=0, sample=sample, ground_z=-1.7), 3), text)


@pytest.mark.parametrize("text", HOSTILE)
def test_checks_and_evidence(text: str) -> None:
    report = ValidationReport(
        (Issue("prompt", text), Issue("boxes", text, severity=Severity.WARNING))
    )
    _shown_as_text(checks_markdown(report), text)
    # A class name forged through the websocket reaches the evidence table.
    draft = Draft().add_box((12.0, 3.0, -0.95, 4.2, 1.8, 1.5, 0.4), text)
    evidence = [BoxEvidence(10, 0, None, Motion.UNKNOWN, 12.4, 10.0)]
    _shown_as_text(evidence_markdown(draft, evidence, selected_id=None), text)


@pytest.mark.browser
def test_viser_shows_escaped_text_literally_in_a_real_browser(chromium, chromium_args) -> None:
    """The proof in viser's own client (react-markdown with raw HTML): escaped, the hostile text
    is shown character for character and makes no element; unescaped (the control), the same
    text makes ``<img>`` elements (fetched by the browser), a ``<b>`` and links (also from a bare
    ``www.`` address and an e-mail address, which GFM links by itself)."""
    import viser
    from playwright.sync_api import sync_playwright

    payload = (
        '<img src="http://127.0.0.1:9/tag.png" onerror="alert(1)"> <b>bold</b> '
        "![t](http://127.0.0.1:9/fetched.png) [link](http://127.0.0.1:9/page) "
        "www.host.example me@host.example"
    )
    count = """() => [
        document.querySelectorAll('img[src*="127.0.0.1:9"]').length,
        [...document.querySelectorAll('b, strong')].filter(e => e.innerText === 'bold').length,
        document.querySelectorAll('a[href*="127.0.0.1:9"], a[href*="host.example"]').length,
    ]"""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        server.gui.add_markdown(f"ESCAPED {md_text(payload)}")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=chromium_args)
            try:
                page = browser.new_page()
                page.goto(f"http://127.0.0.1:{server.get_port()}")
                page.wait_for_function(
                    "() => document.body.innerText.includes('ESCAPED')", timeout=60_000
                )
                page.wait_for_timeout(500)
                text = " ".join(page.evaluate("() => document.body.innerText").split())
                assert f"ESCAPED {payload}" in text
                assert page.evaluate(count) == [0, 0, 0]
                # The control: the same text unescaped is live HTML in viser's markdown.
                server.gui.add_markdown(f"RAW {payload}")
                page.wait_for_function(
                    "() => document.body.innerText.includes('RAW')", timeout=30_000
                )
                page.wait_for_timeout(500)
                assert page.evaluate(count) == [2, 1, 3]  # the link, the URL, the address
            finally:
                browser.close()
    finally:
        server.stop()
