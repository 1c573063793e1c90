"""The app in a real browser: Debian's headless Chromium, driven by Playwright, opens the page,
types a prompt into the Query tab and saves a screenshot (:func:`drive`). Used by the documentation
pictures (``python -m app.screenshots``) and by the real-browser tests (``tests/``, which import
it; nothing here imports ``tests``). Chromium is the system's (``apt-get install chromium``),
never one Playwright downloads.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path

PAGE_SIZE = (1400, 860)
"""The browser tests' page size (CSS pixels): ``viewport={"width": 1400, "height": 860}``."""
CHROMIUM_CANDIDATES = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
"""Headless Chromium with software rendering (SwiftShader), nothing fetched from the network."""

HIDE_NOTIFICATIONS = ".mantine-Notifications-root{display:none !important}"
"""A style that keeps the page's notifications out of a screenshot."""


def find_chromium() -> str | None:
    """Path of a Chromium executable, or None."""
    for candidate in CHROMIUM_CANDIDATES:
        if Path(candidate).is_file():
            return candidate
    return shutil.which("chromium")


def scene_has(name: str) -> str:
    """A JavaScript predicate: the browser's own scene tree (``window.__viserSceneTree``, a hook
    the viser 1.1.1 client exposes) holds the node ``name``."""
    return (
        "() => window.__viserSceneTree !== undefined && "
        f"Object.keys(window.__viserSceneTree.getState()).includes({name!r})"
    )


def drive(
    url: str,
    screenshot: Path,
    prompt: str,
    chromium: str,
    wait_answer: Callable[[], bool] | None = None,
    before_screenshot: Callable[[], None] | None = None,
    timeout_s: float = 40.0,
    expect_boxes: bool = True,
    page_size: tuple[int, int] = PAGE_SIZE,
) -> float:
    """Open ``url``, type ``prompt`` + Enter, wait for the boxes, save a screenshot.

    Args:
        url: The app's address (:attr:`app.server.Talk2PCApp.url`).
        screenshot: The PNG written (its folder is created).
        prompt: What is typed into the Query tab's prompt box.
        chromium: The Chromium executable (:func:`find_chromium`).
        wait_answer: Optional ``() -> bool`` polled until the server has drawn the answer.
        before_screenshot: Optional ``() -> None`` called just before the screenshot (e.g. to
            move the camera or to check the answer; what it raises ends the run, no picture).
        timeout_s: Seconds each wait may take.
        expect_boxes: Whether the answer has boxes; False: wait for the heatmap only, and check
            that the browser's scene holds no predicted box once the server has answered.
        page_size: The page's width and height in CSS pixels.

    Returns:
        Seconds from pressing Enter to the predicted-box node (or, with ``expect_boxes`` False,
        the heatmap) existing in the browser.

    Raises:
        AssertionError: with ``expect_boxes`` False, boxes were drawn.
        TimeoutError: a wait ran past ``timeout_s`` (Playwright's).
    """
    from playwright.sync_api import sync_playwright

    timeout_ms = timeout_s * 1000
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": page_size[0], "height": page_size[1]})
            page.goto(url)
            page.wait_for_function(
                "() => !document.body.innerText.includes('Connecting...')", timeout=timeout_ms
            )
            page.wait_for_function(scene_has("/scene/lidar"), timeout=timeout_ms)
            box = page.locator("textarea:not([aria-hidden='true'])").first
            box.wait_for(timeout=timeout_ms)
            box.fill(prompt)
            start = time.perf_counter()
            box.press("Enter")
            if expect_boxes:
                page.wait_for_function(scene_has("/pred/edges"), timeout=timeout_ms)
            page.wait_for_function(scene_has("/heatmap"), timeout=timeout_ms)
            elapsed = time.perf_counter() - start
            if wait_answer is not None:
                deadline = time.monotonic() + timeout_s
                while not wait_answer() and time.monotonic() < deadline:
                    time.sleep(0.05)
            if not expect_boxes:
                page.wait_for_timeout(500)  # anything still in flight arrives
                assert not page.evaluate(scene_has("/pred/edges")), "boxes drawn for no answer"
            if before_screenshot is not None:
                before_screenshot()
            page.add_style_tag(content=HIDE_NOTIFICATIONS)
            page.wait_for_timeout(2500)  # the scene fades in; SwiftShader renders slowly
            screenshot.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(screenshot))
            return elapsed
        finally:
            browser.close()
