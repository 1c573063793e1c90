"""Ranks by speed and within a side or motion state, and references picked by speed, side or
motion (model.referent.subsets), and the stage reading them."""

from __future__ import annotations

import numpy as np
import torch

from model.referent.candidates import (
    RADAR_EVIDENCE,
    RADAR_MEDIAN_VC,
    SPEED_SCALE,
    geometry_features,
)
from model.referent.compare import COMPARE_FEATURES
from model.referent.stage import geometry_width
from model.referent.subsets import (
    BUMPS,
    PER_PICKED,
    PICKED,
    SUBSET_FEATURES,
    SUBSET_ORDERS,
    side_probabilities,
    subset_features,
)
from scenes.actors import CLASSES
from tests.stage_helpers import answers_without

CAR, PED, CYC = (CLASSES.index(c) for c in ("Car", "Pedestrian", "Cyclist"))


def _batch(rows: list[tuple[float, float, int, float]], score: float = 0.9):
    """One scene of candidates ``(x, y, class, speed m/s)`` (a car-sized box each)."""
    boxes = np.array([[x, y, -1.0, 4.0, 2.0, 1.5, 0.0] for x, y, _, _ in rows])
    labels = np.array([c for _, _, c, _ in rows])
    geometry = torch.from_numpy(geometry_features(boxes, labels, np.full(len(rows), score)))
    radar = torch.zeros(1, len(rows), 4 + RADAR_EVIDENCE)
    radar[0, :, 4 + RADAR_MEDIAN_VC] = torch.tensor([s for *_, s in rows]) / SPEED_SCALE
    return geometry[None], radar, torch.zeros(1, len(rows), dtype=torch.bool)


def _rank(features: torch.Tensor, order: str) -> np.ndarray:
    """The soft rank of ordering ``order`` of each candidate (undoing ``min(r, 6) / 4``)."""
    i = SUBSET_ORDERS.index(order) * (1 + len(BUMPS))
    return 4.0 * features[0, :, i].numpy()


def _picked(features: torch.Tensor, cls: int, pick: str) -> torch.Tensor:
    """``(K, PER_PICKED)``: each candidate's relation to class ``cls``'s ``pick`` reference."""
    start = len(SUBSET_ORDERS) * (1 + len(BUMPS)) + 1
    start += (cls * len(PICKED) + PICKED.index(pick)) * PER_PICKED
    return features[0, :, start : start + PER_PICKED]


def test_speed_ranks_and_ranks_within_a_side_and_a_motion_state() -> None:
    # Three cyclists at 2, 8 and 5 m/s on the left, one parked on the right; a car.
    g, r, pad = _batch(
        [
            (10, 4, CYC, 2.0),
            (20, 5, CYC, 8.0),
            (30, 3, CYC, 5.0),
            (15, -4, CYC, 0.0),
            (12, 0, CAR, 0),
        ]
    )
    f = subset_features(g, r, pad)
    assert f.shape == (1, 5, SUBSET_FEATURES)
    np.testing.assert_allclose(_rank(f, "fastest")[:4], [2, 0, 1, 3], atol=0.05)
    np.testing.assert_allclose(_rank(f, "slowest")[:4], [1, 3, 2, 0], atol=0.05)
    # On the left, by depth: 10, 20, 30 m; the one on the right is first on its side.
    np.testing.assert_allclose(_rank(f, "nearest_same_side")[:4], [0, 1, 2, 0], atol=0.05)
    np.testing.assert_allclose(_rank(f, "farthest_same_side")[:4], [2, 1, 0, 0], atol=0.05)
    # Moving: 10, 20, 30 m; the parked one is alone in its state.
    np.testing.assert_allclose(_rank(f, "nearest_same_motion")[:4], [0, 1, 2, 0], atol=0.05)
    assert _rank(f, "fastest")[4] < 0.05  # the car has no rival of its class
    moving = f[0, :, len(SUBSET_ORDERS) * (1 + len(BUMPS))]
    np.testing.assert_allclose(moving.numpy(), [1, 1, 1, 0, 0], atol=0.01)


def test_picked_references_fastest_parked_and_left() -> None:
    # "the car nearest to the fastest cyclist": the fastest cyclist is at (30, 3).
    g, r, pad = _batch(
        [
            (10, 4, CYC, 2.0),
            (30, 3, CYC, 8.0),
            (12, 2, CAR, 0.0),
            (28, 4, CAR, 6.0),
            (18, -5, CAR, 0),
        ]
    )
    f = subset_features(g, r, pad)
    fastest = _picked(f, CYC, "fastest")
    np.testing.assert_allclose(fastest[:, 4].numpy(), [0, 1, 0, 0, 0], atol=0.01)  # own weight
    np.testing.assert_allclose(10 * fastest[2, :2].numpy(), [18.0, 1.0], atol=0.05)  # dx, dy
    rank = 4 * fastest[:, 5].numpy()  # the car (28, 4) is nearest to it, then (18, -5), (12, 2)
    np.testing.assert_allclose(rank[2:], [2, 0, 1], atol=0.05)
    # The parked cars are (12, 2) and (18, -5): no single one; the car on the right is (18, -5).
    right = _picked(f, CAR, "right")
    np.testing.assert_allclose(right[:, 4].numpy(), [0, 0, 0, 0, 1], atol=0.01)
    moving = _picked(f, CAR, "moving")
    assert moving[3, 4] > 0.99
    # A class with no candidate gives no reference: zeros.
    assert not _picked(f, PED, "fastest").any()


def test_padding_is_no_rival_and_each_row_is_its_own_scene() -> None:
    g, r, pad = _batch([(10, 4, CYC, 2.0), (20, 5, CYC, 8.0), (30, 3, CYC, 5.0)])
    alone = subset_features(g[:, :2], r[:, :2], pad[:, :2])
    padded = subset_features(g, r, torch.tensor([[False, False, True]]))
    torch.testing.assert_close(padded[:, :2], alone)
    assert not padded[0, 2].any()
    other = _batch([(12, -3, CAR, 0.0), (25, 1, PED, 1.0), (40, 6, CYC, 3.0)])
    rows = [torch.cat([a, b, a, a]) for a, b in zip((g, r, pad), other, strict=True)]
    many = subset_features(*rows)
    torch.testing.assert_close(many[0], subset_features(g, r, pad)[0])
    torch.testing.assert_close(many[1], subset_features(*other)[0])
    torch.testing.assert_close(many[3], many[0])


def test_sides_follow_the_ego_corridor() -> None:
    p = side_probabilities(
        torch.tensor([20.0, 20.0, 20.0, 3.0]), torch.tensor([5.0, 0.0, -5.0, 1.4])
    )
    assert p[0, 0] > 0.98 and p[1, 1] > 0.98 and p[2, 2] > 0.98
    assert p[3].max() < 0.7  # beside the bumper, far off the ahead bearing: on no side for sure


def test_the_stage_reads_the_subset_features(untrained_model, random_scene) -> None:
    model = untrained_model("referent", text_encoder="gru", operating_threshold=0.0)
    width = model.grounding.stage.geometry[0].weight.shape[1]
    assert width == geometry_width(model.grounding.stage.cfg) + COMPARE_FEATURES
    columns = slice(width - SUBSET_FEATURES, width)  # they come last
    a, b = answers_without(model, *random_scene(), "the second fastest car", columns)
    assert len(a) and not np.allclose(a, b, atol=1e-4)
