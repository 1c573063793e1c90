"""The app on a nuScenes root with Talk2Car commands, driven through its websocket as a browser
would (issue 40.6): the sample's commands listed with their referred boxes, LiDAR and radar
drawn, a typed prompt answered over the detector's proposals and over the labelled boxes, and a
pair annotated there written as a Talk2Car command that ``read_commands`` reads back with the same
box; a pair that does not refer to exactly one labelled annotation is refused in the tab. The
model is the small referent-path TPCNet (GRU text encoder), untrained; the root is the
``nuscenes_root`` fixture's (about 4 s to export)."""

from __future__ import annotations

import numpy as np

from app.text import md_text
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import read_commands
from tests.app.ws.session_helpers import connect_annotating


def _connect(app, ws_client):
    return connect_annotating(
        app, ws_client, ("/scene/lidar", "/scene/radar"), "the scene and the Annotate tab"
    )


def _referable(sample) -> int:
    """A labelled box a pair can hold: ahead, near the middle of the image."""
    for i, box in enumerate(sample.boxes):
        if 8 < box[0] < 40 and abs(box[1]) < 6:
            return i
    raise AssertionError("no referable labelled box")


def test_commands_prompts_and_a_pair_saved_as_a_command(nusc_app, ws_client) -> None:
    app = nusc_app
    root = NuScenesRoot(app.frames.root.path)
    client, session, panel = _connect(app, ws_client)
    try:
        sample = app.frame.sample
        commands = app.frames.root.commands(sample.sample_id)
        assert commands and sample.prompt == commands[0].command.text
        # The frame summary lists the scene and every command with its referred box.
        text = "\n".join(client.markdown.values())
        assert "*Scene* " in text and f"*Commands ({len(commands)}):*" in text
        for c in commands:
            assert md_text(c.command.text) in text
            assert f"**{c.cls}** ({md_text(c.command.category)}) at {c.box[0]:.1f} m ahead" in text
        assert session.camera is not None and sample.image is not None
        assert sample.image.shape == (900, 1600, 3)  # CAM_FRONT

        # A typed prompt over the detector's proposals, then over the labelled boxes.
        client.set("Score threshold", 0.0)
        client.set("Prompt", "stop behind the pedestrian on the left")
        client.click("Run")
        client.pump_until(
            lambda: session.answer is not None and "/heatmap" in client.nodes, 60, "the answer"
        )
        client.set("Candidates", "Labelled boxes")
        client.set("Prompt", "follow the car ahead")
        client.click("Run")
        client.pump_until(
            lambda: session.answer is not None and session.answer.prompt == "follow the car ahead",
            60,
            "the answer over the labelled boxes",
        )
        chosen = np.asarray(session.answer.predictions.boxes).reshape(-1, 7)
        assert len(chosen) > 0
        for box in chosen:  # every box answered is one of the sample's annotations
            assert np.abs(sample.boxes - box[None]).max(axis=1).min() < 1e-4

        # Annotate: a click on a labelled box adds it; two boxes are refused in the tab.
        k = _referable(sample)
        box = sample.boxes[k]
        client.click_ground(box[0], box[1], panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 10, "the labelled box added")
        np.testing.assert_allclose(panel.draft.boxes[0].box, box, atol=1e-9)
        other = next(
            j
            for j, b in enumerate(sample.boxes)
            if j != k and 2 < b[0] < 45 and abs(b[1]) < 15 and np.hypot(*(b[:2] - box[:2])) > 3
        )
        client.click_ground(sample.boxes[other][0], sample.boxes[other][1], panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 2, 10, "a second box")
        client.set("Pair prompt", "park behind the one on the right")
        client.pump_until(
            lambda: "exactly one labelled annotation" in panel.w.checks.content, 10, "the refusal"
        )
        assert panel.w.save.disabled
        client.click_ground(sample.boxes[other][0], sample.boxes[other][1], panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 10, "the second box removed")
        client.pump_until(lambda: not panel.w.save.disabled, 10, "Save enabled")
        client.set("Pair prompt", "park behind the one on the right\n")
        client.pump_until(lambda: "Saved pair" in panel.w.status.content, 20, "the save")
    finally:
        client.close()
    pairs = app.annotations.path / "commands"
    found = read_commands(pairs, "train", root)
    assert not found.skipped and len(found.commands) == 1
    command = found.commands[0]
    assert command.text == "park behind the one on the right"
    assert command.sample_token == sample.sample_id
    assert command.cam_token == root.frame(sample.sample_id).cam_front_token
    np.testing.assert_allclose(found.referent[command.command_token].box, box, atol=1e-6)
    assert found.referent[command.command_token].cls == sample.classes[k]


def test_browser_shows_the_commands_and_the_camera_image(nusc_app, chromium, chromium_args) -> None:
    """Real browser (headless Chromium): the nuScenes root's sample shows its commands in the
    panel, the LiDAR and radar in the scene, and the 1600 x 900 CAM_FRONT image in the camera
    panel; screenshot ``artifacts/nuscenes-browser.png``."""
    from playwright.sync_api import sync_playwright

    from tests.browser_helpers import ARTIFACTS, scene_has
    from tools.camera_shot import CAMERA_IMAGE_WIDTH

    app = nusc_app
    commands = app.frames.root.commands(app.frame.sample.sample_id)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=chromium_args)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 860})
            page.goto(app.url)
            page.wait_for_function(scene_has("/scene/lidar"), timeout=60_000)
            page.wait_for_function(scene_has("/scene/radar"), timeout=10_000)
            for c in commands:
                page.get_by_text(c.command.text, exact=False).first.wait_for(timeout=10_000)
            page.get_by_text(f"Commands ({len(commands)}):").first.wait_for(timeout=10_000)
            page.wait_for_function(f"() => ({CAMERA_IMAGE_WIDTH})() > 400", timeout=20_000)
            # The camera panel's image (the widest) has CAM_FRONT's 16:9 shape, not VoD's.
            width, height = page.evaluate(
                """() => Array.from(document.images)
                    .filter((img) => img.complete && img.naturalWidth > 400)
                    .map((img) => [img.naturalWidth, img.naturalHeight])
                    .sort((a, b) => b[0] - a[0])[0]"""
            )
            assert abs(height / width - 900 / 1600) < 0.01, (width, height)
            page.add_style_tag(content=".mantine-Notifications-root{display:none !important}")
            page.wait_for_timeout(1500)  # SwiftShader renders slowly
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "nuscenes-browser.png"))
        finally:
            browser.close()
