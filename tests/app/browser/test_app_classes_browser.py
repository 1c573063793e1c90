"""Real-browser test of the app serving a ``nuscenes`` class-set model (issue 36): headless
Chromium, driven by Playwright, uses the app as a person does on a small ``--classes nuscenes``
synthetic root and checks what the page shows.

- The View tab's legend names the ten classes of the served set, and its swatches, read from the
  image the page shows, are the colours of :mod:`scenes.geometry.classes` exactly (the legend is a
  PNG: viser's default JPEG shifted them by up to 40 levels).
- "the trucks" typed into the prompt box is answered with boxes drawn in the browser's scene in
  the Truck colour, labelled ``Truck``, and the answer in words, "N trucks match.", shown as text.
- "the tram" at the highest score threshold gets the honest empty answer worded from the set's
  plurals ("... I find cars, trucks, buses, ... and barriers."), and no box is drawn.
- The Annotate tab's *New box class* offers exactly the ten classes, *Change class* shows a button
  for each; a TrafficCone placed with a ground click is sized as its class, relabelled through the
  buttons, saved with Enter and read back from disk with its class. Key 0 only toggles *Refers to
  nothing* (with ten classes it also chose the tenth, Barrier: keys go 1 to 9).

The served model is the small TPCNet (Bi-GRU text encoder, referent path) with weights drawn from
a fixed seed, the ``Truck`` channel of its heatmap biased up so that what it boxes is known
(trucks) without a trained checkpoint; its operating threshold is 0, so every candidate is an
answer until the person raises *Score threshold*.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from app.view.colors import class_legend, legend_swatches
from app.view.scene_view import CLASS_LEGEND
from scenes.geometry.classes import NUSCENES
from scenes.talk2radar.layout import LABEL, LIDAR_FOLDER, sample_file
from scenes.talk2radar.root import Talk2RadarRoot
from tests.browser_helpers import CHROMIUM_ARGS, PAGE_SIZE, pixel_of, poll, scene_has

TIMEOUT = 60.0
SHOWN = "Truck"
"""The class the served model boxes (its heatmap channel biased up), beyond the three."""


@pytest.fixture(scope="module")
def nuscenes_synth_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``python -m scenes.synth --classes nuscenes --no-camera``'s root, 2 worlds of 2 prompts,
    all test (about 1 s)."""
    from scenes.synth.generate import SynthSettings, generate_root

    root = tmp_path_factory.mktemp("nuscenes-classes") / "root"
    settings = SynthSettings(seed=5, classes="nuscenes", camera=None, prompts_per_world=2)
    generate_root(root, 4, settings, split_fractions=(0.0, 0.0, 1.0))
    return root


def _truck_frame(root: Path) -> int:
    """Index in the test split of the first frame whose world holds a truck (from the data)."""
    r = Talk2RadarRoot(root, classes=NUSCENES)
    for index, sid in enumerate(r.ids("test")):
        if any(a.cls == SHOWN for a in r.load(sid).meta.actors):
            return index
    raise AssertionError(f"no frame of {root} holds a {SHOWN}")


@pytest.fixture(scope="module")
def page_and_app(
    nuscenes_synth_root, chromium, torch_threads, serve_app, untrained_nuscenes_app_model
):
    """A Chromium page on the app serving the root with a ``nuscenes`` model: ``(page, app,
    session)``, the page loaded on the frame with a truck."""
    from playwright.sync_api import sync_playwright

    with torch_threads(1):
        model = untrained_nuscenes_app_model()
        with torch.no_grad():
            model.scene.head.heatmap[-1].bias[NUSCENES.names.index(SHOWN)] += 6.0
        with (
            serve_app(nuscenes_synth_root, model, warm_up=False, split="test") as app,
            sync_playwright() as p,
        ):
            assert app.go_to(_truck_frame(nuscenes_synth_root)) is not None
            browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
            try:
                page = browser.new_page(viewport={"width": PAGE_SIZE[0], "height": PAGE_SIZE[1]})
                before = set(app.sessions)
                page.goto(app.url)
                page.wait_for_function(scene_has("/scene/lidar"), timeout=TIMEOUT * 1000)
                poll(lambda: set(app.sessions) - before, TIMEOUT, "the page's session")
                session = app.sessions[max(set(app.sessions) - before)]
                yield page, app, session
            finally:
                browser.close()


