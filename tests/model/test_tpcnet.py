"""TPCNet end to end: shapes for both presets and every option, gradients, the scene/prompt split,
and bad input."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

from model import build_config, build_model
from model.config import ALIASES, ConfigError
from model.core.grid import BevGrid
from model.head.decode import decode
from model.head.detector import HeadOutput
from model.head.losses import grounding_loss
from model.head.targets import collate_targets, draw_targets
from model.nets.text import EmptyPromptError
from model.tpcnet import MissingSensorError, NonFiniteInputError, TPCNet

COARSE = BevGrid(0.0, 51.2, -25.6, 25.6, 1.28)  # 40 x 40 pillars: fast option tests
LONG_PROMPT = " ".join(["the red car parked on the left side of the road near the kerb"] * 6)


def make_scene(seed: int, n_lidar: int = 3000, n_radar: int = 200) -> tuple[np.ndarray, ...]:
    """Random LiDAR ``(N, 4)`` and radar ``(M, 7)`` clouds, some points outside the range."""
    rng = np.random.default_rng(seed)
    lidar = np.column_stack(
        [
            rng.uniform(-5, 60, n_lidar),
            rng.uniform(-30, 30, n_lidar),
            rng.uniform(-3.5, 2.5, n_lidar),
            rng.uniform(0, 255, n_lidar),
        ]
    ).astype(np.float32)
    radar = np.column_stack(
        [
            rng.uniform(0, 51.2, n_radar),
            rng.uniform(-25.6, 25.6, n_radar),
            rng.uniform(-2, 1, n_radar),
            rng.uniform(-20, 20, n_radar),
            rng.uniform(-10, 10, n_radar),
            rng.uniform(-10, 10, n_radar),
            rng.integers(-4, 1, n_radar),
        ]
    ).astype(np.float32)
    return lidar, radar


BOXES = [
    (np.array([[12.0, 3.0, -0.8, 4.2, 1.8, 1.5, 0.3]]), ("Car",)),
    (
        np.array([[20.0, -4.0, -0.9, 0.6, 0.6, 1.7, 1.0], [30, 6, -1, 1.8, 0.7, 1.6, -2.0]]),
        ("Pedestrian", "Cyclist"),
    ),
]


def _batch(model: TPCNet, batch: int = 2) -> tuple[list[Any], list[Any], list[str]]:
    scenes = [make_scene(i) for i in range(batch)]
    lidar = [s[0] for s in scenes] if model.cfg.uses_lidar else None
    radar = [s[1] for s in scenes] if model.cfg.uses_radar else None
    prompts = ["the car about 12 metres ahead", "pedestrians and a cyclist on the right"][:batch]
    return lidar, radar, prompts


def _loss(model: TPCNet, out: HeadOutput) -> torch.Tensor:
    targets = collate_targets(
        [
            draw_targets(b, c, model.head_grid, model.cfg.head)
            for b, c in BOXES[: out.heatmap.shape[0]]
        ]
    )
    return grounding_loss(out, targets).total


def _assert_gradients_reach_every_parameter(model: TPCNet) -> None:
    missing = [n for n, p in model.named_parameters() if p.grad is None]
    assert not missing, f"no gradient for {missing}"
    zero = [n for n, p in model.named_parameters() if not bool(p.grad.abs().sum() > 0)]
    assert not zero, f"zero gradient for {zero}"


def test_small_preset_forward_shapes_and_gradients() -> None:
    torch.manual_seed(0)
    model = build_model("small").train()
    assert all(p.requires_grad for p in model.parameters())
    assert not any("bert" in n or "embeddings" in n for n in model.state_dict())
    out = model(*_batch(model))
    assert out.heatmap.shape == (2, 3, 80, 80) and out.regression.shape == (2, 8, 80, 80)
    assert model.head_grid.shape == (80, 80) and model.head_grid.cell == pytest.approx(0.64)
    _loss(model, out).backward()
    _assert_gradients_reach_every_parameter(model)


OPTIONS: list[dict[str, Any]] = [
    {},
    {"fusion": "bi_mhca"},
    {"fusion": "lidar_query"},
    {"fusion": "radar_query"},
    {"fusion": "conv_gate"},
    {"modalities": "lidar"},
    {"modalities": "radar"},
    {"text_fusion": "ggf"},
    {"anchor": "edge"},
    {"anchor": "center"},
    {"text_encoder": "gru"},
    {"agent_size": (6, 6), "graph_k": (4, 2, 1)},
]


@pytest.mark.parametrize(
    "overrides", OPTIONS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "default"
)
def test_every_option_runs_and_trains(overrides: dict[str, Any]) -> None:
    torch.manual_seed(0)
    model = build_model("small", pillars__grid=COARSE, **overrides).train()
    for key, value in overrides.items():
        node: Any = model.cfg
        for part in ALIASES.get(key, key).split("."):
            node = getattr(node, part)
        assert node == value, key
    out = model(*_batch(model))
    assert out.heatmap.shape == (2, 3, 20, 20) and out.regression.shape == (2, 8, 20, 20)
    _loss(model, out).backward()
    _assert_gradients_reach_every_parameter(model)
    if model.cfg.modalities != "both":
        assert model.scene.fusion is None
        assert (model.scene.lidar is None) == (model.cfg.modalities == "radar")
        assert (model.scene.radar is None) == (model.cfg.modalities == "lidar")


def test_paper_preset_shapes_with_reduced_input() -> None:
    cfg = build_config("paper")
    assert cfg.pillars.grid.shape == (320, 320) and cfg.head_grid.shape == (80, 80)
    model = build_model("paper", pillars__grid=COARSE).eval()
    with torch.no_grad():
        features = model.encode_scene(*make_scene(0))
    widths = [tuple(s.shape) for s in features.stages]
    assert widths == [(1, 64, 20, 20), (1, 128, 10, 10), (1, 256, 5, 5)]
    assert model.scene.neck.out_channels == 384
    pred = model.ground(features, "the car ahead")
    assert pred.heatmaps.shape == (3, 10, 10) and pred.grid == COARSE.downsample(4)


@pytest.mark.slow
def test_paper_preset_full_forward_batch_1() -> None:
    model = build_model("paper").eval()
    with torch.no_grad():
        out = model(*_batch(model, batch=1))
    assert out.heatmap.shape == (1, 3, 80, 80) and out.regression.shape == (1, 8, 80, 80)


def _threshold_in_a_gap(heatmap: np.ndarray, rank: int = 10) -> float:
    """A score threshold near the ``rank``-th highest score that no score lies close to, so that
    float noise between two equal computations cannot move a peak across it."""
    values = np.sort(heatmap.ravel())[::-1]
    for i in range(rank, values.size - 1):
        if values[i] - values[i + 1] > 1e-4:
            return float(values[i] + values[i + 1]) / 2
    return 1.0


@pytest.mark.parametrize("overrides", [{}, {"text_encoder": "gru", "text_fusion": "ggf"}])
def test_encode_scene_and_ground_equal_forward(overrides: dict[str, Any]) -> None:
    torch.manual_seed(0)
    model = build_model("small", head__top_k=50, pillars__grid=COARSE, **overrides)
    lidar, radar, prompts = _batch(model)
    with torch.no_grad():  # move the BatchNorm running statistics away from their init
        model.train()
        model(lidar, radar, prompts)
    model.eval()
    with torch.no_grad():
        out = model(lidar, radar, prompts)
    for b in range(2):
        expected = torch.sigmoid(out.heatmap[b]).numpy()
        threshold = _threshold_in_a_gap(expected)
        detections = decode(out, model.head_grid, model.cfg.head, score_threshold=threshold)
        pred = model.ground(
            model.encode_scene(lidar[b], radar[b]), prompts[b], score_threshold=threshold
        )
        np.testing.assert_allclose(pred.heatmaps, expected, atol=2e-5)
        assert pred.boxes.shape == detections[b].boxes.shape
        np.testing.assert_allclose(pred.boxes, detections[b].boxes, atol=1e-3)
        np.testing.assert_allclose(pred.scores, detections[b].scores, atol=2e-5)
        assert pred.classes == detections[b].classes
        assert pred.boxes.shape[0] > 0 or threshold == 1.0


@pytest.fixture(scope="module")
def small_model() -> TPCNet:
    torch.manual_seed(0)
    # An untrained head scores every cell near 0.1: keep decoding cheap with a small top-K.
    return build_model("small", head__top_k=20).eval()


def test_predictions_content(small_model: TPCNet) -> None:
    features = small_model.encode_scene(*make_scene(3))
    assert features.num_lidar == 3000 and features.num_radar == 200
    assert features.timings.total > 0
    pred = small_model.ground(features, "  the car ahead  ", score_threshold=0.0)
    assert pred.prompt == "the car ahead" and not pred.truncated
    k = pred.boxes.shape[0]
    assert 0 < k <= small_model.cfg.head.max_detections
    assert pred.boxes.shape == (k, 7) and pred.scores.shape == (k,) and len(pred.classes) == k
    assert set(pred.classes) <= {"Car", "Pedestrian", "Cyclist"}
    assert np.all(np.diff(pred.scores) <= 0)
    assert pred.heatmaps.shape == (3, 80, 80) and pred.heatmaps.dtype == np.float32
    assert pred.heatmaps.min() >= 0.0 and pred.heatmaps.max() <= 1.0
    assert pred.grid == small_model.head_grid
    assert min(vars(pred.timings).values()) >= 0.0 and pred.timings.total > 0
    strict = small_model.ground(features, "the car ahead", score_threshold=0.99)
    assert strict.boxes.shape[0] <= k


def test_empty_and_out_of_range_clouds_are_fine(small_model: TPCNet) -> None:
    empty = small_model.encode_scene(np.zeros((0, 4), np.float32), np.zeros((0, 7), np.float32))
    far = np.array([[80.0, 0.0, 0.0, 10.0], [-10.0, 50.0, 0.0, 10.0]], np.float32)
    outside = small_model.encode_scene(far, np.zeros((0, 7), np.float32))
    for feats in (empty, outside):
        pred = small_model.ground(feats, "a cyclist", score_threshold=0.5)
        assert pred.heatmaps.shape == (3, 80, 80)
    torch.testing.assert_close(empty.stages[0], outside.stages[0])


def test_non_finite_points_are_rejected_before_the_network(small_model: TPCNet) -> None:
    lidar, radar = make_scene(0)
    bad = lidar.copy()
    bad[17, 1] = np.nan
    called = []
    hook = small_model.scene.lidar.pillars.register_forward_pre_hook(lambda *a: called.append(1))
    try:
        with pytest.raises(NonFiniteInputError, match=r"LiDAR cloud 0.*row 17"):
            small_model.encode_scene(bad, radar)
        bad_radar = radar.copy()
        bad_radar[3, 4] = np.inf
        with pytest.raises(NonFiniteInputError, match=r"radar cloud 1.*row 3"):
            small_model([lidar, lidar], [radar, bad_radar], ["a car", "a car"])
    finally:
        hook.remove()
    assert not called


def test_huge_finite_points_are_accepted() -> None:
    # The finiteness check sums the cloud first; a sum that overflows is looked at row by row.
    from model.tpcnet import as_points

    huge = np.full((4, 4), 3e38, np.float32)
    assert as_points(huge, 4, "LiDAR cloud 0").shape == (4, 4)
    huge[2, 3] = -np.inf
    with pytest.raises(NonFiniteInputError, match="row 2"):
        as_points(huge, 4, "LiDAR cloud 0")


def test_wrong_shapes_and_missing_sensors() -> None:
    torch.manual_seed(0)
    lidar, radar = make_scene(0)
    model = build_model("small", pillars__grid=COARSE).eval()
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        model.encode_scene(lidar[:, :3], radar)
    with pytest.raises(MissingSensorError, match="LiDAR"):
        model.encode_scene(None, radar)
    lidar_only = build_model("small", modalities="lidar", pillars__grid=COARSE).eval()
    with pytest.raises(MissingSensorError, match=r"modalities='lidar'.*LiDAR"):
        lidar_only.encode_scene(radar=radar)
    # The unused sensor is ignored, even when it holds garbage.
    garbage = np.full((5, 7), np.nan, np.float32)
    a = lidar_only.encode_scene(lidar, garbage)
    b = lidar_only.encode_scene(lidar, None)
    torch.testing.assert_close(a.stages[2], b.stages[2])
    radar_only = build_model("small", modalities="radar", pillars__grid=COARSE).eval()
    pred = radar_only.ground(radar_only.encode_scene(radar=radar), "a car", score_threshold=0.5)
    assert pred.heatmaps.shape == (3, 20, 20)
    with pytest.raises(ValueError, match="do not come from this model"):
        other = build_model("small", pillars__grid=COARSE, backbone__channels=(16, 24, 32))
        model.ground(other.encode_scene(lidar, radar), "a car")


def test_prompt_errors_and_truncation(small_model: TPCNet) -> None:
    features = small_model.encode_scene(*make_scene(1))
    for prompt in ("", "   "):
        with pytest.raises(EmptyPromptError):
            small_model.ground(features, prompt)
    lidar, radar = make_scene(1)
    with pytest.raises(EmptyPromptError):
        small_model([lidar], [radar], [" \t"])
    pred = small_model.ground(features, LONG_PROMPT, score_threshold=0.5)
    assert pred.truncated


def test_build_model_rejects_unknown_overrides() -> None:
    with pytest.raises(ConfigError, match="unknown override 'fusoin'"):
        build_model("small", fusoin="baca")
    with pytest.raises(ConfigError, match="unknown preset"):
        build_model("huge")
    with pytest.raises(ConfigError, match=r"fusion\.kind"):
        build_model("small", fusion="concat")
