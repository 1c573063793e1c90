"""Unit tests of the app's pure parts: colour maps, box segments, IoU, heatmap image, rings, ground
estimate, prompt handling, history, modality inputs, frame store and the engine's feature cache."""

from __future__ import annotations

import time
import types

import numpy as np
import pytest

from app.engine import (
    DaemonWorkers,
    GroundingEngine,
    GroundingModel,
    Predictions,
    initial_threshold,
    model_modalities,
    sensor_inputs,
)
from app.query.answer import results_markdown
from app.query.answer_words import answer_sentence
from app.query.heatmap_view import ground_placement, heatmap_rgba
from app.query.panel import NO_HISTORY, PromptHistory
from app.query.prompt import submitted_prompt
from app.serving.ground_truth import Overlap
from app.serving.navigation import (
    FrameLoadError,
    FrameStore,
    Navigator,
    NoSuchFrameError,
    estimate_ground_z,
    step_index,
)
from app.view.boxes_view import (
    GT_STYLE,
    PRED_STYLE,
    SEGMENTS_PER_BOX,
    best_iou,
    box_label,
    box_segments,
    segment_colors,
)
from app.view.colors import (
    CLASS_COLORS,
    GT_COLOR,
    VELOCITY_STOPS,
    intensity_colors,
    lut_map,
    velocity_colors,
    velocity_legend,
)
from app.view.scene_view import (
    EGO_SIZE,
    bev_pose,
    chase_pose,
    ego_segments,
    ring_segments,
)
from model.checkpoint_meta import CheckpointMeta
from scenes.frame import RootError
from scenes.geometry.classes import NUSCENES
from scenes.talk2radar.layout import VELODYNE, sample_file
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.text_policy import collapse_spaces

# ---------------------------------------------------------------------------- colours


def test_lut_map_ends_midpoints_and_saturation() -> None:
    stops = [(0, 0, 0), (100, 200, 50), (200, 0, 250)]
    out = lut_map(np.array([0.0, 0.25, 0.5, 1.0, -3.0, 7.0, np.nan]), 0.0, 1.0, stops)
    assert out.dtype == np.uint8 and out.shape == (7, 3)
    assert out[0].tolist() == [0, 0, 0]
    assert out[1].tolist() == [50, 100, 25]  # halfway between stops 0 and 1
    assert out[2].tolist() == [100, 200, 50]
    assert out[3].tolist() == [200, 0, 250]
    assert out[4].tolist() == [0, 0, 0]  # below lo saturates
    assert out[5].tolist() == [200, 0, 250]  # above hi saturates
    assert out[6].tolist() == [0, 0, 0]  # NaN -> first stop
    with pytest.raises(ValueError):
        lut_map(np.zeros(2), 1.0, 1.0, stops)


def test_velocity_colors_diverge_blue_approaching_red_receding() -> None:
    out = velocity_colors(np.array([-10.0, 0.0, 10.0, -25.0]), v_max=10.0)
    assert out[0].tolist() == list(VELOCITY_STOPS[0])
    assert out[1].tolist() == list(VELOCITY_STOPS[2])
    assert out[2].tolist() == list(VELOCITY_STOPS[-1])
    assert out[3].tolist() == out[0].tolist()
    blue, red = out[0].astype(int), out[2].astype(int)
    assert blue[2] > blue[0] and red[0] > red[2]
    with pytest.raises(ValueError):
        velocity_colors(np.zeros(1), 0.0)


def test_intensity_colors_use_sqrt_scale() -> None:
    out = intensity_colors(np.array([0.0, 255.0 / 4.0, 255.0]))
    lo, hi = np.array([70, 70, 78]), np.array([255, 255, 255])
    assert out[0].tolist() == lo.tolist() and out[2].tolist() == hi.tolist()
    assert out[1].tolist() == np.round(lo + 0.5 * (hi - lo)).astype(int).tolist()


def test_velocity_legend_is_blue_left_red_right() -> None:
    img = velocity_legend(8.0)
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and img.shape[1] == 320
    left, right = img[12, 10].astype(int), img[12, 309].astype(int)
    assert left[2] > left[0] + 100 and right[0] > right[2] + 100
    assert (img[30:, :, :] > 200).any()  # some light text under the bar


# ---------------------------------------------------------------------------- boxes


