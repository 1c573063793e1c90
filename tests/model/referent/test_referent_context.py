"""The referent stage's context features: ranks among candidates and relations to references."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from model.config import ModelConfig, ReferentConfig
from model.referent.candidates import nearest_depth
from model.referent.context import (
    BUMP_WIDTH,
    BUMPS,
    CONTEXT_FEATURES,
    PER_REFERENCE,
    RANK_TAU,
    REFERENCE_TAU,
    REFERENCES,
    RELATION_SCALE,
    context_features,
    objectness,
    rank_columns,
    relation_columns,
)
from model.training.start import widened
from scenes.geometry.actors import CLASSES

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
    from model.training.start import init_from

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


# ------------------------------------------------------ the compiled pass's reference (NumPy form)


def _ref_sigmoid(z: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * z))


def _ref_rank_code(rank: np.ndarray, bumps: tuple[int, ...]) -> np.ndarray:
    """``(..., 1 + len(bumps))`` of soft ranks ``(...)``: ``min(r, 6) / 4`` and a Gaussian bump
    at each ``n``."""
    cols = [np.minimum(rank, 6.0) / 4.0]
    cols += [np.exp(-((rank - n) ** 2) / (2 * BUMP_WIDTH**2)) for n in bumps]
    return np.stack(cols, axis=-1)


def _ref_softmax_last(logits: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """Softmax of ``logits`` over the last axis, over the ``allowed`` entries only (a row with
    none: all zeros)."""
    z = np.where(allowed, logits, -np.inf)
    top = z.max(axis=-1, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    e = np.where(allowed, np.exp(z - top), 0.0)
    total = e.sum(axis=-1, keepdims=True)
    return np.divide(e, total, out=np.zeros_like(e), where=total > 0)


def _ref_references(
    x: np.ndarray, y: np.ndarray, depth: np.ndarray, labels: np.ndarray, log_w: np.ndarray
) -> np.ndarray:
    """Reference weights ``(C * R, K, K)``: ``[c * R + r, i, j]`` is candidate ``j``'s share in
    class ``c``'s reference ``r`` (:data:`REFERENCES`) as seen from candidate ``i``."""
    k = len(x)
    n_cls, n_ref = len(CLASSES), len(REFERENCES)
    of_c = labels[None, :] == np.arange(n_cls)[:, None]  # (C, K)
    keys = np.stack([-depth, depth, y, -y])  # nearest, farthest, leftmost, rightmost
    logit = keys[None, :, :] / REFERENCE_TAU + log_w  # (C, 4, K)
    extreme = _ref_softmax_last(logit, of_c[:, None, :])  # (C, 4, K): the same from every i
    dist = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    # The c candidate closest to candidate i, itself excluded.
    allowed = of_c[:, None, :] & ~np.eye(k, dtype=bool)[None]
    closest = _ref_softmax_last(
        (-dist / REFERENCE_TAU + log_w[None, :])[None], allowed
    )  # (C, K, K)
    out = np.empty((n_cls, n_ref, k, k))
    out[:, :4] = extreme[:, :, None, :]
    out[:, 4] = closest
    return out.reshape(n_cls * n_ref, k, k)


