"""The camera panel in a real browser: Debian's headless Chromium, driven by Playwright, uses the
app as a person annotating a View-of-Delft frame would. Not a test module: the browser test of
``tests/app/browser/test_app_browser.py`` calls :func:`drive_camera`, and run as a script it writes the
documentation screenshot::

    python -m tools.camera_shot --out docs/images/camera.png

(the default synthetic data written in the View-of-Delft layout by :mod:`scenes.export_real`, the
bundled checkpoint, or an untrained model where there is none).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from app.browser import CHROMIUM_ARGS, find_chromium, scene_has

REPO = Path(__file__).resolve().parents[1]

VIEWPORT = {"width": 1400, "height": 860}
"""The window size the issue asks the Annotate tab to fit (Save pair in sight)."""


@dataclass(frozen=True)
class CameraRun:
    """What :func:`drive_camera` saw.

    Attributes:
        save_bottom: The lowest pixel row of the *Save pair* button when the Annotate tab opened.
        save_disabled: Whether it was disabled then (an empty draft).
        focus_after_escape: The tag of the focused element after Esc in *Pair prompt*.
        shown_width: Natural width of the camera image the browser shows (px).
        sample_id: The pair saved by Enter in *Pair prompt*.
    """

    save_bottom: float
    save_disabled: bool
    focus_after_escape: str
    shown_width: int
    sample_id: str


def _poll(condition: Callable[[], object], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")
        time.sleep(0.05)


CAMERA_IMAGE_WIDTH = """() => Math.max(0, ...Array.from(document.images)
    .filter((img) => img.complete && img.naturalWidth > 400).map((img) => img.naturalWidth))"""
"""The widest loaded image of the page: the camera panel's (the legends are narrower)."""


def drive_camera(
    app,
    chromium: str,
    screenshot: Path,
    query: str,
    pair_prompt: str,
    timeout_s: float = 60.0,
) -> CameraRun:
    """Open the app, run ``query`` (Enter), open the Annotate tab, add the first ready-made box
    (*Add object*), type ``pair_prompt``, leave the field with Esc, take the screenshot (the
    camera panel shows the ground truth, the answer and the draft projected), then save with
    Enter in *Pair prompt*."""
    from playwright.sync_api import sync_playwright

    timeout_ms = timeout_s * 1000
    store = app.annotations.store
    before = {p.sample_id for p in store.pairs()}
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport=VIEWPORT)
            sessions = set(app.sessions)
            page.goto(app.url)
            page.wait_for_function(
                "() => !document.body.innerText.includes('Connecting...')", timeout=timeout_ms
            )
            page.wait_for_function(scene_has("/scene/lidar"), timeout=timeout_ms)
            _poll(lambda: set(app.sessions) - sessions, timeout_s, "the session")
            session = app.sessions[max(set(app.sessions) - sessions)]
            box = page.locator("textarea:visible").first
            box.fill(query)
            box.press("Enter")
            _poll(lambda: session.camera.layer("pred") is not None, timeout_s, "the answer")

            page.get_by_role("tab", name="Annotate").click()
            panel = next(x for x in app.annotations.panels() if x.session is session)
            save = page.get_by_role("button", name="Save pair")
            save.wait_for(timeout=timeout_ms)
            bounds = save.bounding_box()
            assert bounds is not None
            save_bottom = bounds["y"] + bounds["height"]
            save_disabled = save.is_disabled()
            page.get_by_role("button", name="Add object").click()
            _poll(lambda: len(panel.draft.boxes) == 1, timeout_s, "the ready-made box")
            _poll(lambda: session.camera.layer("draft") is not None, timeout_s, "the draft drawn")
            prompt = page.locator("textarea:visible").first
            prompt.click()
            prompt.type(pair_prompt)
            _poll(lambda: panel.draft.prompt == pair_prompt, timeout_s, "the typed prompt")
            prompt.press("Escape")
            focus = str(page.evaluate("() => document.activeElement.tagName"))
            page.mouse.move(5, 5)  # no tooltip in the picture
            page.add_style_tag(content=".mantine-Notifications-root{display:none !important}")
            page.wait_for_timeout(2500)  # the scene fades in; SwiftShader renders slowly
            shown = int(page.evaluate(CAMERA_IMAGE_WIDTH))
            screenshot.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(screenshot))
            prompt.click()
            prompt.press("End")
            prompt.press("Enter")
            _poll(lambda: {x.sample_id for x in store.pairs()} - before, timeout_s, "the save")
            (sid,) = {x.sample_id for x in store.pairs()} - before
            return CameraRun(save_bottom, save_disabled, focus, shown, sid)
        finally:
            browser.close()


def build_parser() -> argparse.ArgumentParser:
    """``python -m tools.camera_shot``'s parser."""
    parser = argparse.ArgumentParser(description="Screenshot the camera panel for the docs.")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "camera.png")
    parser.add_argument("--query", default="the cyclist right in front of us")
    parser.add_argument("--prompt", default="the cyclist crossing right in front of us")
    return parser


def main() -> int:
    """Write ``docs/images/camera.png`` from the default data in the View-of-Delft layout."""
    import launch
    from app import AppConfig, Talk2PCApp
    from scenes.export_real import export

    args = build_parser().parse_args()
    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("no Chromium found")
    with tempfile.TemporaryDirectory() as tmp:
        vod = Path(tmp) / "vod"
        export(launch.ensure_default_data(), None, vod)
        root = launch.open_root(vod, None)
        split = launch.choose_split(root, None)
        model, note = launch.load_model(None, "cpu", threads=1)
        pairs = Path(tmp) / "vod-talk2radar"  # named: a release is never written beside
        config = AppConfig(port=0, split=split, model_note=note, pairs_root=pairs)
        app = Talk2PCApp(root, model, config).start()
        try:
            app.wait_ready(timeout=120)
            run = drive_camera(app, chromium, args.out, args.query, args.prompt, 120.0)
        finally:
            app.stop()
    print(f"{args.out}: {run}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
