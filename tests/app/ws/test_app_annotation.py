"""The Annotate tab, driven through the app's websocket as a browser would (see test_app_ws.py):
ground clicks (``ScenePointerMessage``), gizmo drags (``TransformControls*Message``), typing and
button clicks (``GuiUpdateMessage``); the saved pairs are read back with ``Talk2RadarRoot``.

The model is the small TPCNet with the Bi-GRU text encoder (quick to load), untrained, with a
score threshold of 0 so that "Use predictions" has boxes to use.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from annotate import AnnotationStore, Draft, default_box, proposals
from app.annotate_tab import AnnotationPanel
from app.annotate_tab.formatting import NO_BOX, option_index, option_pair_id, pair_option
from app.annotate_tab.view import box_at, ground_hit, wxyz_to_yaw, yaw_to_wxyz
from scenes.talk2radar.root import Talk2RadarRoot
from tests.browser_helpers import PAGE_SIZE, pixel_of, poll
from tests.paths import REPO

# ---------------------------------------------------------------------- pure helpers


def test_ground_hit_intersects_the_ground_plane() -> None:
    # From (0, 0, 10) towards (12, 3, -1.7): the ray meets z = -1.7 exactly at (12, 3).
    origin = np.array([0.0, 0.0, 10.0])
    direction = np.array([12.0, 3.0, -11.7]) * 0.37  # any length
    x, y = ground_hit(origin, direction, -1.7)
    assert (x, y) == pytest.approx((12.0, 3.0), abs=1e-12)
    assert ground_hit(origin, [1.0, 0.0, 0.2], -1.7) is None  # looking up
    assert ground_hit(origin, [1.0, 0.0, 0.0], -1.7) is None  # parallel to the ground
    assert ground_hit(origin, [100.0, 0.0, -0.1], -1.7) is None  # hits 1170 m away


def test_box_at_prefers_the_nearest_centre() -> None:
    boxes = np.array(
        [
            [10.0, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0],
            [12.0, 0.0, -1.0, 4.0, 2.0, 1.5, math.pi / 2],  # x 11..13, y -2..2
        ]
    )
    assert box_at(boxes, 8.5, 0.5) == 0
    assert box_at(boxes, 11.8, 1.5) == 1  # inside both footprints, nearer box 1's centre
    assert box_at(boxes, 12.0, 2.1) == 1  # within the 0.2 m margin
    assert box_at(boxes, 12.0, 2.3) is None
    assert box_at(np.zeros((0, 7)), 0.0, 0.0) is None


def test_yaw_quaternion_round_trip() -> None:
    for yaw in (0.0, 0.3, -2.0, 3.0):
        assert wxyz_to_yaw(yaw_to_wxyz(yaw)) == pytest.approx(yaw, abs=1e-12)
    # A quaternion for 90 degrees about z: w = z = sqrt(1/2).
    assert wxyz_to_yaw((math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))) == pytest.approx(math.pi / 2)


def test_option_parsing() -> None:
    assert option_index("#3 Car · 12.0 m") == 2
    assert option_index(NO_BOX) is None
    from annotate import PairInfo

    info = PairInfo("00042", 1, ("train",), "the car | ahead", 2, "ada", "t", None)
    assert pair_option(info) == "00042 · 2 boxes · the car | ahead"
    assert option_pair_id(pair_option(info)) == "00042"
    assert option_pair_id("(no saved pairs)") is None


# ---------------------------------------------------------------------- through the websocket


@pytest.fixture(scope="module")
def annotating_app(
    tmp_path_factory, write_tiny_root, torch_threads, serve_app, untrained_model, grounding
):
    """The app on a tiny root, on each grounding path."""
    root = write_tiny_root(tmp_path_factory.mktemp("annotate") / "root")
    with torch_threads(1):
        model = untrained_model(
            grounding, text_encoder="gru", head__score_threshold=0.0, operating_threshold=0.0
        )
        with serve_app(root, model) as app:
            yield app


def _connect(app, ws_client):
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(
        lambda: "/scene/lidar" in client.nodes and "Save pair" in client.gui,
        15,
        "the scene and the Annotate tab",
    )
    session = app.sessions[(set(app.sessions) - before).pop()]
    panel = next(p for p in app.annotations.panels() if p.session is session)
    client.pump_until(lambda: panel.frame is not None, 5, "the draft's frame")
    return client, panel


def _files(root: Path) -> dict[str, tuple[int, int]]:
    out = {}
    for folder, _, names in os.walk(root):
        for name in names:
            path = Path(folder) / name
            if name != ".lock":
                st = path.stat()
                out[str(path.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


def test_place_two_boxes_type_prompt_save_and_find_the_sample(annotating_app, ws_client) -> None:
    app = annotating_app
    client, panel = _connect(app, ws_client)
    try:
        ground = panel.frame.ground_z
        client.click_ground(12.0, 3.0, ground)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "the first box")
        first = panel.draft.boxes[0]
        np.testing.assert_allclose(first.box, default_box("Car", 12.0, 3.0, ground), atol=1e-9)
        assert first.cls == "Car" and panel.selected == first.box_id
        client.pump_until(
            lambda: "/annotate/gizmo/selected/edges" in client.nodes, 5, "the selected box"
        )

        client.set("New box class", "Pedestrian")  # the next box's; the selected car stays
        client.pump_until(lambda: panel.w.cls.value == "Pedestrian", 5, "the class")
        client.click_ground(10.0, -2.0, ground)
        client.pump_until(lambda: len(panel.draft.boxes) == 2, 5, "the second box")
        second = panel.draft.boxes[1]
        assert second.cls == "Pedestrian" and panel.selected == second.box_id
        assert panel.draft.boxes[0].cls == "Car"
        client.pump_until(
            lambda: "/annotate/boxes/edges" in client.nodes, 5, "the unselected box drawn"
        )
        assert client.dropdown("Box")[1:] == ("#1 Car · 12.4 m", "#2 Pedestrian · 10.2 m")

        # Select the car in the list, make it 1.6 m tall (standing on the ground) and turn it.
        client.set("Box", "#1 Car · 12.4 m")
        client.pump_until(lambda: panel.selected == first.box_id, 5, "the car selected")
        client.set("Height (m)", 1.6)
        client.pump_until(lambda: panel.draft.boxes[0].box[5] == 1.6, 5, "the new height")
        assert panel.draft.boxes[0].box[2] - 0.8 == pytest.approx(ground)  # bottom on the ground
        client.set("Yaw (deg)", 30.0)
        client.pump_until(
            lambda: panel.draft.boxes[0].box[6] == pytest.approx(math.radians(30.0)), 5, "yaw"
        )

        prompt = "the car on the left and the pedestrian on the right"
        client.set("Pair prompt", prompt)
        client.set("Split", "test")
        client.set("Annotator", "ada")
        client.pump_until(lambda: panel.w.annotator.value == "ada", 5, "the annotator")
        client.pump_until(lambda: panel.draft.prompt == prompt, 5, "the prompt")
        expected_boxes = panel.draft.box_array
        count = len(app.frames)
        client.click("Save pair")
        client.pump_until(
            lambda: any(t.startswith("Saved pair") for t, _ in client.notifications), 10, "saved"
        )
        title = next(t for t, _ in client.notifications if t.startswith("Saved pair"))
        sid = title.split()[-1]
        assert sid == "00003"  # the tiny root holds 00000..00002

        sample = Talk2RadarRoot(app.frames.root.path).load(sid)
        assert sample.prompt == prompt
        assert sample.classes == ("Car", "Pedestrian")
        np.testing.assert_allclose(sample.boxes, expected_boxes, atol=1e-4)
        client.pump_until(  # the split is re-read after the notification is sent
            lambda: len(app.frames) == count + 1 and sid in app.frames.ids, 10, "the re-read split"
        )
        assert panel.draft == Draft() and not panel.draft.boxes  # a fresh draft
        record = AnnotationStore(app.frames.root.path).history(sid)[-1]
        assert record.annotator == "ada" and record.splits == ("test",)
    finally:
        client.close()

    # A page reload (a new connection) lists the pair.
    again, _ = _connect(app, ws_client)
    try:
        again.pump_until(
            lambda: any(o.startswith(f"{sid} · 2 boxes") for o in again.dropdown("Pair")),
            5,
            "the saved pair in the list",
        )
    finally:
        again.close()


def test_typing_revalidates_without_recounting_points_or_redrawing_boxes(
    annotating_app, ws_client, monkeypatch
) -> None:
    import app.annotate_tab.panel as panel_module

    client, panel = _connect(annotating_app, ws_client)
    try:
        client.click_ground(18.0, -1.0, panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "a box")
        client.pump_until(lambda: "/annotate/gizmo/selected/edges" in client.nodes, 5, "drawn")
        client.drain(0.5)  # every refresh of the placement is done
        counted, drawn, checked = [], [], []
        real_evidence, real_show, real_checks = (
            panel_module.box_evidence,
            panel.view.show,
            panel_module.checks_markdown,
        )
        monkeypatch.setattr(
            panel_module, "box_evidence", lambda *a: counted.append(1) or real_evidence(*a)
        )
        monkeypatch.setattr(panel.view, "show", lambda *a: drawn.append(1) or real_show(*a))
        monkeypatch.setattr(
            panel_module,
            "checks_markdown",
            lambda r, **kw: checked.append(r.ok) or real_checks(r, **kw),
        )
        client.set("Pair prompt", "the car ahead")
        client.pump_until(lambda: checked and checked[-1], 5, "the draft revalidated")
        assert panel.draft.prompt == "the car ahead" and not counted and not drawn
        client.set("Box", NO_BOX)  # a selection: boxes redrawn, evidence re-shown, not recounted
        client.pump_until(lambda: panel.selected is None and drawn, 5, "the box unselected")
        assert not counted and checked == [True]
        client.set("Box", client.dropdown("Box")[1])
        client.pump_until(lambda: panel.selected is not None, 5, "the box selected")
        client.set("Height (m)", 1.9)  # a box edit: the points in it are counted again
        # the recount comes first and the revalidation after it, in the same refresh
        client.pump_until(lambda: counted and len(checked) >= 2, 5, "the evidence recounted")
        assert len(checked) == 2
    finally:
        client.close()


def test_each_app_owns_its_annotation_hub(tmp_path, write_tiny_root) -> None:
    import types

    from app import AppConfig, Talk2PCApp

    root = write_tiny_root(tmp_path / "root", frames=1)
    first = Talk2PCApp(root, types.SimpleNamespace(), AppConfig(port=0, warm_up=False))
    second = Talk2PCApp(root, types.SimpleNamespace(), AppConfig(port=0, warm_up=False))
    try:
        assert first.annotations is not second.annotations
        assert not (root / "annotations").exists()  # nothing written before a tab asks
        assert first.annotations.store is not None and first.annotations.error is None
        assert not (root / "annotations").exists()  # opening it writes nothing either
        assert first.annotations.store is not second.annotations.store
    finally:
        first.stop()
        second.stop()
    assert first.annotations.panels() == []


def test_invalid_save_notifies_and_writes_nothing(annotating_app, ws_client) -> None:
    app = annotating_app
    client, panel = _connect(app, ws_client)
    try:
        client.click_ground(14.0, -4.0, panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "a box")
        before = _files(app.frames.root.path)
        client.click("Save pair")
        client.pump_until(
            lambda: any(t == "Cannot save the pair" for t, _ in client.notifications),
            10,
            "the refusal",
        )
        body = next(b for t, b in client.notifications if t == "Cannot save the pair")
        assert body == "the prompt is empty: type the sentence the boxes answer"
        assert _files(app.frames.root.path) == before
        assert len(panel.draft.boxes) == 1  # the draft is kept for fixing
    finally:
        client.close()


def test_undo_redo_and_one_undo_step_per_gizmo_drag(annotating_app, ws_client) -> None:
    client, panel = _connect(annotating_app, ws_client)
    try:
        ground = panel.frame.ground_z
        client.click_ground(20.0, 1.0, ground)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "a box")
        client.pump_until(lambda: "/annotate/gizmo/selected/edges" in client.nodes, 5, "drawn")
        client.click("Draft", "Undo")
        client.pump_until(lambda: not panel.draft.boxes, 5, "the box undone")
        client.pump_until(
            lambda: "/annotate/gizmo/selected/edges" not in client.nodes, 5, "the box removed"
        )
        client.click("Draft", "Redo")
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "the box redone")
        placed = panel.draft.boxes[0].box
        assert panel.selected == panel.draft.boxes[0].box_id  # redo selects the box it brings
        client.pump_until(lambda: "/annotate/gizmo/selected/edges" in client.nodes, 5, "drawn")

        client.pump_until(lambda: "/annotate/gizmo" in client.owners, 5, "the gizmo")
        z = placed[2]
        drag = [(20.5, 1.5, 0.2), (21.0, 2.0, 0.4), (21.5, 2.5, 0.6)]
        client.drag_gizmo("/annotate/gizmo", [(x, y, yaw_to_wxyz(t)) for x, y, t in drag], z)
        client.pump_until(
            lambda: panel.draft.boxes[0].box[0] == pytest.approx(21.5), 5, "the dragged box"
        )
        moved = panel.draft.boxes[0].box
        assert moved[:3] == pytest.approx((21.5, 2.5, z)) and moved[6] == pytest.approx(0.6)
        assert moved[3:6] == placed[3:6]
        client.click("Draft", "Undo")  # the whole drag is one step
        client.pump_until(lambda: panel.draft.boxes[0].box == placed, 5, "the drag undone")
        client.click("Draft", "Undo")
        client.pump_until(lambda: not panel.draft.boxes, 5, "the placement undone")
    finally:
        client.close()


def test_two_clients_have_separate_drafts(annotating_app, ws_client) -> None:
    a, panel_a = _connect(annotating_app, ws_client)
    b, panel_b = _connect(annotating_app, ws_client)
    try:
        a.click_ground(16.0, -3.0, panel_a.frame.ground_z)
        a.pump_until(lambda: len(panel_a.draft.boxes) == 1, 5, "A's box")
        a.pump_until(lambda: "/annotate/gizmo/selected/edges" in a.nodes, 5, "A's box drawn")
        b.drain(0.5)
        assert not panel_b.draft.boxes
        assert not any(n.startswith("/annotate/gizmo/selected") for n in b.nodes)
        b.click_ground(25.0, 4.0, panel_b.frame.ground_z)
        b.pump_until(lambda: len(panel_b.draft.boxes) == 1, 5, "B's box")
        assert len(panel_a.draft.boxes) == 1
        assert panel_a.draft.boxes[0].box[0] == pytest.approx(16.0)
        assert panel_b.draft.boxes[0].box[0] == pytest.approx(25.0)
    finally:
        a.close()
        b.close()


def test_fit_to_points_and_use_predictions(annotating_app, ws_client, gt_box) -> None:
    app = annotating_app
    client, panel = _connect(app, ws_client)
    try:
        # The frame's car: points filling gt_box's extent shifted by 2 m per frame, axis-aligned
        # (write_tiny_root draws them between the box's min and max corners: yaw 0).
        car = gt_box + np.array([2.0 * app.frame.index, 0, 0, 0, 0, 0, -gt_box[6]])
        client.set("New box class", "Car")
        client.pump_until(lambda: panel.w.cls.value == "Car", 5, "the class")
        client.click_ground(car[0] + 0.1, car[1], panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "a rough box")
        client.click("Fit to points")
        client.pump_until(
            lambda: any(t == "Box fitted" for t, _ in client.notifications), 10, "the fit"
        )
        fitted = np.array(panel.draft.boxes[0].box)
        assert np.hypot(*(fitted[:2] - car[:2])) < 0.15
        np.testing.assert_allclose(fitted[3:5], car[3:5], atol=0.2)
        assert abs(fitted[6]) < 0.03  # the heading of the placed box (0) is kept

        client.set("Prompt", "the car ahead\n")  # the Query tab
        client.pump_until(lambda: panel.session.answer is not None, 30, "an answer")
        client.pump_until(lambda: not panel.w.use_predictions.disabled, 5, "the button enabled")
        pred = panel.session.answer.predictions
        expected = proposals(pred.boxes, pred.classes, panel.draft.box_array)
        client.click("Use predictions")
        client.pump_until(lambda: len(panel.draft.boxes) > 1, 5, "the predicted boxes")
        np.testing.assert_allclose(panel.draft.box_array[1:], expected[0], atol=1e-9)
        assert panel.draft.classes[1:] == expected[1]
        client.click("Draft", "Undo")  # all of them in one step
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "the proposals undone")
    finally:
        client.close()


def test_open_edit_and_delete_a_saved_pair(annotating_app, ws_client) -> None:
    app = annotating_app
    store = app.annotations.store
    client, panel = _connect(app, ws_client)
    try:
        client.click_ground(11.0, 1.0, panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "a box")
        client.set("Pair prompt", "the car right ahead")
        client.pump_until(lambda: panel.draft.prompt == "the car right ahead", 5, "the prompt")
        client.click("Save pair")
        client.pump_until(
            lambda: any(t.startswith("Saved pair") for t, _ in client.notifications), 10, "saved"
        )
        sid = next(t for t, _ in client.notifications if t.startswith("Saved pair")).split()[-1]
        saved = store.open(sid).box_array
        client.pump_until(
            lambda: any(o.startswith(sid) for o in client.dropdown("Pair")), 5, "listed"
        )
        client.set("Pair", next(o for o in client.dropdown("Pair") if o.startswith(sid)))
        client.click("Open pair")
        client.pump_until(lambda: panel.draft.sample_id == sid, 5, "the pair opened")
        np.testing.assert_allclose(panel.draft.box_array, saved)
        client.set("Pair prompt", "the nearest car ahead")
        client.pump_until(lambda: panel.draft.prompt == "the nearest car ahead", 5, "the edit")
        client.click("Save pair")
        client.pump_until(lambda: store.version(sid) == 2, 10, "version 2")
        assert Talk2RadarRoot(app.frames.root.path).load(sid).prompt == "the nearest car ahead"

        client.pump_until(lambda: panel.w.pair.value.startswith(sid), 5, "the pair selected")
        client.click("Delete pair")
        client.pump_until(lambda: "Delete the pair" in client.gui, 5, "the confirmation")
        client.click("Delete the pair")
        client.pump_until(lambda: sid not in [p.sample_id for p in store.pairs()], 10, "deleted")
        client.pump_until(
            lambda: not any(o.startswith(sid) for o in client.dropdown("Pair")), 5, "unlisted"
        )
    finally:
        client.close()


# ---------------------------------------------------------------------- in a real browser


def drive_annotation(
    app,
    chromium: str,
    targets: list[tuple[float, float, bool]],
    screenshot: Path,
    before_screenshot=None,
    timeout_s: float = 40.0,
) -> tuple[float, str]:
    """Make a pair in headless Chromium with the mouse only, as a person would.

    Opens the app, the Annotate tab; for each ``(x, y, fit)`` target clicks the ground there
    (and *Fit to points* when ``fit``); clicks *Suggest*; takes the screenshot; clicks *Save
    pair*; reloads the page and waits until the saved pair is listed in the Annotate tab.

    Returns:
        Seconds from the first click to the saved pair, and the pair's sample id.
    """
    import time

    from playwright.sync_api import sync_playwright

    from tests.browser_helpers import CHROMIUM_ARGS, scene_has

    store = app.annotations.store
    before = {p.sample_id for p in store.pairs()}
    timeout_ms = timeout_s * 1000
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 860})

            def open_tab() -> AnnotationPanel:
                sessions = set(app.sessions)
                page.goto(app.url)
                page.wait_for_function(
                    "() => !document.body.innerText.includes('Connecting...')", timeout=timeout_ms
                )
                page.wait_for_function(scene_has("/scene/lidar"), timeout=timeout_ms)
                page.get_by_role("tab", name="Annotate").click()
                poll(lambda: set(app.sessions) - sessions, timeout_s, "the session")
                session = app.sessions[max(set(app.sessions) - sessions)]
                return next(p for p in app.annotations.panels() if p.session is session)

            panel = open_tab()
            poll(lambda: panel.frame is not None, timeout_s, "the frame")
            start = time.perf_counter()
            for k, (x, y, fit) in enumerate(targets):
                camera = panel.session.client.camera
                page.mouse.click(*pixel_of(camera, (x, y, panel.frame.ground_z), PAGE_SIZE))
                poll(lambda k=k: len(panel.draft.boxes) == k + 1, timeout_s, f"box {k + 1}")
                if fit:
                    placed = panel.draft.boxes[k].box
                    page.get_by_role("button", name="Fit to points").click()
                    poll(lambda k=k, b=placed: panel.draft.boxes[k].box != b, timeout_s, "fit")
            page.get_by_role("button", name="Suggest").click()
            poll(lambda: panel.draft.prompt.strip() != "", timeout_s, "a suggested prompt")
            before_shot = time.perf_counter()
            if before_screenshot is not None:
                before_screenshot(panel)
            page.mouse.move(5, 5)  # no tooltip in the picture
            page.add_style_tag(content=".mantine-Notifications-root{display:none !important}")
            page.wait_for_timeout(2500)  # the scene fades in; SwiftShader renders slowly
            screenshot.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(screenshot))
            shot_s = time.perf_counter() - before_shot
            page.get_by_role("button", name="Save pair").click()
            poll(lambda: {p.sample_id for p in store.pairs()} - before, timeout_s, "the save")
            elapsed = time.perf_counter() - start - shot_s  # the screenshot is not the person's
            (sid,) = {p.sample_id for p in store.pairs()} - before
            open_tab()  # a page reload: the pair is listed
            page.wait_for_function(
                f"() => document.body.innerText.includes({sid!r})", timeout=timeout_ms
            )
            return elapsed, sid
        finally:
            browser.close()


@pytest.mark.browser
@pytest.mark.slow
def test_browser_makes_a_two_box_pair_with_the_mouse(
    tmp_path, chromium, write_tiny_root, torch_threads, gt_box
) -> None:
    from app import AppConfig, Talk2PCApp
    from model import build_model

    root = write_tiny_root(tmp_path / "root", frames=2)
    with torch_threads(1):
        model = build_model("small", text_encoder="gru").eval()
        app = Talk2PCApp(root, model, AppConfig(port=0, warm_up=False)).start()
        try:
            car = gt_box[:2] + np.array([2.0 * app.frame.index, 0.0])
            targets = [(float(car[0]), float(car[1]), True), (25.0, -4.0, False)]
            shot = REPO / "artifacts" / "annotate-browser.png"
            elapsed, sid = drive_annotation(app, chromium, targets, shot)
            sample = Talk2RadarRoot(root).load(sid)
            assert sample.classes == ("Car", "Car") and sample.prompt
            assert np.hypot(*(sample.boxes[0, :2] - car)) < 0.15  # fitted to the car's points
            assert elapsed < 60.0
            assert shot.is_file() and shot.stat().st_size > 10_000
        finally:
            app.stop()


def describable_cars(sample, ground_z: float) -> list:
    """Two cars 10-32 m ahead that *Suggest* can single out with a sentence once their boxes are
    placed by a ground click and *Fit to points*, as the screenshot makes them (else one such
    car): the picture should show a suggested prompt, not the *No suggestion* notice."""
    import itertools

    from annotate.fitting import BoxRegion, FitError, fit_box
    from annotate.suggest import scene_objects, suggest_prompt

    def fitted(actor) -> np.ndarray:
        rough = np.array(default_box("Car", actor.box[0], actor.box[1], ground_z))
        try:
            return np.asarray(fit_box(sample.lidar, BoxRegion(rough), cls="Car").box)
        except FitError:
            return rough

    cars = [a for a in sample.meta.actors if a.cls == "Car" and 10.0 < a.box[0] < 32.0]
    scene = scene_objects(sample)
    for group in [*itertools.combinations(cars, 2), *((c,) for c in cars)]:
        boxes = np.stack([fitted(a) for a in group])
        rng = np.random.default_rng(1)
        if suggest_prompt(boxes, ["Car"] * len(group), scene, sample.radar, rng).text:
            return list(group)
    raise SystemExit(f"frame {sample.sample_id}: no car 10-32 m ahead that a sentence singles out")


def main() -> int:
    """Write ``docs/images/annotate.png``: a two-car pair made with the mouse on the first test
    frame of a copy of the default data (the default data itself is not written to)."""
    import argparse
    import shutil
    import tempfile

    import launch
    from app import AppConfig, Talk2PCApp
    from app.view.scene_view import CameraPose, apply_pose
    from tests.browser_helpers import REPO, find_chromium

    parser = argparse.ArgumentParser(description="Screenshot the Annotate tab for the docs.")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images" / "annotate.png")
    args = parser.parse_args()
    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("no Chromium found")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "default"
        shutil.copytree(launch.ensure_default_data(), root, symlinks=True)
        model, note = launch.load_model(None, "cpu", threads=1)
        config = AppConfig(port=0, split="test", model_note=note)
        app = Talk2PCApp(launch.open_root(root, "test"), model, config).start()
        try:
            app.wait_ready(timeout=120)
            chosen = describable_cars(app.frame.sample, app.frame.ground_z)
            targets = [(float(a.box[0]), float(a.box[1]), True) for a in chosen]
            ground = app.frame.ground_z

            def close_up(panel: AnnotationPanel) -> None:
                middle = np.mean([t[:2] for t in targets], axis=0)
                pose = CameraPose(
                    (float(middle[0]) - 16.0, float(middle[1]) - 9.0, ground + 9.0),
                    (float(middle[0]) + 1.0, float(middle[1]), ground),
                )
                apply_pose(panel.session.client.camera, pose)

            elapsed, sid = drive_annotation(app, chromium, targets, args.out, close_up)
            pair = next(p for p in app.annotations.store.pairs() if p.sample_id == sid)
            print(
                f"{args.out}: pair {sid} {pair.prompt!r} saved {elapsed:.1f} s after the 1st click"
            )
        finally:
            app.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
