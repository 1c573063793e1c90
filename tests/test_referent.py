"""The referent path: numerals, candidate evidence, the referent stage, its training step and the
model's encode_scene / ground in ``grounding="referent"`` mode."""

from pathlib import Path

import numpy as np
import pytest
import torch

from model import build_model
from model.candidates import (
    geometry_features,
    lidar_evidence,
    nearest_depth,
    pool_bev,
    radar_evidence,
)
from model.config import ReferentConfig
from model.grid import BevGrid
from model.numerals import number_spans, token_numeric_features
from model.referent import CandidateBatch, ReferentStage, referent_loss
from model.referent_train import ReferentTrainConfig, referent_step
from model.text import tokenize_with_numbers
from scenes.actors import Actor
from scenes.frame_dataset import FrameDataset, flip_actor, scene_ids
from scenes.root import Talk2RadarRoot
from scenes.synth import SynthSettings, generate_root


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("referent") / "root"
    generate_root(root, 8, SynthSettings(seed=11), split_fractions=(0.5, 0.25, 0.25))
    return root


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("the car beyond 40 m", [("40", 40.0)]),
        ("about twenty five metres ahead", [("twenty five", 25.0)]),
        ("at two and a half m/s", [("two and a half", 2.5)]),
        ("10m away at 20km/h", [("10", 10.0), ("20", 20.0)]),
        ("twenty-five kph", [("twenty-five", 25.0)]),
        ("one hundred and five", [("one hundred and five", 105.0)]),
        ("a car and a bike", []),
        ("2,5 m/s", [("2,5", 2.5)]),
        ("two point five metres per second", [("two point five", 2.5)]),
        ("zero point five", [("zero point five", 0.5)]),
    ],
)
def test_number_spans(text, expected):
    assert [(text[a:b], v) for a, b, v in number_spans(text)] == expected


def test_numeric_features_follow_the_tokens():
    ids, numbers, truncated = tokenize_with_numbers("the car beyond forty metres", 30)
    assert not truncated and numbers.shape == (len(ids), 4)
    flagged = np.flatnonzero(numbers[:, 0])
    assert len(flagged) == 1  # "forty" only; [CLS]/[SEP] and words stay zero
    assert numbers[flagged[0], 2] == pytest.approx(40 / 50)
    offsets = [(0, 0), (0, 3), (4, 6), (0, 0)]
    assert token_numeric_features("the 12", offsets)[2, 1] == pytest.approx(1.2)


def test_geometry_depth_is_the_nearest_corner():
    box = np.array([[20.0, 3.0, 0.0, 4.0, 2.0, 1.5, 0.0]])
    assert nearest_depth(box)[0] == pytest.approx(18.0)
    rotated = np.array([[20.0, 3.0, 0.0, 4.0, 2.0, 1.5, np.pi / 2]])
    assert nearest_depth(rotated)[0] == pytest.approx(19.0)
    g = geometry_features(box, np.array([1]), np.array([0.7]))
    assert g.shape == (1, 17) and g[0, 1] == 1.0 and g[0, 3] == pytest.approx(0.7)
    assert g[0, 12] == pytest.approx(18.0 / 50.0)


def test_point_evidence_counts_and_motion():
    box = np.array([[10.0, 0.0, 0.0, 1.0, 1.0, 2.0, 0.0]])
    lidar = np.array([[10.0, 0.0, 0.0, 100.0], [10.3, 0.2, 0.5, 200.0], [14.0, 0.0, 0.0, 50.0]])
    ev = lidar_evidence(box, lidar)
    assert ev[0, 0] == pytest.approx(np.log1p(2)) and ev[0, 1] == pytest.approx(150 / 255)
    # A crossing object: y grows by 0.4 m per scan (time = -k for the k-th older scan).
    radar = np.array([[10.0, -0.4 * k, 0.0, 5.0, -1.0, 0.0, -k] for k in range(3)])
    rev = radar_evidence(box, radar)
    assert rev[0, 0] == pytest.approx(np.log1p(3)) and rev[0, 1] == pytest.approx(np.log1p(1))
    assert rev[0, 8] == pytest.approx(0.4) and rev[0, 7] == pytest.approx(0.0)
    assert rev[0, 2] == pytest.approx(-0.1)  # mean v_r / 10
    empty = radar_evidence(np.array([[30.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0]]), radar)
    assert not empty.any()


def test_pool_bev_is_bilinear_in_metres():
    grid = BevGrid(0.0, 8.0, -4.0, 4.0, 1.0)
    xs = torch.arange(8, dtype=torch.float32) + 0.5  # cell-centre x
    fmap = xs[None, None, :].expand(1, 8, 8).clone()
    out = pool_bev(fmap, grid, torch.tensor([[3.0, 0.0], [5.25, 1.0]]))
    assert out[:, 0].tolist() == pytest.approx([3.0, 5.25])


def _cands(k: int, pad: int = 0) -> CandidateBatch:
    g = torch.randn(1, k + pad, 17)
    padding = torch.zeros(1, k + pad, dtype=torch.bool)
    padding[0, k:] = True
    return CandidateBatch(
        g, torch.randn(1, k + pad, 6), torch.randn(1, k + pad, 4 + 4), None, padding
    )