def test_box_segments_axis_aligned_box() -> None:
    box = np.array([[1.0, 2.0, 3.0, 4.0, 2.0, 1.5, 0.0]])
    segs = box_segments(box)
    assert segs.shape == (SEGMENTS_PER_BOX, 2, 3) and segs.dtype == np.float32
    lengths = np.sort(np.linalg.norm(segs[:12, 0] - segs[:12, 1], axis=1))
    np.testing.assert_allclose(lengths, [1.5] * 4 + [2.0] * 4 + [4.0] * 4, atol=1e-6)
    np.testing.assert_allclose(np.unique(segs[:12, :, 2]), [2.25, 3.75])
    # Heading tick: top-face centre -> middle of the front (+x) top edge.
    np.testing.assert_allclose(segs[12], [[1.0, 2.0, 3.75], [3.0, 2.0, 3.75]], atol=1e-6)


def test_box_segments_tick_follows_yaw_and_empty_input() -> None:
    box = np.array([[0.0, 0.0, 0.0, 4.0, 2.0, 2.0, np.pi / 2]])
    np.testing.assert_allclose(box_segments(box)[12], [[0, 0, 1], [0, 2, 1]], atol=1e-6)
    assert box_segments(np.zeros((0, 7))).shape == (0, 2, 3)


def test_best_iou_hand_computed() -> None:
    gt = np.array([[10.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0], [30.0, 5.0, 0.0, 4.0, 2.0, 1.5, 0.0]])
    pred = np.array(
        [
            [10.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0],  # identical to gt 0
            [12.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0],  # half overlap: 6 / (12 + 12 - 6)
            [50.0, -9.0, 0.0, 4.0, 2.0, 1.5, 0.0],  # nothing
        ]
    )
    np.testing.assert_allclose(best_iou(pred, gt), [1.0, 1.0 / 3.0, 0.0], atol=1e-9)
    assert np.isnan(best_iou(pred, np.zeros((0, 7)))).all()
    assert best_iou(np.zeros((0, 7)), gt).shape == (0,)


def test_box_label_and_segment_colors() -> None:
    assert box_label("Car", 0.871) == "Car 0.87"
    assert box_label("Car", 0.871, 0.6449) == "Car 0.87 | IoU 0.64"
    assert box_label("Car", 0.871, float("nan")) == "Car 0.87"
    assert box_label("Cyclist") == "GT Cyclist"
    cols = segment_colors(["Car", "Pedestrian"], PRED_STYLE)
    assert cols.shape == (2 * SEGMENTS_PER_BOX, 2, 3)
    assert cols[0, 0].tolist() == list(CLASS_COLORS["Car"])
    assert cols[-1, 1].tolist() == list(CLASS_COLORS["Pedestrian"])
    gt_cols = segment_colors(["Car", "Cyclist"], GT_STYLE)
    assert (gt_cols == np.array(GT_COLOR, np.uint8)).all()


# ---------------------------------------------------------------------------- heatmap


def test_heatmap_rgba_colour_of_best_class_and_alpha() -> None:
    heat = np.zeros((3, 2, 2), np.float32)
    heat[0, 0, 0] = 0.8  # Car
    heat[2, 0, 0] = 0.3
    heat[1, 1, 1] = 0.5  # Pedestrian
    heat[2, 0, 1] = 1.4  # clipped to 1
    rgba = heatmap_rgba(heat, opacity=0.5)
    assert rgba.shape == (2, 2, 4) and rgba.dtype == np.uint8
    assert rgba[0, 0].tolist() == [*CLASS_COLORS["Car"], round(255 * 0.5 * 0.8)]
    assert rgba[1, 1].tolist() == [*CLASS_COLORS["Pedestrian"], round(255 * 0.5 * 0.5)]
    assert rgba[0, 1].tolist() == [*CLASS_COLORS["Cyclist"], round(255 * 0.5)]
    assert rgba[1, 0, 3] == 0  # empty cell: transparent
    with pytest.raises(ValueError):
        heatmap_rgba(np.zeros((2, 2, 2)), 1.0)


def test_ground_placement_centres_the_grid() -> None:
    grid = types.SimpleNamespace(x_min=0.0, x_max=40.0, y_min=-10.0, y_max=10.0)  # a GridExtent
    place = ground_placement(grid, ground_z=-1.7, lift=0.05)
    assert place.position == pytest.approx((20.0, 0.0, -1.65))
    assert (place.render_width, place.render_height) == (40.0, 20.0)


# ---------------------------------------------------------------------------- scene view


