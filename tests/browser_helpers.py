"""Real-browser helpers shared by the browser tests and the screenshot scripts: where Debian's
Chromium is, the flags it runs with (headless, software rendering) and a page-side check of
viser's scene tree (from :mod:`app.browser`, which ``python -m app.screenshots`` uses too),
waiting on the server's state (:func:`poll`), where a world point appears on the canvas
(:func:`pixel_of`, for ground clicks), opening the Annotate tab (:func:`open_annotate`), a page
on a served app with its session (:func:`open_session_page`) and a screenshot without the
notifications (:func:`screenshot`). Not a test module; the ``chromium`` fixture of ``conftest.py`` uses it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from app.browser import (
    CHROMIUM_ARGS,
    CHROMIUM_CANDIDATES,
    HIDE_NOTIFICATIONS,
    PAGE_SIZE,
    find_chromium,
    scene_has,
)
from tests.paths import REPO

ARTIFACTS = REPO / "artifacts"

__all__ = [
    "ARTIFACTS",
    "CHROMIUM_ARGS",
    "CHROMIUM_CANDIDATES",
    "PAGE_SIZE",
    "REPO",
    "find_chromium",
    "labelled_field",
    "open_annotate",
    "open_session_page",
    "pixel_of",
    "poll",
    "scene_has",
    "screenshot",
]


def poll(condition: Callable[[], object], timeout: float, what: str) -> None:
    """Wait until ``condition()`` holds (checked every 50 ms); fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.05)


def open_session_page(browser, app, node: str, timeout: float = 90.0):
    """A new page of ``PAGE_SIZE`` on ``app``, once its scene tree holds ``node``, and the
    server's session of that page: ``(page, session)``."""
    page = browser.new_page(viewport={"width": PAGE_SIZE[0], "height": PAGE_SIZE[1]})
    before = set(app.sessions)
    page.goto(app.url)
    page.wait_for_function(scene_has(node), timeout=timeout * 1000)
    poll(lambda: set(app.sessions) - before, timeout, "the page's session")
    return page, app.sessions[max(set(app.sessions) - before)]


def screenshot(page, name: str) -> None:
    """``artifacts/<name>`` of ``page``, notifications hidden, after the software renderer has
    drawn (SwiftShader renders slowly)."""
    page.add_style_tag(content=HIDE_NOTIFICATIONS)
    page.wait_for_timeout(1500)
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / name))


def pixel_of(camera, point, page_size: tuple[float, float] | None = None) -> tuple[float, float]:
    """Where a world point (LiDAR frame) appears on a browser's canvas (full-page canvas).

    viser's camera pose is ``T_world_camera`` in the OpenCV convention (+z forward, +y down) and
    ``fov`` is the vertical field of view. The camera's ``image_width`` / ``image_height`` are the
    render size, which the client may keep below the page's (its adaptive pixel ratio): with
    ``page_size`` (the page's width and height in CSS pixels) the result is in the page's pixels,
    where a mouse click goes.
    """
    w, x, y, z = camera.wxyz
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    p = rotation.T @ (np.asarray(point, dtype=np.float64) - np.asarray(camera.position))
    focal = camera.image_height / 2.0 / math.tan(camera.fov / 2.0)
    u = camera.image_width / 2.0 + focal * p[0] / p[2]
    v = camera.image_height / 2.0 + focal * p[1] / p[2]
    if page_size is not None:
        u *= page_size[0] / camera.image_width
        v *= page_size[1] / camera.image_height
    return u, v


def open_annotate(page, app, timeout_s: float = 40.0):
    """Load the app's page, wait for the scene, open the Annotate tab; returns the new browser's
    :class:`app.annotate_tab.AnnotationPanel` once its draft has a frame."""
    sessions = set(app.sessions)
    page.goto(app.url)
    page.wait_for_function(
        "() => !document.body.innerText.includes('Connecting...')", timeout=timeout_s * 1000
    )
    page.wait_for_function(scene_has("/scene/lidar"), timeout=timeout_s * 1000)
    page.get_by_role("tab", name="Annotate").click()
    poll(lambda: set(app.sessions) - sessions, timeout_s, "the session")
    session = app.sessions[max(set(app.sessions) - sessions)]
    panel = next(p for p in app.annotations.panels() if p.session is session)
    poll(lambda: panel.frame is not None, timeout_s, "the draft's frame")
    return panel


def labelled_field(page, label: str):
    """The text field (``input`` or ``textarea``) of the viser control labelled ``label``
    (viser's ``<label for=...>`` does not name a text field's id, so ``get_by_label`` misses)."""
    row = f"//label[normalize-space()='{label}']/ancestor::div[contains(@class,'mantine-Flex-root')][1]"
    return page.locator(f"xpath={row}").locator("input, textarea").first