def test_referent_stage_is_permutation_equivariant_and_masks_padding():
    torch.manual_seed(0)
    stage = ReferentStage(ReferentConfig(dim=32, layers=2, heads=4), 8, 6, 4, None).eval()
    cands = _cands(5, pad=2)
    tokens, pad = torch.randn(1, 7, 8), torch.zeros(1, 7, dtype=torch.bool)
    logits = stage(cands, tokens, None, pad)
    assert logits.shape == (1, 7) and bool((logits[0, 5:] <= -1e3).all())
    perm = torch.tensor([3, 0, 4, 1, 2, 5, 6])
    permuted = CandidateBatch(
        cands.geometry[:, perm],
        cands.fused[:, perm],
        cands.lidar[:, perm],
        None,
        cands.padding[:, perm],
    )
    again = stage(permuted, tokens, None, pad)
    assert torch.allclose(again[0, :5], logits[0, perm[:5]], atol=1e-5)
    # The prompt matters: other tokens give other scores.
    assert not torch.allclose(stage(cands, torch.randn(1, 7, 8), None, pad)[0, :5], logits[0, :5])


def test_referent_loss_prefers_the_referent():
    target = torch.tensor([[0.0, 1.0, 0.0]])
    pad = torch.zeros(1, 3, dtype=torch.bool)
    good = referent_loss(torch.tensor([[-3.0, 3.0, -3.0]]), target, pad)
    bad = referent_loss(torch.tensor([[3.0, -3.0, 3.0]]), target, pad)
    assert good[0] < bad[0] and good[1] < bad[1]


def test_frame_dataset_one_item_per_scene_and_flip(tiny_root):
    root = Talk2RadarRoot(tiny_root)
    worlds = {root.load_meta(i).world_id for i in root.ids("train")}
    assert len(scene_ids(root, "train")) == len(worlds)
    a = Actor(1, "Car", np.array([10.0, 2.0, 0.0, 4.0, 2.0, 1.5, 0.3]), np.array([1.0, 0.5]))
    f = flip_actor(a)
    assert f.box[1] == -2.0 and f.box[6] == pytest.approx(-0.3) and f.velocity[1] == -0.5
    assert f.radial_velocity == pytest.approx(a.radial_velocity)
    item = FrameDataset(root, "train")[0]
    assert item.actors and item.lidar.shape[1] == 4 and item.radar.shape[1] == 7


def test_referent_step_learns_on_a_fixed_batch(tiny_root):
    torch.manual_seed(0)
    model = build_model("small", grounding="referent")
    model.train()
    ds = FrameDataset(Talk2RadarRoot(tiny_root), "train")
    frames = [ds[i] for i in range(min(2, len(ds)))]
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3)
    cfg = ReferentTrainConfig(prompts_per_scene=4)
    losses = []
    for _ in range(12):
        # The same prompts every step (same generator seed): the loss must fall.
        loss = referent_step(model, frames, np.random.default_rng(0), cfg)
        assert loss.prompts > 0
        opt.zero_grad()
        loss.total.backward()
        opt.step()
        losses.append(float((loss.bce + loss.listwise).detach()))
    assert min(losses[-3:]) < 0.75 * losses[0]


def test_referent_model_grounds_a_scene(tiny_root):
    torch.manual_seed(0)
    model = build_model("small", grounding="referent").eval()
    sample = Talk2RadarRoot(tiny_root).load(Talk2RadarRoot(tiny_root).ids("test")[0])
    features = model.encode_scene(sample.lidar, sample.radar)
    assert features.objects is not None and features.detection_heatmaps.shape == (3, 80, 80)
    pred = model.ground(features, "the nearest car on the left", score_threshold=0.0)
    assert len(pred.boxes) == len(features.objects)
    assert np.all(np.diff(pred.scores) <= 0) and np.all((pred.scores >= 0) & (pred.scores <= 1))
    assert pred.heatmaps.shape == (3, 80, 80) and pred.timings.referent > 0
    high = model.ground(features, "the nearest car on the left", score_threshold=0.99)
    assert np.all(high.scores >= 0.99)
    with pytest.raises(ValueError, match="forward"):
        model([sample.lidar], [sample.radar], ["the car"])


def test_cached_stage_banks_prompts_and_learns(tiny_root):
    from model.referent_train import cache_scenes, cached_referent_step, match_detections

    torch.manual_seed(0)
    model = build_model("small", grounding="referent")
    scenes, bank = cache_scenes(model, FrameDataset(Talk2RadarRoot(tiny_root), "train"), 6)
    assert all(len(s.prompts) == len(s.targets) for s in scenes)
    assert set(bank.entries) == {t for s in scenes for t in s.prompts}
    for p in model.parameters():
        p.requires_grad_(False)
    for p in model.referent.parameters():
        p.requires_grad_(True)
    opt = torch.optim.AdamW(model.referent.parameters(), lr=3e-3)
    cfg = ReferentTrainConfig(prompts_per_scene=6)
    usable = [s for s in scenes if s.prompts]
    assert usable, "the (seeded, untrained) detector should propose some actor of these scenes"
    losses = []
    model.referent.train()
    for _ in range(15):
        loss = cached_referent_step(model, usable, bank, np.random.default_rng(0), cfg)
        opt.zero_grad()
        loss.total.backward()
        opt.step()
        losses.append(float(loss.total.detach()))
    assert min(losses[-3:]) < 0.75 * losses[0]
    # Matching is one-to-one and class-aware.
    a = Actor(4, "Pedestrian", np.array([10.0, 0.0, 0.0, 0.6, 0.6, 1.7, 0.0]), np.zeros(2))
    boxes = np.array([[10.2, 0.1, 0, 0.6, 0.6, 1.7, 0], [10.3, 0, 0, 0.6, 0.6, 1.7, 0]])
    assert match_detections(boxes, np.array([1, 1]), [a]).tolist() == [4, -1]
    assert match_detections(boxes, np.array([0, 2]), [a]).tolist() == [-1, -1]