def test_ring_segments_radii_and_height() -> None:
    segs = ring_segments(-1.7, step=10.0, max_range=50.0, sides=48)
    assert segs.shape == (5 * 48, 2, 3)
    radii = np.linalg.norm(segs[..., :2], axis=-1)
    np.testing.assert_allclose(np.unique(np.round(radii, 3)), [10, 20, 30, 40, 50])
    np.testing.assert_allclose(segs[..., 2], -1.68, atol=1e-6)


def test_estimate_ground_z() -> None:
    rng = np.random.default_rng(0)
    xy = rng.uniform([4, -15], [28, 15], size=(2000, 2))
    ground = np.c_[xy, rng.normal(-1.7, 0.02, 2000), np.zeros(2000)]
    walls = np.c_[rng.uniform(5, 25, (500, 2)), rng.uniform(-1.5, 3.0, 500), np.zeros(500)]
    assert estimate_ground_z(np.r_[ground, walls]) == pytest.approx(-1.7, abs=0.05)
    assert estimate_ground_z(np.zeros((0, 4))) == pytest.approx(-1.7)
    assert estimate_ground_z(np.zeros((5, 4)), default=-2.0) == -2.0


def test_ego_marker_stands_on_the_ground_and_points_forward() -> None:
    segs = ego_segments(-1.7)
    assert segs.shape == (15, 2, 3)
    l, w, h = EGO_SIZE
    np.testing.assert_allclose([segs[:12, :, 2].min(), segs[:12, :, 2].max()], [-1.7, -1.7 + h])
    np.testing.assert_allclose(np.ptp(segs[:12, :, 0]), l, atol=1e-6)
    np.testing.assert_allclose(np.ptp(segs[:12, :, 1]), w, atol=1e-6)
    shaft = segs[12]
    assert shaft[1, 0] - shaft[0, 0] == pytest.approx(3.0) and shaft[0, 0] == pytest.approx(
        segs[:12, :, 0].max()
    )


def test_camera_presets() -> None:
    bev = bev_pose(-1.7)
    down = np.subtract(bev.look_at, bev.position)
    assert down[2] < -60 and abs(down[0]) <= 1.0 + 1e-9  # nearly straight down, +x up the screen
    chase = chase_pose(-1.7)
    assert chase.position[0] < 0 < chase.look_at[0] and chase.position[2] > chase.look_at[2]


# ---------------------------------------------------------------------------- query panel


def test_submitted_prompt_detects_enter() -> None:
    assert submitted_prompt("the car") is None
    assert submitted_prompt("the car ahead\n") == "the car ahead"
    assert submitted_prompt("\n") == ""
    assert submitted_prompt("two  cyclists\r\nleft") == "two cyclists left"
    assert collapse_spaces("  a \t b  ") == "a b"
    assert submitted_prompt("a\x0bb\n") == "a\x0bb"  # left for the text policy to refuse


def test_prompt_history_order_dedup_cap() -> None:
    h = PromptHistory(size=3)
    assert h.options() == (NO_HISTORY,)
    for p in ["a", "b", "a", "c", "d"]:
        h.add(p)
    assert h.items == ["d", "c", "a"]
    assert h.options() == ("d", "c", "a")


def test_results_markdown_lists_boxes_and_latency() -> None:
    pred = types.SimpleNamespace(
        scores=np.array([0.9, 0.4]), classes=("Car", "Cyclist"), truncated=False
    )
    answer = types.SimpleNamespace(
        predictions=pred,
        cached=True,
        encode_ms=0.0,
        ground_ms=41.0,
        waited_ms=0.0,
        modality="radar",
        score_threshold=0.3,
        prompt="the <b>car</b> and the cyclist",
    )
    overlaps = (Overlap(3, "Car", 0.714, True), None)
    text = results_markdown(answer, overlaps, latency_ms=55.4)
    assert text.startswith(r"1 car and 1 cyclist match\.")  # escaped: shown as text
    assert "**2 boxes** in **55 ms**" in text and "cached" in text and "Radar" in text
    assert r"| 0 | Car | 0.90 | \#3 Car\, IoU 0\.71 \(referent\) |" in text  # as text
    assert "| 1 | Cyclist | 0.40 | none |" in text
    # A frame without labelled objects: no overlap column at all.
    bare = results_markdown(answer, None, latency_ms=55.4)
    assert "| 0 | Car | 0.90 |\n" in bare and "overlaps" not in bare and "IoU" not in bare


