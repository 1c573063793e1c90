"""Real-browser tests of the Annotate tab (issue 19): headless Chromium, driven by Playwright,
annotates as a person does (mouse clicks on the ground, the dropdowns, the keyboard), and the
saved files are read back from disk.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scenes.layout import LABEL, LIDAR_FOLDER, sample_file
from tests.browser_helpers import CHROMIUM_ARGS, open_annotate, pixel_of, poll

TIMEOUT = 60.0


def _label_classes(root: Path, sample_id: str) -> list[str]:
    """The class names of the lines of a sample's ``label_2`` file, in file order."""
    path = sample_file(root / LIDAR_FOLDER, LABEL, sample_id)
    return [line.split(" ", 1)[0] for line in path.read_text().splitlines() if line.strip()]


@pytest.mark.browser
def test_browser_next_class_never_relabels_the_placed_box(
    tmp_path, chromium, write_tiny_root, torch_threads, serve_app, gt_box
) -> None:
    """Place a Car with a ground click, choose Pedestrian for the next box, place it, save: the
    saved label_2 holds one Car and one Pedestrian (the Car is not relabelled)."""
    from playwright.sync_api import sync_playwright

    from model import build_model

    root = write_tiny_root(tmp_path / "root", frames=2)
    with torch_threads(1):
        model = build_model("small", text_encoder="gru").eval()
        with serve_app(root, model, warm_up=False) as app, sync_playwright() as p:
            store = app.annotations.store
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 860})
                panel = open_annotate(page, app, TIMEOUT)
                ground = panel.frame.ground_z
                car = gt_box[:2] + np.array([2.0 * app.frame.index, 0.0])
                camera = panel.session.client.camera
                page.mouse.click(*pixel_of(camera, (car[0], car[1], ground)))
                poll(lambda: len(panel.draft.boxes) == 1, TIMEOUT, "the car")
                assert panel.draft.classes == ("Car",) and panel.selected is not None

                page.get_by_label("New box class").click()
                page.get_by_role("option", name="Pedestrian").click()
                poll(lambda: panel.w.cls.value == "Pedestrian", TIMEOUT, "the next class")
                page.wait_for_timeout(300)  # any (wrong) relabel would have arrived by now
                assert panel.draft.classes == ("Car",), "choosing the next class relabelled"

                page.mouse.click(*pixel_of(camera, (10.0, -3.0, ground)))
                poll(lambda: len(panel.draft.boxes) == 2, TIMEOUT, "the pedestrian")
                assert panel.draft.classes == ("Car", "Pedestrian")

                prompt = page.locator("textarea:visible").first
                prompt.click()
                prompt.type("the car and the pedestrian ahead")
                poll(lambda: panel.draft.prompt.endswith("ahead"), TIMEOUT, "the prompt")
                prompt.press("Enter")
                poll(lambda: store.pairs(), TIMEOUT, "the save")
            finally:
                browser.close()
            (pair,) = store.pairs()
            assert sorted(_label_classes(store.path, pair.sample_id)) == ["Car", "Pedestrian"]
