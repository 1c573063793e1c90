"""Keys belong to where the person is (issue 39.5), in headless Chromium as a person presses them.

- A focused slider keeps its keys: arrows on the Query tab's *Score threshold* move the threshold
  and never the Annotate draft's selected box; nor do arrows pressed while the Query tab is shown
  with nothing focused. In the Annotate tab, with nothing focused, they move it.
- The list of keys (H) closes with Esc, with H and with a click outside it; while it is open a
  hotkey acts on nothing behind it (3 leaves the New box class alone); a click on the view while
  it is open closes it and still reaches the view (a box is placed).
"""

from __future__ import annotations

import numpy as np
import pytest

from app.annotate_tab.keys import HELP_CLOSE
from tests.browser_helpers import (
    CHROMIUM_ARGS,
    PAGE_SIZE,
    labelled_field,
    open_annotate,
    pixel_of,
    poll,
)

TIMEOUT = 60.0


def _slider(page, label: str):
    """The focusable thumb of the viser slider labelled ``label``."""
    row = f"//label[normalize-space()='{label}']/ancestor::div[contains(@class,'mantine-Flex-root')][1]"
    return page.locator(f"xpath={row}").locator("[role=slider]").first


@pytest.fixture
def annotating_page(tmp_path, chromium, write_tiny_root, torch_threads, serve_app):
    """A page on the Annotate tab of an app serving a tiny root: ``(page, app, panel)``."""
    from playwright.sync_api import sync_playwright

    from model import build_model

    root = write_tiny_root(tmp_path / "root", frames=1)
    with torch_threads(1):
        model = build_model("small", text_encoder="gru").eval()
        with serve_app(root, model, warm_up=False) as app, sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": PAGE_SIZE[0], "height": PAGE_SIZE[1]})
                yield page, app, open_annotate(page, app, TIMEOUT)
            finally:
                browser.close()


def _place(page, panel, x: float, y: float, count: int) -> None:
    camera = panel.session.client.camera
    page.mouse.click(*pixel_of(camera, (x, y, panel.frame.ground_z), PAGE_SIZE))
    poll(lambda: len(panel.draft.boxes) == count, TIMEOUT, f"box {count}")


@pytest.mark.browser
@pytest.mark.parametrize("keys", [["ArrowRight"] * 3, ["ArrowUp", "ArrowLeft", "Shift+ArrowDown"]])
def test_a_focused_slider_and_another_tab_keep_their_keys(annotating_page, keys) -> None:
    page, _app, panel = annotating_page
    _place(page, panel, 12.0, 3.0, 1)
    assert panel.selected is not None
    box = panel.draft.box_array.copy()

    page.get_by_role("tab", name="Query").click()
    threshold = panel.session.query.threshold
    before = threshold.value
    slider = _slider(page, "Score threshold")
    slider.focus()
    for key in keys:
        page.keyboard.press(key)
    poll(lambda: threshold.value != before, TIMEOUT, "the slider moved by its keys")
    page.wait_for_timeout(500)  # a box move would have arrived by now
    np.testing.assert_array_equal(panel.draft.box_array, box)

    page.evaluate("document.activeElement && document.activeElement.blur()")  # nothing focused
    for key in keys:
        page.keyboard.press(key)
    page.wait_for_timeout(500)
    np.testing.assert_array_equal(panel.draft.box_array, box)  # not the Annotate tab's keys here

    page.get_by_role("tab", name="Annotate").click()
    page.evaluate("document.activeElement && document.activeElement.blur()")
    page.keyboard.press("ArrowUp")  # where they belong, they act
    poll(lambda: not np.array_equal(panel.draft.box_array, box), TIMEOUT, "the box moved")