def _reference_context_features(
    boxes: np.ndarray, labels: np.ndarray, scores: np.ndarray
) -> np.ndarray:
    """The features as their first, NumPy form computed them (whole arrays of candidate pairs):
    what the compiled pass must equal to float rounding."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    k = len(b)
    if k == 0:
        return np.zeros((0, CONTEXT_FEATURES), dtype=np.float32)
    labels = np.asarray(labels, dtype=np.int64).reshape(k)
    w = objectness(np.asarray(scores, dtype=np.float64).reshape(k))
    depth = nearest_depth(b)
    x, y = b[:, 0], b[:, 1]
    others = ~np.eye(k, dtype=bool)
    same = (labels[:, None] == labels[None, :]) & others

    # Ranks: [order, i, j] = w_j sigmoid((key_j - key_i) / tau) over the order's set.
    keys = np.stack([-depth, depth, y, -y, -depth, depth])
    member = np.stack([same] * 4 + [others] * 2)
    step = _ref_sigmoid((keys[:, None, :] - keys[:, :, None]) / RANK_TAU)
    ranks = (step * w * member).sum(axis=2)  # (6, K)
    n_cls = len(CLASSES)
    mass = np.array([w[labels == c].sum() for c in range(n_cls)])
    rank_part = np.concatenate(
        [_ref_rank_code(r, BUMPS) for r in ranks] + [(mass[labels] / 4.0)[:, None]], axis=1
    )

    # Relations, all C * R references at once ([q, i] rows).
    a = _ref_references(x, y, depth, labels, np.log(np.maximum(w, 1e-6)))
    rx, ry, redge = a @ x, a @ y, a @ (2.0 * x - depth)  # (Q, K)
    dx, dy = rx - x, ry - y
    # Each candidate's soft rank by distance to (its own row's) reference among its class:
    # "the pedestrian closest to the nearest car" is the pedestrian ranked 0; the reference
    # itself is no rival (weights 1 - a).
    to_ref = np.hypot(x[None, None, :] - rx[:, :, None], y[None, None, :] - ry[:, :, None])
    diag = np.diagonal(to_ref, axis1=1, axis2=2)  # (Q, K)
    step = _ref_sigmoid((diag[:, :, None] - to_ref) / RANK_TAU)
    rank = (step * (w * (1.0 - a)) * same).sum(axis=2)
    place = np.stack(
        [
            dx / RELATION_SCALE,
            dy / RELATION_SCALE,
            np.hypot(dx, dy) / RELATION_SCALE,
            (depth - redge) / RELATION_SCALE,
            np.diagonal(a, axis1=1, axis2=2),
        ],
        axis=2,
    )
    block = np.concatenate([place, _ref_rank_code(rank, (0, 1))], axis=2)  # (Q, K, PER_REFERENCE)
    block = np.where((a.sum(axis=2) > 0)[..., None], block, 0.0)
    per_class = block.reshape(n_cls, len(REFERENCES), k, PER_REFERENCE).transpose(0, 2, 1, 3)
    per_class = per_class.reshape(n_cls, k, len(REFERENCES) * PER_REFERENCE)
    masses = np.broadcast_to(mass[:, None, None] / 4.0, (n_cls, k, 1))
    relation_part = np.concatenate([per_class, masses], axis=2).transpose(1, 0, 2).reshape(k, -1)
    out = np.concatenate([rank_part, relation_part], axis=1).astype(np.float32)
    assert out.shape == (k, CONTEXT_FEATURES), out.shape
    return out


@pytest.mark.parametrize("seed", range(4))
def test_compiled_context_features_equal_the_numpy_form(seed):
    # Random scenes of 1 to 40 candidates (a class missing in some, near ties in depth and y):
    # the compiled pass equals the NumPy form it replaced, to float rounding.
    rng = np.random.default_rng(seed)
    for k in (1, 2, int(rng.integers(3, 41)), 40):
        boxes = np.column_stack(
            [
                rng.uniform(0, 50, k), rng.uniform(-20, 20, k), rng.uniform(-1, 0, k),
                rng.uniform(0.5, 5, k), rng.uniform(0.5, 2, k), rng.uniform(1, 2, k),
                rng.uniform(-3, 3, k),
            ]
        )  # fmt: skip
        boxes[k // 2 :, 0] = boxes[: k - k // 2, 0] + 1e-3
        labels = rng.integers(0, 3 if seed % 2 else 2, k)
        scores = rng.uniform(0, 1, k)
        got = context_features(boxes, labels, scores)
        want = _reference_context_features(boxes, labels, scores)
        assert got.shape == want.shape == (k, CONTEXT_FEATURES) and got.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)
