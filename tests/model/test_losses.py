"""The grounding loss (eq. 18): hand-computed values, masking, stability and a short optimisation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from model.config import HeadConfig
from model.core.grid import BevGrid
from model.head.detector import C3DRecHead, HeadOutput
from model.head.losses import focal_heatmap_loss, gather_regression, grounding_loss
from model.head.targets import BatchTargets, collate_targets, draw_targets

GRID = BevGrid(x_min=0.0, x_max=8.0, y_min=-4.0, y_max=4.0, cell=0.5)  # (16, 16)


def _targets(heatmap, indices, regression, mask) -> BatchTargets:
    indices = torch.as_tensor(indices, dtype=torch.int64)
    return BatchTargets(
        heatmap=torch.as_tensor(heatmap, dtype=torch.float32),
        indices=indices,
        anchor_offsets=torch.zeros(*indices.shape, 2),
        regression=torch.as_tensor(regression, dtype=torch.float32),
        mask=torch.as_tensor(mask, dtype=torch.bool),
        labels=torch.zeros_like(indices),
    )


def test_focal_loss_hand_computed():
    # p = 0.5 everywhere. Positive cell: -log(0.5) * 0.5^2. Cell with target 0.5:
    # -log(0.5) * 0.5^2 * (1 - 0.5)^4. Cell with target 0: -log(0.5) * 0.5^2. One positive.
    logits = torch.zeros(1, 1, 1, 3)
    target = torch.tensor([[[[1.0, 0.5, 0.0]]]])
    expected = math.log(2.0) * 0.25 * (1.0 + 1.0 / 16.0 + 1.0)
    assert focal_heatmap_loss(logits, target).item() == pytest.approx(expected, rel=1e-5)
    # Two positives: the sum is divided by 2.
    target2 = torch.tensor([[[[1.0, 1.0, 0.0]]]])
    expected2 = math.log(2.0) * 0.25 * 3.0 / 2.0
    assert focal_heatmap_loss(logits, target2).item() == pytest.approx(expected2, rel=1e-5)


def test_focal_loss_is_finite_for_extreme_logits():
    logits = torch.tensor([[[[100.0, -100.0, 100.0, -100.0]]]], requires_grad=True)
    target = torch.tensor([[[[1.0, 1.0, 0.0, 0.0]]]])
    loss = focal_heatmap_loss(logits, target)
    loss.backward()
    assert torch.isfinite(loss) and torch.all(torch.isfinite(logits.grad))
    # Clamped at 1e-4: the confident wrong cells dominate, the right ones cost (almost) nothing.
    assert loss.item() == pytest.approx(-2 * math.log(1e-4) * (1 - 1e-4) ** 2 / 2, rel=1e-3)


def test_gather_regression_reads_anchor_cells():
    reg = torch.arange(2 * 8 * 3 * 4, dtype=torch.float32).reshape(2, 8, 3, 4)
    idx = torch.tensor([[0, 5], [11, 7]])
    got = gather_regression(reg, idx)
    assert got.shape == (2, 2, 8)
    assert torch.equal(got[0, 1], reg[0, :, 1, 1])
    assert torch.equal(got[1, 0], reg[1, :, 2, 3])


def test_regression_term_hand_computed_and_masked():
    H, W = 2, 2
    heatmap_logits = torch.zeros(1, 3, H, W)
    reg = torch.zeros(1, 8, H, W)
    reg[0, 0, 0, 1] = 2.0  # |error| = 2 on one channel: smooth-L1 = 2 - beta/2
    reg[0, 1, 0, 1] = 0.05  # |error| = 0.05 < beta: 0.5 * 0.05^2 / beta
    reg[0, :, 1, 1] = 100.0  # a masked-out box's cell: must not count
    targets = _targets(torch.zeros(1, 3, H, W), [[1, 3]], torch.zeros(1, 2, 8), [[True, False]])
    beta_sl1 = 1.0 / 9.0
    expected_reg = (2.0 - beta_sl1 / 2) + 0.5 * 0.05**2 / beta_sl1
    terms = grounding_loss(HeadOutput(heatmap_logits, reg), targets, beta=0.25)
    assert terms.regression.item() == pytest.approx(expected_reg, rel=1e-5)
    assert terms.total.item() == pytest.approx(terms.heatmap.item() + 0.25 * expected_reg, rel=1e-5)


def test_regression_averaged_over_valid_boxes():
    reg = torch.zeros(2, 8, 2, 2)
    reg[0, 2, 0, 0] = 1.0
    reg[1, 2, 1, 0] = 3.0
    targets = _targets(torch.zeros(2, 3, 2, 2), [[0], [2]], torch.zeros(2, 1, 8), [[True], [True]])
    terms = grounding_loss(HeadOutput(torch.zeros(2, 3, 2, 2), reg), targets, smooth_l1_beta=1e-9)
    assert terms.regression.item() == pytest.approx((1.0 + 3.0) / 2, rel=1e-5)


def test_zero_boxes_gives_heatmap_loss_only():
    t = draw_targets(np.zeros((0, 7)), [], GRID, HeadConfig())
    batch = collate_targets([t, t])
    out = HeadOutput(
        torch.zeros(2, 3, 16, 16, requires_grad=True), torch.zeros(2, 8, 16, 16, requires_grad=True)
    )
    terms = grounding_loss(out, batch)
    assert torch.isfinite(terms.total)
    assert terms.regression.item() == 0.0
    assert terms.total.item() == pytest.approx(terms.heatmap.item())
    # p = 0.5 on every negative cell, no positive (normaliser 1).
    assert terms.heatmap.item() == pytest.approx(2 * 3 * 256 * math.log(2.0) * 0.25, rel=1e-5)
    terms.total.backward()
    assert torch.all(torch.isfinite(out.heatmap.grad))


def test_shape_mismatch_rejected():
    t = collate_targets([draw_targets(np.zeros((0, 7)), [], GRID, HeadConfig())])
    with pytest.raises(ValueError, match="heatmap"):
        grounding_loss(HeadOutput(torch.zeros(1, 3, 8, 8), torch.zeros(1, 8, 8, 8)), t)


def test_loss_falls_and_gradients_flow_on_a_toy_head():
    torch.manual_seed(0)
    cfg = HeadConfig(head_channels=16)
    head = C3DRecHead(cfg, in_channels=8)
    boxes = np.array([[3.1, 1.2, -1.0, 4.0, 1.8, 1.5, 0.4], [5.3, -2.2, -0.8, 0.7, 0.6, 1.7, -1.0]])
    batch = collate_targets([draw_targets(boxes, ["Car", "Pedestrian"], GRID, cfg)])
    x = torch.randn(1, 8, 16, 16)
    opt = torch.optim.Adam(head.parameters(), lr=1e-2)

    terms = grounding_loss(head(x), batch)
    terms.total.backward()
    for name, p in head.named_parameters():
        assert p.grad is not None and torch.any(p.grad != 0), name
    first, first_reg = terms.total.item(), terms.regression.item()
    opt.step()
    for _ in range(39):
        opt.zero_grad()
        terms = grounding_loss(head(x), batch)
        terms.total.backward()
        opt.step()
    assert terms.total.item() < 0.3 * first
    assert terms.regression.item() < 0.5 * first_reg