def test_the_answer_is_said_in_words() -> None:
    assert answer_sentence("the bus", ()) == (
        "No object here matches; I find cars, pedestrians and cyclists."
    )
    assert answer_sentence("the car", ("Car",)) == "1 car matches."
    both = ("Pedestrian", "Car", "Pedestrian")
    assert answer_sentence("the people and the car", both) == "2 pedestrians and 1 car match."
    assert answer_sentence("How many pedestrians are there?", both[::2]) == (
        "2: 2 pedestrians (boxed)."
    )
    # item 4 (issue 36): the empty answer is worded from the served checkpoint's class set
    assert answer_sentence("the tram", (), known=NUSCENES) == (
        "No object here matches; I find cars, trucks, buses, trailers, construction vehicles, "
        "pedestrians, motorcycles, bicycles, traffic cones and barriers."
    )
    assert answer_sentence("the trucks", ("Truck", "Truck", "TrafficCone"), NUSCENES) == (
        "2 trucks and 1 traffic cone match."
    )


# ---------------------------------------------------------------------------- engine inputs


def test_sensor_inputs_empty_the_other_sensor() -> None:
    sample = types.SimpleNamespace(lidar=np.ones((5, 4)), radar=np.ones((3, 7)))
    lidar, radar = sensor_inputs(sample, "lidar")
    assert lidar.shape == (5, 4) and radar.shape == (0, 7)
    lidar, radar = sensor_inputs(sample, "radar")
    assert lidar.shape == (0, 4) and radar.shape == (3, 7)
    lidar, radar = sensor_inputs(sample, "both")
    assert lidar.shape == (5, 4) and radar.shape == (3, 7) and lidar.dtype == np.float32
    with pytest.raises(ValueError):
        sensor_inputs(sample, "sonar")  # type: ignore[arg-type]


def test_daemon_workers_results_errors_and_shutdown() -> None:
    import threading

    pool = DaemonWorkers(1, "t")
    gate = threading.Event()
    assert pool.submit(lambda a, b: a + b, 2, 3).result(timeout=5) == 5
    with pytest.raises(ZeroDivisionError):
        pool.submit(lambda: 1 / 0).result(timeout=5)
    blocked = pool.submit(gate.wait, 5)
    queued = pool.submit(lambda: "never")
    deadline = time.monotonic() + 5
    while not blocked.running() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert all(t.daemon for t in pool._threads)
    pool.shutdown()
    gate.set()
    assert blocked.result(timeout=5) is True and queued.cancelled()
    with pytest.raises(RuntimeError):
        pool.submit(print)


def test_model_modalities() -> None:
    def fake(modalities: str) -> object:
        return types.SimpleNamespace(cfg=types.SimpleNamespace(modalities=modalities))

    assert model_modalities(fake("both")) == ("both", "lidar", "radar")
    assert model_modalities(fake("lidar")) == ("lidar",)
    assert model_modalities(fake("radar")) == ("radar",)
    assert model_modalities(types.SimpleNamespace()) == ("both", "lidar", "radar")  # no config


def test_initial_threshold_operating_then_the_heads_then_default() -> None:
    head = types.SimpleNamespace(uncalibrated_threshold=0.2)  # the grounding head's own
    uncalibrated = types.SimpleNamespace(cfg=types.SimpleNamespace(), grounding=head)
    calibrated = types.SimpleNamespace(
        cfg=uncalibrated.cfg,
        grounding=head,
        checkpoint_metadata=CheckpointMeta(operating_threshold=0.35),
    )
    assert initial_threshold(calibrated, 0.3) == 0.35
    assert initial_threshold(uncalibrated, 0.3) == 0.2
    assert initial_threshold(types.SimpleNamespace(), 0.3) == 0.3  # a model without a config


# ---------------------------------------------------------------------------- frames + engine


def test_frame_store_and_step(tmp_path, write_tiny_root) -> None:
    root = Talk2RadarRoot(write_tiny_root(tmp_path / "root", frames=3))
    store = FrameStore(root, "test", cache_size=2)
    assert len(store) == 3 and store.ids == ("00000", "00001", "00002")
    frame = store.load(1)
    assert frame.index == 1 and frame.sample_id == "00001"
    assert frame.ground_z == pytest.approx(-1.7, abs=0.05)
    assert store.load(1) is frame  # cached
    with pytest.raises(IndexError):
        store.load(3)
    with pytest.raises(RootError):
        FrameStore(root, "nonexistent")
    write_tiny_root(tmp_path / "root", frames=4)  # one more sample listed in the split
    store.refresh()
    assert len(store) == 4 and store.ids[-1] == "00003"
    assert store.load(1) is frame  # same id at the same position: still cached
    assert [step_index(i, 1, 3) for i in range(3)] == [1, 2, 0]
    assert step_index(0, -1, 3) == 2


