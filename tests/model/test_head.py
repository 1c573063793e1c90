"""C3D-RECHead module: configuration, output shapes, initialisation, gradients."""

from __future__ import annotations

import pytest
import torch

from model.config import HeadConfig
from model.head.detector import C3DRecHead, HeadOutput


def test_default_config_matches_contract():
    cfg = HeadConfig()
    assert cfg.anchor == "corner"
    assert (cfg.head_channels, cfg.min_radius, cfg.max_detections) == (64, 2, 50)
    assert (cfg.score_threshold, cfg.nms_iou, cfg.gaussian_overlap) == (0.1, 0.2, 0.1)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"anchor": "centre"},
        {"head_channels": 0},
        {"score_threshold": 1.0},
        {"score_threshold": -0.1},
        {"nms_iou": 0.0},
        {"max_detections": 0},
        {"min_radius": -1},
        {"gaussian_overlap": 0.0},
        {"gaussian_overlap": 1.0},
        {"top_k": 0},
    ],
)
def test_config_rejects_bad_values(kwargs):
    field = next(iter(kwargs))
    with pytest.raises(ValueError, match=field):
        HeadConfig(**kwargs)


def test_output_shapes():
    # The anchor choice (HeadConfig.anchor) is read by targets and decoding, not by the head.
    head = C3DRecHead(HeadConfig(head_channels=16), in_channels=8)
    out = head(torch.randn(2, 8, 12, 10))
    assert isinstance(out, HeadOutput)
    assert out.heatmap.shape == (2, 3, 12, 10)
    assert out.regression.shape == (2, 8, 12, 10)


def test_heatmap_bias_gives_initial_score_about_0_1():
    head = C3DRecHead(HeadConfig(head_channels=8), in_channels=4)
    bias = head.heatmap[-1].bias
    assert torch.allclose(bias, torch.full_like(bias, -2.19))
    assert torch.allclose(torch.sigmoid(bias), torch.full_like(bias, 0.1), atol=1e-3)
    # With the rest of the head zeroed, every cell starts at that score.
    with torch.no_grad():
        head.heatmap[-1].weight.zero_()
    scores = torch.sigmoid(head(torch.randn(1, 4, 5, 5)).heatmap)
    assert torch.allclose(scores, torch.full_like(scores, 0.1), atol=1e-3)


def test_gradients_reach_every_parameter():
    torch.manual_seed(0)
    head = C3DRecHead(HeadConfig(head_channels=8), in_channels=4)
    out = head(torch.randn(2, 4, 9, 9))
    (out.heatmap.square().mean() + out.regression.square().mean()).backward()
    for name, p in head.named_parameters():
        assert p.grad is not None and torch.any(p.grad != 0), name


def test_forward_rejects_wrong_rank():
    head = C3DRecHead(HeadConfig(head_channels=8), in_channels=4)
    with pytest.raises(ValueError, match=r"\(B, C, H, W\)"):
        head(torch.randn(4, 9, 9))


def test_in_channels_must_be_positive():
    with pytest.raises(ValueError, match="in_channels"):
        C3DRecHead(HeadConfig(), in_channels=0)
