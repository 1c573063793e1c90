"""The referent stage's context features: ranks among candidates and relations to references."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from model.config import ModelConfig, ReferentConfig
from model.referent.context import (
    CONTEXT_FEATURES,
    context_features,
    objectness,
    rank_columns,
    relation_columns,
)
from model.training.loop import widened
from scenes.actors import CLASSES

CAR, PED, CYC = (CLASSES.index(c) for c in ("Car", "Pedestrian", "Cyclist"))


def _box(x: float, y: float, cls: int) -> list[float]:
    size = {CAR: (4.0, 1.8, 1.5), PED: (0.6, 0.6, 1.7), CYC: (1.8, 0.6, 1.7)}[cls]
    return [x, y, size[2] / 2, *size, 0.0]


def _scene(items: list[tuple[float, float, int, float]]):
    boxes = np.array([_box(x, y, c) for x, y, c, _ in items])
    labels = np.array([c for _, _, c, _ in items])
    scores = np.array([s for *_, s in items])
    return boxes, labels, scores


def _rank(feats: np.ndarray, order: str) -> np.ndarray:
    """Index of the strongest bump (0 .. 3) per candidate."""
    return feats[:, rank_columns(order)][:, 1:].argmax(axis=1)


def test_ordinal_ranks_count_the_candidates_of_the_class_before_each():
    boxes, labels, scores = _scene(
        [
            (30.0, 0.0, CAR, 0.9),
            (10.0, 5.0, CAR, 0.9),
            (20.0, -5.0, CAR, 0.9),
            (15.0, 0.0, PED, 0.9),
        ]
    )
    f = context_features(boxes, labels, scores)
    assert f.shape == (4, CONTEXT_FEATURES) and f.dtype == np.float32
    # Cars by depth: 10 m first, 20 m second, 30 m third; the pedestrian is alone in its class.
    assert _rank(f, "nearest").tolist() == [2, 0, 1, 0]
    assert _rank(f, "farthest").tolist() == [0, 2, 1, 0]
    # Left is +y: the car at y = 5 is leftmost, the one at y = -5 rightmost.
    assert _rank(f, "leftmost")[:3].tolist() == [1, 0, 2]
    assert _rank(f, "rightmost")[:3].tolist() == [1, 2, 0]
    # Among all classes the pedestrian at 15 m is the second closest object.
    assert _rank(f, "nearest_all").tolist() == [3, 0, 2, 1]


def test_a_faint_detection_barely_moves_a_rank():
    boxes, labels, scores = _scene([(10.0, 0.0, CAR, 0.05), (20.0, 0.0, CAR, 0.9)])
    f = context_features(boxes, labels, scores)
    assert _rank(f, "nearest").tolist() == [0, 0]
    strong = context_features(boxes, labels, np.array([0.9, 0.9]))
    assert _rank(strong, "nearest").tolist() == [0, 1]


def test_many_faint_detections_do_not_add_up_to_a_rank():
    # Ten faint car peaks (score 0.1) in front of a real car: it is still the nearest car.
    faint = [(5.0 + i, 8.0 - i, CAR, 0.1) for i in range(10)]
    boxes, labels, scores = _scene([*faint, (20.0, 0.0, CAR, 0.8), (30.0, 0.0, CAR, 0.8)])
    f = context_features(boxes, labels, scores)
    assert _rank(f, "nearest")[10:].tolist() == [0, 1]
    assert objectness(np.array([0.05, 0.1, 0.3, 0.6])) == pytest.approx(
        [0.0067, 0.018, 0.5, 0.9975], abs=1e-3
    )


def test_relations_to_the_nearest_car():
    # Nearest car at (10, 0); a farther car at (30, 0); pedestrians at (12, 3) and (29, 2).
    boxes, labels, scores = _scene(
        [(10.0, 0.0, CAR, 0.9), (30.0, 0.0, CAR, 0.9), (12.0, 3.0, PED, 0.9), (29.0, 2.0, PED, 0.9)]
    )
    f = context_features(boxes, labels, scores)
    cols = relation_columns("Car", "nearest")
    block = f[:, cols]
    dx, dy, dist, behind, own, _, bump0, bump1 = block.T
    # The nearest car is the reference: its own weight is ~1, the other car's ~0.
    assert own[0] > 0.99 and own[1] < 0.01 and own[2] == 0.0
    # Offsets point from each candidate to the reference's centre (in tens of metres).
    assert dx[2] == pytest.approx(-0.2, abs=1e-3) and dy[2] == pytest.approx(-0.3, abs=1e-3)
    assert dist[3] == pytest.approx(np.hypot(19.0, 2.0) / 10, abs=1e-3)
    # "the pedestrian closest to the nearest car" ranks 0 among pedestrians, the other 1.
    assert bump0[2] > 0.9 and bump1[3] > 0.9 and bump0[3] < 0.1
    # The far car is behind the nearest one (its near edge beyond the reference's far edge).
    assert behind[1] > 0 and behind[0] < 0


def test_closest_reference_excludes_the_candidate_itself():
    boxes, labels, scores = _scene(
        [(10.0, 0.0, CYC, 0.9), (14.0, 0.0, CYC, 0.9), (40.0, 0.0, CYC, 0.9)]
    )
    f = context_features(boxes, labels, scores)
    dist = f[:, relation_columns("Cyclist", "closest")][:, 2] * 10
    assert dist.tolist() == pytest.approx([4.0, 4.0, 26.0], abs=1e-2)
    # No car in the scene: every relation to a car is zero.
    assert not f[:, relation_columns("Car", "nearest")].any()


def test_mirroring_swaps_left_and_right():
    boxes, labels, scores = _scene(
        [(12.0, 4.0, PED, 0.8), (18.0, -3.0, PED, 0.7), (25.0, 1.0, PED, 0.6), (9.0, 2.0, CAR, 0.9)]
    )
    mirrored = boxes.copy()
    mirrored[:, 1] *= -1
    f = context_features(boxes, labels, scores)
    g = context_features(mirrored, labels, scores)
    np.testing.assert_allclose(f[:, rank_columns("leftmost")], g[:, rank_columns("rightmost")])
    for cls in CLASSES:
        a, b = relation_columns(cls, "leftmost"), relation_columns(cls, "rightmost")
        np.testing.assert_allclose(f[:, a][:, 2:], g[:, b][:, 2:], atol=1e-6)


def test_empty_and_single_candidate():
    assert context_features(np.zeros((0, 7)), np.zeros(0), np.zeros(0)).shape == (
        0,
        CONTEXT_FEATURES,
    )
    one = context_features(*_scene([(10.0, 0.0, CAR, 0.9)]))
    assert np.isfinite(one).all() and _rank(one, "nearest").tolist() == [0]


def test_configs_written_before_the_field_read_as_without_context():
    data = ModelConfig().to_dict()
    assert data["referent"]["context"] is True
    del data["referent"]["context"]
    assert ModelConfig.from_dict(data).referent == ReferentConfig(context=False)


def test_a_grown_input_keeps_the_old_columns_and_zeroes_the_new():
    old = torch.randn(5, 3)
    grown = widened(torch.empty(5, 7), old)
    assert grown is not None and torch.equal(grown[:, :3], old) and not grown[:, 3:].any()
    assert widened(torch.empty(6, 7), old) is None and widened(torch.empty(5, 3), old) is None
    rows = widened(torch.empty(8, 3), old, axis=0)  # a gate whose outputs grew
    assert rows is not None and torch.equal(rows[:5], old) and not rows[5:].any()
    assert (
        widened(torch.empty(8, 3), old) is None and widened(torch.empty(5, 7), old, axis=0) is None
    )


def test_init_from_a_checkpoint_without_context_keeps_its_answers(
    tmp_path, untrained_model, random_scene
):
    from model.checkpoint import save_checkpoint
    from model.training.loop import init_from

    old = untrained_model(
        "referent",
        text_encoder="gru",
        referent__context=False,
        referent__text_gate=False,
        referent__numeric_compare=False,
        referent__subset_ranks=False,
    )
    path = save_checkpoint(tmp_path / "old.pt", old)
    new = untrained_model("referent", seed=1, text_encoder="gru")
    gate = {k for k in new.state_dict() if "geometry_gate" in k}
    assert len(gate) == 2  # its text gate (ReferentConfig.text_gate) is new, and starts at 1
    assert init_from(new, str(path)) == len(new.state_dict()) - len(gate)
    lidar, radar = random_scene()
    with torch.no_grad():
        a = old.ground(old.encode_scene(lidar, radar), "a car")
        b = new.ground(new.encode_scene(lidar, radar), "a car")
    assert len(a.scores) and np.allclose(a.scores, b.scores, atol=1e-6)


def test_the_text_gate_reads_the_sentence_and_older_configs_go_without(
    untrained_model, random_scene
):
    data = ModelConfig().to_dict()
    del data["referent"]["text_gate"]
    assert ModelConfig.from_dict(data).referent == ReferentConfig(text_gate=False)
    model = untrained_model("referent", text_encoder="gru", operating_threshold=0.0)
    stage = model.grounding.stage
    assert stage.geometry_gate is not None and not stage.geometry_gate.weight.any()
    torch.nn.init.normal_(stage.geometry_gate.weight, std=1.0)
    lidar, radar = random_scene()
    with torch.no_grad():
        scene = model.encode_scene(lidar, radar)
        a = model.ground(scene, "a car").scores
        torch.nn.init.zeros_(stage.geometry_gate.weight)
        b = model.ground(scene, "a car").scores
    assert len(a) and not np.allclose(a, b, atol=1e-4)