def _scene_node(page, name: str) -> dict | None:
    """The browser's own scene node ``name`` (its message's props; typed arrays as lists)."""
    return page.evaluate(
        """name => { const n = window.__viserSceneTree.getState()[name];
        if (!n || !n.message) return null; const out = {};
        for (const [k, v] of Object.entries(n.message.props || {}))
            out[k] = ArrayBuffer.isView(v) ? Array.from(v) : v;
        return out; }""",
        name,
    )


def _row(page, label: str):
    """The viser control row labelled ``label``."""
    xpath = f"//label[normalize-space()='{label}']/ancestor::div[contains(@class,'mantine-Flex-root')][1]"
    return page.locator(f"xpath={xpath}")


@pytest.mark.browser
def test_browser_legend_and_answers_name_every_class_of_the_served_set(page_and_app) -> None:
    page, _app, session = page_and_app
    truck = NUSCENES.get(SHOWN)

    # the legend: its label names the ten classes, as text; its swatches are their colours
    page.get_by_role("tab", name="View").click()
    label = f"{CLASS_LEGEND}: {', '.join(NUSCENES.names)}"
    page.get_by_text(label, exact=True).wait_for(timeout=TIMEOUT * 1000)
    image = page.locator(f"xpath=//*[normalize-space(text())='{label}']/following::img[1]")
    data = image.evaluate(
        "async img => Array.from(new Uint8Array(await (await fetch(img.src)).arrayBuffer()))"
    )
    shown = np.asarray(Image.open(io.BytesIO(bytes(data))).convert("RGB"))
    assert shown.shape == class_legend(NUSCENES.names).shape
    for cls, (x0, y0, x1, y1) in zip(NUSCENES.classes, legend_swatches(len(NUSCENES)), strict=True):
        swatch = shown[y0 : y1 + 1, x0 : x1 + 1].reshape(-1, 3)
        assert (swatch == cls.color).all(), f"{cls.name}'s swatch is not {cls.color}"

    # a prompt about a class beyond the three: trucks drawn in the Truck colour, named
    page.get_by_role("tab", name="Query").click()
    prompt = page.locator("textarea:not([aria-hidden='true'])").first
    prompt.fill("the trucks")
    prompt.press("Enter")
    page.wait_for_function(scene_has("/pred/edges"), timeout=TIMEOUT * 1000)
    poll(lambda: session.answer is not None, TIMEOUT, "the answer")
    count = len(session.answer.predictions.boxes)
    assert count > 0 and set(session.answer.predictions.classes) == {SHOWN}
    said = f"{count} {truck.plural if count != 1 else truck.noun} match"
    page.get_by_text(said).first.wait_for(timeout=TIMEOUT * 1000)
    edges = _scene_node(page, "/pred/edges")
    colors = np.asarray(edges["colors"]).reshape(-1, 3)
    assert len(colors) and (colors == truck.color).all()
    first = _scene_node(page, "/pred/labels/0")
    assert first is not None and first["text"].startswith(f"{SHOWN} ")
    assert "\\" not in page.inner_text("body")  # the answer shown as text, no markup escapes

    # something the model cannot see: nothing boxed, the set's plurals in words
    threshold = _row(page, "Score threshold").locator("input.mantine-NumberInput-input")
    threshold.fill("0.95")
    threshold.press("Enter")
    poll(lambda: session.query.threshold.value == pytest.approx(0.95), TIMEOUT, "the threshold")
    prompt.fill("the tram")
    prompt.press("Enter")
    empty = f"No object here matches; I find {NUSCENES.plural_list()}."
    assert "traffic cones and barriers" in empty
    page.get_by_text(empty, exact=True).wait_for(timeout=TIMEOUT * 1000)
    drawn = scene_has("/pred/edges")
    page.wait_for_function(f"() => !({drawn})()", timeout=TIMEOUT * 1000)
    assert session.answer is not None and len(session.answer.predictions.boxes) == 0


