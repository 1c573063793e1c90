"""Ranks by speed and within a side or motion state, and references picked by speed, side or
motion (model.referent.subsets), and the stage reading them."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import Tensor

from model.referent.candidates import (
    DEPTH_COLUMN,
    DEPTH_SCALE,
    LATERAL_SCALE,
    RADAR_EVIDENCE,
    RADAR_MEDIAN_VC,
    SPEED_SCALE,
    geometry_features,
)
from model.referent.compare import COMPARE_FEATURES, candidate_speed
from model.referent.context import (
    BUMP_WIDTH,
    OBJECT_SCORE,
    OBJECT_WIDTH,
    RELATION_SCALE,
)
from model.referent.stage import geometry_width
from model.referent.subsets import (
    _SCORE_COLUMN,
    _X_COLUMN,
    _Y_COLUMN,
    BUMPS,
    DEPTH_TAU,
    MOTION_WIDTH,
    PER_PICKED,
    PICK_STATE_TAU,
    PICK_TAU,
    PICKED,
    SIDE_WIDTH,
    SPEED_TAU,
    SUBSET_FEATURES,
    SUBSET_ORDERS,
    subset_features,
)
from scenes.geometry.actors import CLASSES, MOVING_SPEED
from scenes.language.prompts.atoms import AHEAD_MAX_BEARING_DEG, LANE_HALF_WIDTH
from tests.model.referent.stage_helpers import answers_without

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
    # The definition the compiled pass is held to (test_compiled_subset_features_equal_the_torch_form).
    p = _reference_sides(torch.tensor([20.0, 20.0, 20.0, 3.0]), torch.tensor([5.0, 0.0, -5.0, 1.4]))
    assert p[0, 0] > 0.98 and p[1, 1] > 0.98 and p[2, 2] > 0.98
    assert p[3].max() < 0.7  # beside the bumper, far off the ahead bearing: on no side for sure


def test_the_stage_reads_the_subset_features(untrained_model, random_scene) -> None:
    model = untrained_model("referent", text_encoder="gru", operating_threshold=0.0)
    width = model.grounding.stage.geometry[0].weight.shape[1]
    assert width == geometry_width(model.grounding.stage.cfg) + COMPARE_FEATURES
    columns = slice(width - SUBSET_FEATURES, width)  # they come last
    a, b = answers_without(model, *random_scene(), "the second fastest car", columns)
    assert len(a) and not np.allclose(a, b, atol=1e-4)


# ----------------------------------------------------------------- the compiled pass's reference


def _reference_sides(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    left = torch.sigmoid((y - LANE_HALF_WIDTH) / SIDE_WIDTH)
    right = torch.sigmoid((-y - LANE_HALF_WIDTH) / SIDE_WIDTH)
    bearing = torch.rad2deg(torch.atan2(y.abs(), x.clamp(min=1e-3)))
    ahead = (1.0 - left - right).clamp(min=0.0) * torch.sigmoid(AHEAD_MAX_BEARING_DEG - bearing)
    return torch.stack([left, ahead, right], dim=-1)


def _rank_code(rank: torch.Tensor, bumps: tuple[int, ...]) -> torch.Tensor:
    cols = [rank.clamp(max=6.0) / 4.0]
    cols += [torch.exp(-((rank - n) ** 2) / (2 * BUMP_WIDTH**2)) for n in bumps]
    return torch.stack(cols, dim=-1)


def _reference_subset_features(geometry: Tensor, radar: Tensor | None, padding: Tensor) -> Tensor:
    """The features as their first, torch form computed them (float32, batched): what the
    compiled pass must equal to float rounding."""
    n, k = padding.shape
    if k == 0:
        return geometry.new_zeros((n, 0, SUBSET_FEATURES))
    onehot = geometry[..., : len(CLASSES)]
    x = geometry[..., _X_COLUMN] * DEPTH_SCALE
    y = geometry[..., _Y_COLUMN] * LATERAL_SCALE
    depth = geometry[..., DEPTH_COLUMN] * DEPTH_SCALE
    real = (~padding).to(geometry.dtype)
    w = torch.sigmoid((geometry[..., _SCORE_COLUMN].clamp(0, 1) - OBJECT_SCORE) / OBJECT_WIDTH)
    w = w * real  # (N, K)
    speed = candidate_speed(radar, geometry)
    moving = torch.sigmoid((speed - MOVING_SPEED) / MOTION_WIDTH)
    sides = _reference_sides(x, y)  # (N, K, 3)
    eye = torch.eye(k, dtype=torch.bool, device=geometry.device)
    same = (onehot @ onehot.transpose(1, 2)).masked_fill(eye, 0.0)  # (N, K, K)
    rivals = same * w[:, None, :]  # [n, i, j]: j a rival of i
    same_side = sides @ sides.transpose(1, 2)
    same_motion = moving[..., :, None] * moving[..., None, :]
    same_motion = same_motion + (1 - moving)[..., :, None] * (1 - moving)[..., None, :]
    orders = (
        (speed, SPEED_TAU, None),  # a larger key comes first
        (-speed, SPEED_TAU, None),
        (-depth, DEPTH_TAU, same_side),
        (depth, DEPTH_TAU, same_side),
        (-depth, DEPTH_TAU, same_motion),
        (depth, DEPTH_TAU, same_motion),
    )
    ranks = []
    for key, tau, member in orders:
        step = torch.sigmoid((key[:, None, :] - key[:, :, None]) / tau)
        weight = rivals if member is None else rivals * member
        ranks.append(_rank_code((step * weight).sum(-1), BUMPS))
    rank_part = torch.cat([*ranks, moving[..., None]], dim=-1)

    # Picked references: [n, c, p, j] = j's share in class c's reference p.
    keys = torch.stack(
        [speed, -speed, moving, 1 - moving, sides[..., 0], sides[..., 1], sides[..., 2]], dim=1
    )  # (N, P, K), larger = more the reference
    scales = geometry.new_tensor([PICK_TAU] * 2 + [PICK_STATE_TAU] * 5)[None, :, None]
    logit = keys / scales + torch.log(w.clamp(min=1e-6))[:, None, :]
    of_c = (onehot.transpose(1, 2) > 0.5) & ~padding[:, None, :]  # (N, C, K)
    allowed = of_c[:, :, None, :]
    z = logit[:, None, :, :].masked_fill(~allowed, float("-inf"))  # (N, C, P, K)
    any_c = allowed.any(-1, keepdim=True)
    a = torch.softmax(z.masked_fill(~any_c, 0.0), dim=-1) * any_c  # (N, C, P, K)
    rx, ry = (a * x[:, None, None, :]).sum(-1), (a * y[:, None, None, :]).sum(-1)
    redge = (a * (2.0 * x - depth)[:, None, None, :]).sum(-1)  # (N, C, P)
    dx = rx[..., None] - x[:, None, None, :]  # (N, C, P, K): from candidate i
    dy = ry[..., None] - y[:, None, None, :]
    own = a  # candidate i's weight in the reference
    to_ref = torch.hypot(dx, dy)  # (N, C, P, K)
    step = torch.sigmoid((to_ref[..., :, None] - to_ref[..., None, :]) / DEPTH_TAU)  # [.., i, j]
    rival = rivals[:, None, None] * (1.0 - a)[..., None, :]
    rank = (step * rival).sum(-1)
    place = torch.stack(
        [
            dx / RELATION_SCALE,
            dy / RELATION_SCALE,
            to_ref / RELATION_SCALE,
            (depth[:, None, None, :] - redge[..., None]) / RELATION_SCALE,
            own,
        ],
        dim=-1,
    )
    block = torch.cat([place, _rank_code(rank, (0, 1))], dim=-1)  # (N, C, P, K, 8)
    block = block * any_c[..., None]
    picked = block.permute(0, 3, 1, 2, 4).reshape(n, k, -1)
    out = torch.cat([rank_part, picked], dim=-1) * real[..., None]
    return out


@pytest.mark.parametrize("seed", range(4))
def test_compiled_subset_features_equal_the_torch_form(seed):
    # Random scenes (every class, or one missing; moving and still; all sides), a padded batch
    # and a LiDAR-only model's (no radar): the compiled pass equals the torch form it replaced,
    # to the float32 rounding of the latter (a soft rank sums up to 40 float32 terms; a bump's
    # slope multiplies that error by up to ~5).
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 41))
    boxes = np.column_stack(
        [
            rng.uniform(0, 50, k), rng.uniform(-20, 20, k), rng.uniform(-1, 0, k),
            rng.uniform(0.5, 5, k), rng.uniform(0.5, 2, k), rng.uniform(1, 2, k),
            rng.uniform(-3, 3, k),
        ]
    )  # fmt: skip
    labels = rng.integers(0, 3 if seed % 2 else 2, k)
    geometry = torch.from_numpy(geometry_features(boxes, labels, rng.uniform(0, 1, k)))[None]
    radar = torch.from_numpy(rng.normal(0, 0.5, (1, k, 6 + RADAR_EVIDENCE)).astype(np.float32))
    padding = torch.zeros(1, k, dtype=torch.bool)
    for r in (radar, None):
        got = subset_features(geometry, r, padding)
        want = _reference_subset_features(geometry, r, padding)
        assert got.shape == want.shape == (1, k, SUBSET_FEATURES) and got.dtype == want.dtype
        torch.testing.assert_close(got, want, rtol=1e-4, atol=2e-5)
    # Two scenes padded into one batch: each row is its own scene, padding rows are zeros.
    g2 = torch.cat([geometry, torch.roll(geometry, 1, dims=1)])
    r2 = torch.cat([radar, radar])
    pad2 = torch.zeros(2, k, dtype=torch.bool)
    pad2[1, k // 2 :] = True
    got = subset_features(g2, r2, pad2)
    torch.testing.assert_close(got, _reference_subset_features(g2, r2, pad2), rtol=1e-4, atol=2e-5)
    assert not got[1, k // 2 :].any()
