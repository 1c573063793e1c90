"""Issue 20's inference-only fast paths equal the forms they replace: MiniLM's prepacked oneDNN
weights (bit for bit), the head's folded BatchNorms and per-tap last convs (to float rounding),
and the referent head's memory of the last scene's text-free embeddings (the same logits, and
forgotten when the weights or the scene change)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from model.config import HeadConfig
from model.head.detector import C3DRecHead, conv3x3_by_taps
from model.nets import onednn
from model.nets.text import MiniLMForward, load_minilm_forward, tokenize


def _plain_copy(forward: MiniLMForward) -> MiniLMForward:
    """``forward`` with its layers' prepacked weights dropped (the plain oneDNN path)."""
    plain = MiniLMForward.__new__(MiniLMForward)
    plain.__dict__.update(forward.__dict__)
    plain.layers = []
    for layer in forward.layers:
        parts = []
        for part in layer:
            if isinstance(part, onednn.FrozenLinear):
                part = onednn.FrozenLinear.__new__(onednn.FrozenLinear)
                part.__dict__.update(layer[len(parts)].__dict__, packed=None)
            parts.append(part)
        plain.layers.append(tuple(parts))
    return plain


@pytest.mark.skipif(onednn._ONEDNN_LINEAR is None, reason="no oneDNN in this torch build")
def test_minilm_prepacked_weights_give_the_same_features_bit_for_bit():
    forward = load_minilm_forward()
    dense = [p for layer in forward.layers for p in layer if isinstance(p, onednn.FrozenLinear)]
    assert dense and all(d.packed is not None for d in dense)
    plain = _plain_copy(forward)
    assert all(p.packed is None for layer in plain.layers for p in layer[:2])
    prompts = ("the car", "two cyclists on the right, moving away from us at twenty km/h")
    ids = [tokenize(p, 30)[0] for p in prompts]
    for seq in ids:
        one = torch.tensor([seq])
        assert torch.equal(forward(one), plain(one))
    batch = torch.zeros(2, len(ids[1]), dtype=torch.long)
    valid = torch.zeros(2, len(ids[1]), dtype=torch.bool)
    for b, seq in enumerate(ids):
        batch[b, : len(seq)] = torch.tensor(seq)
        valid[b, : len(seq)] = True
    assert torch.equal(forward(batch, valid), plain(batch, valid))


def test_dense_layer_takes_the_plain_weight_for_one_row_and_other_dtypes():
    torch.manual_seed(0)
    weight, bias = torch.randn(24, 16), torch.randn(24)
    dense = onednn.FrozenLinear(weight, bias)
    with torch.inference_mode():
        for x in (torch.randn(1, 16), torch.randn(1, 5, 16), torch.randn(3, 16)):
            torch.testing.assert_close(dense(x), F.linear(x, weight, bias), rtol=1e-5, atol=1e-5)
            torch.testing.assert_close(
                dense(x, gelu=True), F.gelu(F.linear(x, weight, bias)), rtol=1e-5, atol=1e-5
            )
        x64 = torch.randn(4, 16, dtype=torch.float64)
        want = F.linear(x64, weight.double(), bias.double())
        got = onednn.FrozenLinear(weight.double(), bias.double())(x64)
        torch.testing.assert_close(got, want)