def test_engine_caches_scene_features_per_modality(
    tmp_path, write_tiny_root, torch_threads, untrained_model, grounding
) -> None:
    root = Talk2RadarRoot(write_tiny_root(tmp_path / "root", frames=1))
    sample = root.load("00000")
    with torch_threads(1):
        engine = GroundingEngine(untrained_model(grounding, text_encoder="gru"))
        try:
            # A high threshold keeps the untrained model's decoding (NMS) cheap.
            first = engine.answer(sample, "both", "the car ahead", 0.99)
            second = engine.answer(sample, "both", "a pedestrian on the left", 0.99)
            assert engine.encode_calls == 1 and engine.ground_calls == 2
            assert not first.cached and second.cached and second.encode_ms == 0.0
            assert second.prompt == "a pedestrian on the left" and second.sample_id == "00000"
            assert second.predictions.heatmaps.shape[0] == 3
            assert len(second.predictions.boxes) == len(second.predictions.scores)
            engine.answer(sample, "radar", "the car ahead", 0.99)
            assert engine.encode_calls == 2 and engine.cached(sample.sample_id, "radar")
        finally:
            engine.close()
    lidar_only = GroundingEngine(untrained_model(grounding, modalities="lidar", text_encoder="gru"))
    try:
        assert lidar_only.modalities == ("lidar",)
        with pytest.raises(ValueError, match="lidar only"):
            lidar_only.answer(sample, "both", "the car", 0.1)
    finally:
        lidar_only.close()


class _Subscriber:
    def __init__(self) -> None:
        self.shown: list[int] = []
        self.changed = 0

    def frame_shown(self, frame) -> None:
        self.shown.append(frame.index)

    def split_changed(self) -> None:
        self.changed += 1


class _Broken(_Subscriber):
    def frame_shown(self, frame) -> None:
        raise RuntimeError("this browser cannot draw")


def test_navigator_tells_subscribers_and_raises_navigation_errors(
    tmp_path, write_tiny_root
) -> None:
    root = Talk2RadarRoot(write_tiny_root(tmp_path / "root", frames=3))
    moved = []
    nav = Navigator(FrameStore(root, "test"), after_move=moved.append)
    first = nav.load_first()
    assert first.index == 0 and nav.frame is first and not moved
    sub = _Subscriber()
    nav.subscribe(_Broken())  # a failing subscriber does not stop the others
    nav.subscribe(sub)
    assert nav.go_to(2).index == 2 and sub.shown == [2] and [f.index for f in moved] == [2]
    assert nav.go_to(2) is nav.frame and sub.shown == [2]  # the same frame: nothing to tell
    with pytest.raises(NoSuchFrameError, match=r"frames 1\.\.3; 4 does not exist"):
        nav.go_to(3)
    assert nav.step(1).index == 0 and sub.shown == [2, 0]  # wraps around
    velodyne = sample_file(root.lidar_dir, VELODYNE, "00001")
    velodyne.write_bytes(velodyne.read_bytes()[:-3])
    with pytest.raises(FrameLoadError) as caught:
        nav.go_to(1)
    assert caught.value.title == "Could not load frame 2 (00001)"
    assert isinstance(caught.value.cause, RootError | OSError | ValueError)
    assert nav.frame.index == 0 and sub.shown == [2, 0]
    nav.reload()
    assert sub.changed == 1
    nav.unsubscribe(sub)
    nav.go_to(2)
    assert sub.shown == [2, 0] and [f.index for f in moved] == [2, 0, 2]


def test_tpcnet_satisfies_the_app_model_protocol(torch_threads, untrained_model, grounding) -> None:
    with torch_threads(1):
        model = untrained_model(grounding, text_encoder="gru")
        assert model.cfg.grounding == grounding
        assert isinstance(model, GroundingModel)
        features = model.encode_scene(np.zeros((0, 4), np.float32), np.zeros((0, 7), np.float32))
        pred = model.ground(features, "the car ahead", score_threshold=0.99)
    assert isinstance(pred, Predictions)
    assert pred.heatmaps.shape[0] == 3 and pred.boxes.shape[1:] == (7,)
    assert pred.grid.x_min < pred.grid.x_max and pred.grid.y_min < pred.grid.y_max
