"""The camera panel: the overlay drawing (pure parts) and the panel in the running app, driven
through its websocket on a small View-of-Delft-layout root (JPEG images, single-scan radar in its
own frame, no prompt folder)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.view.camera_image import (
    BoxLayer,
    compose,
    display_image,
    lidar_overlay,
    paint_points,
)
from app.view.colors import GT_COLOR, class_color
from app.view.scene_view import camera_view_pose
from scenes.geometry.calib import CAMERA_IN_LIDAR, IMAGE_SIZE, VOD_INTRINSICS, vod_lidar_calibration
from scenes.geometry.projection import project_points
from scenes.talk2radar.layout import IMAGE, LIDAR_FOLDER, RADAR_FOLDERS, sample_file

WHITE = (255, 255, 255)


def _pixel(calib, point) -> tuple[int, int]:
    uv = project_points(np.asarray([point], dtype=np.float64), calib, (10**6, 10**6)).uv[0]
    return int(math.floor(uv[0])), int(math.floor(uv[1]))


# ---------------------------------------------------------------------------- pure parts


def test_display_image_halves_vod_images_and_their_calibration() -> None:
    calib = vod_lidar_calibration()
    image = np.zeros((IMAGE_SIZE[1], IMAGE_SIZE[0], 3), np.uint8)
    image[600:620, 1000:1040] = 255
    shown = display_image(image, calib)
    assert shown.size == (968, 608) and shown.full_size == IMAGE_SIZE
    # A point projects to half its full-size pixel position on the small image.
    point = (20.0, -1.0, 0.5)
    full = project_points(np.array([point]), calib, IMAGE_SIZE).uv[0]
    half = project_points(np.array([point]), shown.calib, shown.size).uv[0]
    np.testing.assert_allclose(half, full / 2.0, atol=1e-9)
    assert shown.image[305, 510].tolist() == [255, 255, 255]  # the white patch, halved
    small = np.zeros((100, 200, 3), np.uint8)
    assert display_image(small, calib).image is small  # never scaled up


def test_compose_draws_box_edges_at_their_projected_pixels() -> None:
    calib = vod_lidar_calibration()
    background = np.zeros((IMAGE_SIZE[1], IMAGE_SIZE[0], 3), np.uint8)
    box = np.array([[12.0, 1.0, -0.95, 4.0, 1.8, 1.5, 0.0]])
    out = compose(background, calib, [BoxLayer(box, (WHITE,), ("Car 0.90",), width=3)])
    # The front bottom-left corner (x + l/2, y + w/2, z - h/2) is on the drawing.
    u, v = _pixel(calib, (14.0, 1.9, -1.7))
    assert out[v - 1 : v + 2, u - 1 : u + 2].max() == 255
    assert background.max() == 0  # the background is not drawn into
    # A box behind the camera draws nothing; an empty layer draws nothing.
    behind = np.array([[-10.0, 0.0, -0.95, 4.0, 1.8, 1.5, 0.0]])
    nothing = compose(
        background, calib, [BoxLayer(behind, (WHITE,), ("x",)), BoxLayer(np.zeros((0, 7)), (), ())]
    )
    assert nothing.max() == 0


def test_box_layer_checks_its_lengths_and_compares_by_content() -> None:
    box = np.zeros((1, 7)) + 1.0
    with pytest.raises(ValueError, match="1 boxes, 2 colours"):
        BoxLayer(box, (WHITE, WHITE), ("",))
    a = BoxLayer(box, (WHITE,), ("a",))
    assert a.same_as(BoxLayer(box.copy(), (WHITE,), ("a",)))
    assert not a.same_as(BoxLayer(box + 1, (WHITE,), ("a",)))
    assert not a.same_as(None)


def test_points_overlay_paints_near_over_far_and_clips_at_the_border() -> None:
    calib = vod_lidar_calibration()
    size = (200, 100)
    image = np.zeros((size[1], size[0], 3), np.uint8)
    uv = np.array([[0, 0], [199, 99], [50, 50], [50, 50]])
    colors = np.array([[1, 1, 1], [2, 2, 2], [3, 3, 3], [4, 4, 4]], np.uint8)
    paint_points(image, uv, colors, 3)
    assert image[0, 0, 0] == 1 and image[99, 199, 0] == 2 and image[50, 50, 0] == 4
    # lidar_overlay returns far points first, so that near ones are painted last.
    lidar = np.array([[40.0, 0.0, 0.0, 1.0], [5.0, 0.0, 0.0, 1.0], [-5.0, 0.0, 0.0, 1.0]])
    points, cols = lidar_overlay(lidar, calib, IMAGE_SIZE)
    assert len(points) == 2  # the point behind the camera is left out
    assert not np.array_equal(cols[0], cols[1])  # coloured by depth


def test_camera_view_pose_is_the_vod_camera() -> None:
    calib = vod_lidar_calibration()
    pose = camera_view_pose(calib, IMAGE_SIZE[1])
    np.testing.assert_allclose(pose.position, CAMERA_IN_LIDAR, atol=1e-9)
    np.testing.assert_allclose(np.subtract(pose.look_at, pose.position), (10.0, 0, 0), atol=1e-9)
    np.testing.assert_allclose(pose.up, (0.0, 0.0, 1.0), atol=1e-9)
    assert pose.fov == pytest.approx(2 * math.atan(IMAGE_SIZE[1] / 2 / VOD_INTRINSICS[1]))
    # Without an image: twice the principal point's row.
    assert camera_view_pose(calib).fov == pytest.approx(
        2 * math.atan(VOD_INTRINSICS[3] / VOD_INTRINSICS[1])
    )


# ---------------------------------------------------------------------------- in the app


@pytest.fixture(scope="module")
def vod_app(tmp_path_factory, write_vod_root, torch_threads, serve_app, untrained_model, grounding):
    """The app on a View-of-Delft root served directly, on each grounding path."""
    root = write_vod_root(tmp_path_factory.mktemp("camera") / "vod", frames=3)
    for tree in (LIDAR_FOLDER, *RADAR_FOLDERS):  # no image (in any tree)
        sample_file(root / tree, IMAGE, "00001").unlink(missing_ok=True)
    sample_file(root / LIDAR_FOLDER, IMAGE, "00002").write_bytes(b"\xff\xd8 broken")
    with torch_threads(1):
        model = untrained_model(
            grounding, text_encoder="gru", head__score_threshold=0.0, operating_threshold=0.0
        )
        with serve_app(root, model, split="val", warm_up=False) as app:
            yield app


def _connect(app, ws_client):
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(lambda: "/scene/lidar" in client.nodes, 15, "the scene")
    session = app.sessions[(set(app.sessions) - before).pop()]
    client.pump_until(lambda: session.camera is not None, 5, "the camera panel")
    return client, session


def _note(session) -> str:
    return session.camera.note.content


def test_camera_panel_shows_the_image_with_gt_and_answers(vod_app, ws_client) -> None:
    app = vod_app
    app.go_to(0)
    client, session = _connect(app, ws_client)
    try:
        camera = session.camera
        client.pump_until(lambda: camera.camera is not None, 5, "the image")
        assert camera.image.visible and "00000\\.jpg · 1936 x 1216" in _note(session)
        assert any(m["type"] == "GuiImageMessage" for m in client.messages)
        picture = camera.render()
        assert picture.shape == (608, 968, 3)
        # The ground truth (every metric object of label_2) is drawn in green.
        gt = camera.layer("gt")
        assert gt is not None and len(gt.boxes) == len(session.sample.boxes) == 4
        car = session.sample.boxes[0]
        corner = (car[0] + car[3] / 2, car[1] - car[4] / 2, car[2] - car[5] / 2)  # yaw ~0.1
        u, v = _pixel(camera.camera.calib, corner)
        patch = picture[v - 3 : v + 4, u - 3 : u + 4].reshape(-1, 3)
        assert (np.abs(patch.astype(int) - GT_COLOR).sum(axis=1) < 60).any()
        # The Query tab's "Ground truth" toggle hides it in the image too.
        client.set("Ground truth", False)
        client.pump_until(lambda: "gt" in camera._hidden, 5, "the GT hidden")
        assert camera.visible_layers() == []
        client.set("Ground truth", True)
        client.pump_until(lambda: "gt" not in camera._hidden, 5, "the GT shown")

        # An answer is drawn in class colours with score labels, and replaced by the next frame.
        draws = camera.draws
        client.set("Prompt", "the car ahead\n")
        client.pump_until(
            lambda: camera.layer("pred") is not None and camera.draws > draws, 30, "the answer"
        )
        pred = camera.layer("pred")
        answer = session.answer.predictions
        k = len(pred.boxes)
        assert 0 < k <= 30 and np.array_equal(pred.boxes, answer.boxes[:k])
        assert pred.colors[0] == class_color(answer.classes[0])
        assert pred.labels[0] == f"{answer.classes[0]} {answer.scores[0]:.2f}"
        assert all(not text for text in pred.labels[10:])  # the best ten are labelled
        assert camera.last_draw_ms > 0

        # The point overlays redraw the image.
        before = camera.render()
        client.set("LiDAR on image", True)
        client.pump_until(lambda: camera._background_key[1], 5, "the LiDAR overlay")
        assert not np.array_equal(camera.render(), before)
        client.set("Radar on image", True)
        client.pump_until(lambda: camera._background_key[2], 5, "the radar overlay")
    finally:
        client.close()


def test_frames_without_or_with_a_broken_image_show_a_note(vod_app, ws_client) -> None:
    app = vod_app
    app.go_to(0)
    client, session = _connect(app, ws_client)
    try:
        app.go_to(1)
        client.pump_until(lambda: session.frame.index == 1, 5, "frame 2")
        assert session.camera.camera is None and not session.camera.image.visible
        assert "No camera image for sample 00001" in _note(session)
        app.go_to(2)
        client.pump_until(lambda: session.frame.index == 2, 5, "frame 3")
        assert session.camera.camera is None
        note = _note(session)
        assert "cannot be shown" in note and "00002" in note and "jpg" in note
        assert "The rest of the frame works" in note
        client.pump_until(
            lambda: "/scene/lidar" in client.nodes and "/gt/edges" in client.nodes,
            5,
            "the rest of the frame",
        )
        assert not any(t == "Camera panel" for t, _ in client.notifications)
    finally:
        app.go_to(0)
        client.close()


def test_camera_viewpoint_preset_and_back(vod_app, ws_client) -> None:
    app = vod_app
    app.go_to(0)
    client, session = _connect(app, ws_client)
    try:
        camera = session.client.camera
        fov = camera.fov
        client.click("Camera", "Camera")
        client.pump_until(
            lambda: np.allclose(camera.position, CAMERA_IN_LIDAR, atol=1e-6), 5, "the camera"
        )
        assert camera.fov == pytest.approx(2 * math.atan(1216 / 2 / VOD_INTRINSICS[1]))
        client.click("Camera", "BEV")
        client.pump_until(lambda: camera.position[2] > 50, 5, "the BEV view")
        assert camera.fov == pytest.approx(fov)  # the browser's field of view is back
    finally:
        client.close()