@pytest.mark.browser
def test_the_key_list_closes_with_esc_h_and_a_click_outside(annotating_page) -> None:
    page, _app, panel = annotating_page
    close = page.get_by_role("button", name=HELP_CLOSE)
    page.evaluate("document.activeElement && document.activeElement.blur()")
    assert panel.w.cls.value == "Car"

    page.keyboard.press("h")
    close.wait_for(state="visible", timeout=TIMEOUT * 1000)
    assert "Ctrl/Cmd+Shift+S" in page.inner_text("body")  # the keys' table
    page.keyboard.press("3")  # behind the window: nothing happens
    page.wait_for_timeout(500)
    assert panel.w.cls.value == "Car" and close.is_visible()
    page.keyboard.press("Escape")
    close.wait_for(state="hidden", timeout=TIMEOUT * 1000)

    page.keyboard.press("h")
    close.wait_for(state="visible", timeout=TIMEOUT * 1000)
    page.keyboard.press("h")
    close.wait_for(state="hidden", timeout=TIMEOUT * 1000)

    page.keyboard.press("h")
    close.wait_for(state="visible", timeout=TIMEOUT * 1000)
    window = page.evaluate(  # the list's window on the page: the click goes beside it
        "(label) => { let n = [...document.querySelectorAll('button')]"
        ".find((b) => b.textContent.trim() === label);"
        "while (n.parentElement && !n.textContent.includes('Annotate keys')) n = n.parentElement;"
        "const r = n.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; }",
        HELP_CLOSE,
    )
    camera = panel.session.client.camera
    ground = panel.frame.ground_z
    x, y = next(
        (x, y)
        for x, y in ((12.0, 3.0), (20.0, -5.0), (15.0, -8.0), (25.0, 0.0))
        if not (
            window[0] <= pixel_of(camera, (x, y, ground), PAGE_SIZE)[0] <= window[2]
            and window[1] <= pixel_of(camera, (x, y, ground), PAGE_SIZE)[1] <= window[3]
        )
    )
    _place(page, panel, x, y, 1)  # a click on the view: closes the list, places the box
    close.wait_for(state="hidden", timeout=TIMEOUT * 1000)
    page.keyboard.press("3")  # the keys act again
    poll(lambda: panel.w.cls.value == "Cyclist", TIMEOUT, "the New box class")


def _camera_pose(panel) -> np.ndarray:
    camera = panel.session.client.camera
    return np.r_[np.asarray(camera.position), np.asarray(camera.wxyz)]


def _box_list(page) -> str:
    """What the *Box* list shows in the page."""
    return labelled_field(page, "Box").input_value()


@pytest.mark.browser
def test_a_selected_boxs_keys_move_the_box_not_the_camera(annotating_page) -> None:
    """Issue 51.2: with a box selected the arrows, Q / E and Shift+arrows move and turn the box
    and leave the 3D camera where it is, and the *Box* list names the box all along (its entry's
    distance changes as it moves); with no box selected the same keys fly the camera."""
    page, _app, panel = annotating_page
    _place(page, panel, 12.0, 3.0, 1)
    page.evaluate("document.activeElement && document.activeElement.blur()")
    poll(lambda: _box_list(page).startswith("#1 Car"), TIMEOUT, "the Box list naming the box")
    page.wait_for_timeout(500)  # the camera at rest
    camera, box = _camera_pose(panel), panel.draft.box_array.copy()

    for key in ("ArrowUp", "ArrowUp", "KeyQ", "Shift+ArrowLeft", "KeyE", "KeyE"):
        page.keyboard.press(key)
    poll(lambda: panel.draft.box_array[0, 6] < box[0, 6] - 0.08, TIMEOUT, "the box turned")
    moved = panel.draft.box_array[0]
    assert moved[0] == pytest.approx(box[0, 0] + 0.2, abs=1e-6)  # Up twice, away on screen
    assert moved[1] == pytest.approx(box[0, 1] + 1.0, abs=1e-6)  # Shift+Left: 1 m left
    page.wait_for_timeout(800)  # a camera move would have been reported by now
    np.testing.assert_allclose(_camera_pose(panel), camera, atol=1e-6)
    distance = f"{np.hypot(moved[0], moved[1]):.1f} m"
    poll(lambda: _box_list(page) == f"#1 Car · {distance}", TIMEOUT, "the Box list after moves")
    assert panel.w.box.value == f"#1 Car · {distance}"

    page.keyboard.press("Escape")  # no box selected: the keys are the camera's
    poll(lambda: _box_list(page) == "(none)", TIMEOUT, "no box selected")
    box = panel.draft.box_array.copy()
    for key in ("ArrowLeft", "KeyE"):
        page.keyboard.down(key)
        page.wait_for_timeout(300)
        page.keyboard.up(key)
    poll(lambda: not np.allclose(_camera_pose(panel), camera, atol=1e-3), TIMEOUT, "the camera")
    np.testing.assert_array_equal(panel.draft.box_array, box)