@pytest.mark.browser
def test_browser_annotate_offers_the_ten_classes_and_saves_a_traffic_cone(page_and_app) -> None:
    page, app, session = page_and_app
    page.get_by_role("tab", name="Annotate").click()
    panel = next(p for p in app.annotations.panels() if p.session is session)
    poll(lambda: panel.frame is not None, TIMEOUT, "the draft's frame")
    store = app.annotations.store

    # New box class: exactly the ten classes, in the set's order
    page.get_by_label("New box class").click()
    options = page.get_by_role("option")
    options.first.wait_for(timeout=TIMEOUT * 1000)
    assert tuple(options.all_inner_texts()) == NUSCENES.names
    page.get_by_role("option", name="TrafficCone").click()
    poll(lambda: panel.w.cls.value == "TrafficCone", TIMEOUT, "the next class")

    # a ground click places a traffic cone, sized as its class
    ground = panel.frame.ground_z
    camera = session.client.camera
    page.mouse.click(*pixel_of(camera, (12.0, 3.0, ground), PAGE_SIZE))
    poll(lambda: len(panel.draft.boxes) == 1, TIMEOUT, "the traffic cone")
    assert panel.draft.classes == ("TrafficCone",)
    assert panel.draft.boxes[0].box[3:6] == pytest.approx(NUSCENES.get("TrafficCone").mean_size)

    # key 0 toggles Refers to nothing and does not choose the tenth class
    page.keyboard.press("0")
    poll(lambda: panel.draft.refers_to_nothing, TIMEOUT, "key 0")
    page.keyboard.press("0")
    poll(lambda: not panel.draft.refers_to_nothing, TIMEOUT, "key 0 again")
    assert panel.w.cls.value == "TrafficCone", "key 0 chose a class too"
    page.keyboard.press("1")
    poll(lambda: panel.w.cls.value == "Car", TIMEOUT, "key 1")
    page.keyboard.press("9")  # the ninth class; the tenth has no key
    poll(lambda: panel.w.cls.value == "TrafficCone", TIMEOUT, "key 9")

    # Change class: a button per class, each in sight; a relabel there and back
    buttons = _row(page, "Change class").get_by_role("button")
    buttons.first.wait_for(timeout=TIMEOUT * 1000)
    assert tuple(t.strip() for t in buttons.all_inner_texts()) == NUSCENES.names
    assert all(b.is_visible() for b in buttons.all())
    buttons.get_by_text("Barrier", exact=True).click()
    poll(lambda: panel.draft.classes == ("Barrier",), TIMEOUT, "the relabel")
    buttons.get_by_text("TrafficCone", exact=True).click()
    poll(lambda: panel.draft.classes == ("TrafficCone",), TIMEOUT, "the relabel back")

    # the sentence, Enter: saved and read back from disk with its class
    page.keyboard.press("p")
    page.keyboard.type("the traffic cone on the left")
    poll(lambda: panel.draft.prompt.endswith("left"), TIMEOUT, "the sentence")
    page.keyboard.press("Enter")
    poll(lambda: store.pairs(), TIMEOUT, "the save")
    (pair,) = store.pairs()
    assert Talk2RadarRoot(store.path, classes=NUSCENES).load(pair.sample_id).classes == (
        "TrafficCone",
    )
    label = sample_file(store.path / LIDAR_FOLDER, LABEL, pair.sample_id).read_text()
    assert label.split(" ", 1)[0] == "TrafficCone"