@pytest.mark.parametrize("channels_last", [False, True])
@pytest.mark.parametrize("out_channels", [1, 3])
def test_conv3x3_by_taps_equals_the_convolution(channels_last, out_channels):
    torch.manual_seed(out_channels)
    full = torch.randn(1, 12, 9, 7)
    if channels_last:
        full = full.contiguous(memory_format=torch.channels_last)
    x = full[0, 4:10]  # a channel slice: contiguous, or strided in a channels-last map
    assert x.is_contiguous() is not channels_last
    weight, bias = torch.randn(out_channels, 6, 3, 3), torch.randn(out_channels)
    out = torch.empty(out_channels, 9, 7)
    got = conv3x3_by_taps(x, weight, bias, out)
    assert got is out
    want = F.conv2d(x[None], weight, bias, padding=1)[0]
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    no_bias = conv3x3_by_taps(x, weight, None, torch.empty(out_channels, 9, 7))
    torch.testing.assert_close(no_bias, want - bias.view(-1, 1, 1), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("batch", [1, 2])
def test_head_inference_form_equals_the_module_form(batch):
    torch.manual_seed(batch)
    head = C3DRecHead(HeadConfig(head_channels=8), in_channels=6)
    # Running statistics and affine parameters away from their defaults, so that folding the
    # BatchNorms into the convs is exercised.
    with torch.no_grad():
        for module in head.modules():
            if isinstance(module, torch.nn.BatchNorm2d):
                module.running_mean.normal_()
                module.running_var.uniform_(0.5, 2.0)
                module.weight.normal_()
                module.bias.normal_()
    head.eval()
    x = torch.randn(batch, 6, 11, 10)
    with torch.enable_grad():  # the module form (the training path)
        want = head(x)
    with torch.no_grad():
        got = head(x)
    for name in ("heatmap", "regression"):
        g, w = getattr(got, name), getattr(want, name)
        assert g.shape == w.shape and g.is_contiguous()
        torch.testing.assert_close(g, w.detach(), rtol=1e-5, atol=1e-5)


def test_referent_head_remembers_the_last_scene_only_while_it_is_the_same(
    untrained_model, random_scene
):
    model = untrained_model("referent")
    head = model.grounding
    features = model.encode_scene(*random_scene())
    assert features.objects is not None and len(features.objects) > 0
    text = model.text_encoder(["the nearest car"])

    def fresh() -> torch.Tensor:  # no memory: the scene's batch and embeddings computed anew
        head._kept_scene = None
        with torch.no_grad():
            return head.refer(features.objects, text)

    with torch.no_grad():
        want = fresh()
        kept = head._kept_scene
        assert kept is not None and kept[0]() is features.objects
        again = head.refer(features.objects, text)
        assert head._kept_scene is kept  # served from memory
        assert torch.equal(again, want)
        with torch.enable_grad():  # the module form, which never uses the memory
            module_form = head.refer(features.objects, text).detach()
        np.testing.assert_allclose(again.numpy(), module_form.numpy(), rtol=0, atol=1e-5)
        # New weights (an optimiser step, load_state_dict: in place): computed again.
        head.stage.fused[0].weight.mul_(1.5)
        changed = head.refer(features.objects, text)
        assert head._kept_scene is not kept
        assert not torch.equal(changed, want)
        assert torch.equal(changed, fresh())
        # Another scene object: computed again.
        other = model.encode_scene(*random_scene())
        head.refer(other.objects, text)
        assert head._kept_scene[0]() is other.objects


def test_ground_draws_on_the_scene_canvas_kept_from_the_last_prompt(untrained_model, random_scene):
    from model.referent.heatmap import referent_heatmap

    model = untrained_model("referent")
    head = model.grounding
    features = model.encode_scene(*random_scene())
    objects = features.objects
    assert objects is not None and len(objects) > 0
    first = model.ground(features, "the nearest car", score_threshold=0.0, ranked=True)
    kept = head._kept_canvas
    assert kept is not None and kept[0]() is objects
    second = model.ground(
        features, "the two pedestrians on the left", score_threshold=0.0, ranked=True
    )
    assert head._kept_canvas is kept  # the same scene: the same canvas
    assert len(first.scores) == len(second.scores) == len(objects)  # (all, at threshold 0)
    # What each answer drew equals the heatmap function on that prompt's probabilities.
    with torch.no_grad():
        probs = torch.sigmoid(head.refer(objects, model.text_encoder(["the nearest car"]))[0])
    want = referent_heatmap(
        features.detection_heatmaps,
        objects.boxes,
        objects.labels,
        probs.numpy().astype(np.float64),
        model.head_grid,
        model.cfg.head.anchor,
    )
    assert first.heatmaps.tobytes() == want.tobytes()
    other = model.encode_scene(*random_scene())
    model.ground(other, "the nearest car")
    assert head._kept_canvas[0]() is other.objects


def test_baca_blocked_attention_equals_the_unblocked_one(monkeypatch):
    from model.nets.fusion import baca, baca_cpu

    torch.manual_seed(0)
    attention = baca.AgentCrossAttention(16, (5, 7), heads=1).eval()
    q, k, v = torch.randn(1, 16, 30, 40), torch.randn(1, 16, 1200), torch.randn(1, 16, 1200)
    with torch.no_grad():
        monkeypatch.setattr(baca_cpu, "BLOCK_SCORES", 1 << 30)  # nothing blocked
        whole = attention.attend(q, k, v)
        monkeypatch.setattr(baca_cpu, "BLOCK_SCORES", 12000)  # uneven blocks: 10 agents, 342 cells
        assert baca_cpu.blocked(q.reshape(1, 16, -1), torch.zeros(1, 16, 35))
        blocked = attention.attend(q, k, v)
    torch.testing.assert_close(blocked, whole, rtol=0, atol=1e-6)
    with torch.enable_grad():  # the module form (training) is never blocked
        assert not baca_cpu.blocked(q.reshape(1, 16, -1), torch.zeros(1, 16, 35))
        np.testing.assert_allclose(
            attention.attend(q, k, v).detach().numpy(), whole.numpy(), rtol=0, atol=1e-5
        )


@pytest.mark.parametrize("shape", [(16, 30, 40), (24, 9, 11)])
@pytest.mark.parametrize("block", [1 << 18, 12000])
def test_one_head_baca_with_folded_projections_equals_the_module_form(monkeypatch, shape, block):
    # CPU inference folds one-head BACA's projections into its agents (model.nets.fusion.baca_cpu:
    # the softmax drops the keys' bias term, a softmax row sums to 1, the output bias goes to
    # the merge); with gradients on the module form runs every projection. Random biases and
    # BatchNorm statistics, so that every folded term matters; blocked and whole.
    from model.nets.fusion import baca, baca_cpu

    monkeypatch.setattr(baca_cpu, "BLOCK_SCORES", block)
    torch.manual_seed(1)
    c, h, w = shape
    fusion = baca.BidirectionalAgentCrossAttention(c, (5, 7), heads=1).eval()
    with torch.no_grad():
        for module in fusion.modules():
            if isinstance(module, torch.nn.Linear):
                module.bias.normal_(0.0, 0.5)
        fusion.merge[1].running_mean.normal_(0.0, 0.5)
        fusion.merge[1].running_var.uniform_(0.5, 2.0)
    f_l, f_r = torch.randn(1, c, h, w), torch.randn(1, c, h, w)
    with torch.no_grad():
        got = fusion(f_l, f_r)
    with torch.enable_grad():
        want = fusion(f_l, f_r).detach()
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    four = baca.BidirectionalAgentCrossAttention(c, (5, 7), heads=4).eval()
    with torch.no_grad():  # (several heads keep their projections: the plain inference form)
        got = four(f_l, f_r)
    torch.testing.assert_close(got, four(f_l, f_r).detach(), rtol=1e-5, atol=1e-5)


def _cloud_with_edges(seed: int, features: int) -> np.ndarray:
    """Points inside and outside the small preset's grid and z range, on its far edges (rounding
    puts some just below x_max into the next column), and 80 in one pillar (more than either
    sensor keeps), in random order."""
    rng = np.random.default_rng(seed)
    n = 4000
    pts = np.c_[
        rng.uniform([-5, -30, -4], [56, 30, 3], (n, 3)), rng.normal(0, 20, (n, features - 3))
    ]
    pts[:50, 0] = np.nextafter(np.float32(51.2), np.float32(0))  # just below x_max
    pts[50:100, 1] = np.float32(-25.6)  # exactly on y_min
    pts[100:180, :3] = rng.uniform([10.0, 1.0, -1.0], [10.3, 1.3, 0.5], (80, 3))  # one pillar
    return pts[rng.permutation(n)].astype(np.float32)


@pytest.mark.parametrize("sensor", ["lidar", "radar"])
def test_compiled_pillar_pass_equals_the_array_form(untrained_model, sensor):
    # One cloud at inference runs model.nets.pillar_kernel; with gradients on, the same encoder
    # runs its array form (voxelize, the pillars' max of the factorised map). Random BatchNorm
    # statistics and signs, so that the sign flip and the folded normalisation both matter.
    model = untrained_model("referent")
    encoder = getattr(model.scene, sensor).pillars
    gen = torch.Generator().manual_seed(3)
    with torch.no_grad():
        encoder.norm.weight.copy_(torch.randn(encoder.out_channels, generator=gen))
        encoder.norm.running_mean.copy_(torch.randn(encoder.out_channels, generator=gen))
        encoder.norm.running_var.copy_(torch.rand(encoder.out_channels, generator=gen) + 0.5)
    for seed in range(3):
        cloud = torch.from_numpy(_cloud_with_edges(seed, encoder.num_features))
        with torch.no_grad():
            got = encoder([cloud])
        with torch.enable_grad():
            want = encoder([cloud]).detach()
        assert got.shape == want.shape == (1, encoder.out_channels, *encoder.grid.shape)
        torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)
    with torch.no_grad():  # nothing in range: an all-zero canvas
        assert not encoder([torch.zeros(0, encoder.num_features)]).any()
        far = torch.full((5, encoder.num_features), 500.0)
        assert not encoder([far]).any()
