"""The referent path: numerals, candidate evidence, the referent stage, its training step and the
model's encode_scene / ground in ``grounding="referent"`` mode."""

from pathlib import Path

import numpy as np
import pytest
import torch

from model import build_model
from model.config import ReferentConfig
from model.core.grid import BevGrid
from model.nets.numerals import number_spans, token_numeric_features
from model.nets.text import tokenize_with_numbers
from model.referent.candidates import (
    geometry_features,
    lidar_evidence,
    nearest_depth,
    pool_bev,
    radar_evidence,
)
from model.referent.stage import CandidateBatch, ReferentStage, geometry_width, referent_loss
from model.training.config import PromptDraw
from model.training.referent_step import ReferentTrainConfig, referent_step
from scenes.datasets.augment import mirror_actor
from scenes.datasets.frames import FrameDataset, SensorAugment, scene_ids
from scenes.datasets.grounding import AugmentConfig
from scenes.geometry.actors import Actor
from scenes.synth.generate import SynthSettings, generate_root
from scenes.talk2radar.root import Talk2RadarRoot


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
        ("one hundred and five km/h", [("one hundred and five", 105.0)]),  # a count: bounded
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
    g = torch.randn(1, k + pad, geometry_width(ReferentConfig()))
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
    f = mirror_actor(a)
    assert f.box[1] == -2.0 and f.box[6] == pytest.approx(-0.3) and f.velocity[1] == -0.5
    assert f.radial_velocity == pytest.approx(a.radial_velocity)
    item = FrameDataset(root, "train")[0]
    assert item.actors and item.lidar.shape[1] == 4 and item.radar.shape[1] == 7


def test_mount_height_offset_moves_points_and_actors_together(tiny_root):
    root = Talk2RadarRoot(tiny_root)
    plain = FrameDataset(root, "train")[0]
    only_mount = SensorAugment(
        p_intensity=0.0,
        p_beams=0.0,
        p_radar_subsample=0.0,
        p_rcs=0.0,
        p_single_scan=0.0,
        p_mount=1.0,
        mount_shift=0.2,
    )
    no_geometry = AugmentConfig(flip_probability=0.0, lidar_keep_min=1.0, shuffle_points=False)
    moved = FrameDataset(root, "train", no_geometry, only_mount, seed=3)[0]
    dz = moved.lidar[:, 2] - plain.lidar[:, 2]
    assert 0.0 < abs(dz[0]) <= 0.2 and np.allclose(dz, dz[0], atol=1e-5)
    np.testing.assert_allclose(moved.radar[:, 2] - plain.radar[:, 2], dz[0], atol=1e-5)
    for a, b in zip(plain.actors, moved.actors, strict=True):
        assert b.box[2] - a.box[2] == pytest.approx(dz[0], abs=1e-5)
        np.testing.assert_array_equal(b.box[[0, 1, 3, 4, 5, 6]], a.box[[0, 1, 3, 4, 5, 6]])
    assert SensorAugment(p_mount=0.0).mount_offset(np.random.default_rng(0)) == 0.0


def test_referent_step_learns_on_a_fixed_batch(tiny_root):
    torch.manual_seed(0)
    model = build_model("small", grounding="referent")
    model.train()
    ds = FrameDataset(Talk2RadarRoot(tiny_root), "train")
    frames = [ds[i] for i in range(min(2, len(ds)))]
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3)
    cfg = ReferentTrainConfig(PromptDraw(4))
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
    pred = model.ground(features, "the nearest car on the left", score_threshold=0.0, ranked=True)
    assert len(pred.boxes) == len(features.objects)
    assert np.all(np.diff(pred.scores) <= 0) and np.all((pred.scores >= 0) & (pred.scores <= 1))
    assert pred.heatmaps.shape == (3, 80, 80) and pred.timings.referent > 0
    # A cut between two scores keeps exactly the candidates above it, in the same order.
    k = len(pred.scores) // 2
    assert k > 0 and pred.scores[k - 1] > pred.scores[k]
    cut = float(pred.scores[k - 1] + pred.scores[k]) / 2.0
    high = model.ground(features, "the nearest car on the left", score_threshold=cut, ranked=True)
    assert 0 < len(high.scores) == k < len(pred.scores)
    np.testing.assert_allclose(high.scores, pred.scores[:k], atol=1e-6)
    np.testing.assert_allclose(high.boxes, pred.boxes[:k], atol=1e-6)
    with pytest.raises(ValueError, match="forward"):
        model([sample.lidar], [sample.radar], ["the car"])


def test_cached_stage_banks_prompts_and_learns(tiny_root):
    from model.training.referent_cache import cache_scenes, cached_referent_step, match_detections

    torch.manual_seed(0)
    model = build_model("small", grounding="referent")
    scenes, bank = cache_scenes(model, FrameDataset(Talk2RadarRoot(tiny_root), "train"), 6)
    assert all(len(s.prompts) == len(s.targets) for s in scenes)
    assert set(bank.entries) == {t for s in scenes for t in s.prompts}
    for p in model.parameters():
        p.requires_grad_(False)
    for p in model.grounding.parameters():
        p.requires_grad_(True)
    opt = torch.optim.AdamW(model.grounding.parameters(), lr=3e-3)
    cfg = ReferentTrainConfig(PromptDraw(6))
    usable = [s for s in scenes if s.prompts]
    assert usable, "the (seeded, untrained) detector should propose some actor of these scenes"
    losses = []
    model.grounding.train()
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


# --------------------------------------------------------------------------- speed-ups, same outputs
# The candidate evidence and the answer's heatmap were made faster (issue 15, speed); these are the
# earlier, straightforward forms, kept here as references: the fast ones must match them bit for bit.


def _reference_in_footprints(points, boxes, margin, use_z):
    order = np.argsort(points[:, 0], kind="stable")
    xs = points[order, 0]
    out = []
    for box in boxes:
        r = 0.5 * float(np.hypot(box[3], box[4])) + margin
        lo, hi = np.searchsorted(xs, [box[0] - r, box[0] + r])
        idx = order[lo:hi]
        p = points[idx]
        dx, dy = p[:, 0] - box[0], p[:, 1] - box[1]
        c, s = np.cos(box[6]), np.sin(box[6])
        lx, ly = dx * c + dy * s, -dx * s + dy * c
        keep = (np.abs(lx) <= box[3] / 2 + margin) & (np.abs(ly) <= box[4] / 2 + margin)
        if use_z:
            keep &= np.abs(p[:, 2] - box[2]) <= box[5] / 2 + margin
        out.append(idx[keep])
    return out


def _reference_lidar_evidence(boxes, lidar):
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    pts = np.asarray(lidar, dtype=np.float64).reshape(-1, 4)
    out = np.zeros((len(b), 4), dtype=np.float32)
    for i, idx in enumerate(_reference_in_footprints(pts, b, 0.2, use_z=True)):
        if len(idx):
            p = pts[idx]
            out[i] = (np.log1p(len(idx)), p[:, 3].mean() / 255.0, np.ptp(p[:, 2]), 1.0)
    return out


def _reference_slope(values, times):
    t = times - times.mean()
    denom = float(np.sum(t * t))
    if denom < 1e-9:
        return 0.0
    return float(np.sum(t * (values - values.mean())) / denom)


def _reference_radar_evidence(boxes, radar):
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    pts = np.asarray(radar, dtype=np.float64).reshape(-1, 7)
    out = np.zeros((len(b), 10), dtype=np.float32)
    for i, idx in enumerate(_reference_in_footprints(pts, b, 0.5, use_z=False)):
        if not len(idx):
            continue
        p = pts[idx]
        vc = p[:, 5]
        out[i] = (
            np.log1p(len(idx)),
            np.log1p(int(np.sum(p[:, 6] == 0))),
            p[:, 4].mean() / 10.0,
            vc.mean() / 10.0,
            np.median(vc) / 10.0,
            vc.std() / 10.0,
            p[:, 3].mean() / 10.0,
            _reference_slope(p[:, 0], p[:, 6]),
            _reference_slope(p[:, 1], p[:, 6]),
            1.0,
        )
    return out


def _reference_heatmap(detection, boxes, labels, probabilities, grid, anchor, sigma_cells=1.5):
    from model.core.anchors import anchor_points

    _, h, w = detection.shape
    weight = np.zeros_like(detection, dtype=np.float32)
    if len(boxes):
        cells = grid.xy_to_cell(anchor_points(np.asarray(boxes).reshape(-1, 7), anchor))
        cols = np.arange(w)[None, None, :] + 0.5
        rows = np.arange(h)[None, :, None] + 0.5
        d2 = (cols - cells[:, 0, None, None]) ** 2 + (rows - cells[:, 1, None, None]) ** 2
        g = np.exp(-d2 / (2 * sigma_cells**2)) * np.asarray(probabilities)[:, None, None]
        for c in range(detection.shape[0]):
            mine = np.asarray(labels) == c
            if mine.any():
                weight[c] = g[mine].max(axis=0)
    peak = np.maximum(detection.reshape(detection.shape[0], -1).max(axis=1), 1e-6)
    shape = 0.5 + 0.5 * detection / peak[:, None, None]
    return np.clip(weight * shape, 0.0, 1.0).astype(np.float32)


def _scene_like(seed: int, k: int = 40, n_lidar: int = 20000, n_radar: int = 1500):
    """Boxes of every size and yaw, some touching or overlapping, and clouds dense around them:
    points on the box surfaces and edges (the inside tests' borderline cases), repeated x values
    (the stable order), background points, radar with 1-5 scans and exact zero velocities."""
    rng = np.random.default_rng(seed)
    size = rng.choice([[4.2, 1.8, 1.6], [0.6, 0.6, 1.7], [1.8, 0.7, 1.6]], size=k)
    centre = np.column_stack(
        [rng.uniform(0.0, 52.0, k), rng.uniform(-26.0, 26.0, k), rng.uniform(-0.5, 0.5, k)]
    )
    centre[k // 2 :, :2] = centre[: k - k // 2, :2] + rng.normal(0.0, 0.8, (k - k // 2, 2))
    boxes = np.column_stack([centre, size * rng.uniform(0.8, 1.2, (k, 3)), rng.uniform(-4, 4, k)])

    def around(n: int) -> np.ndarray:
        which = rng.integers(0, k, n)
        b = boxes[which]
        # Local coordinates up to 1.3x the half-size: inside, on the border and just outside.
        local = rng.uniform(-0.65, 0.65, (n, 3)) * (b[:, 3:6] + 0.6)
        local[: n // 5, 0] = np.sign(local[: n // 5, 0]) * (b[: n // 5, 3] / 2 + 0.2)
        c, s = np.cos(b[:, 6]), np.sin(b[:, 6])
        x = b[:, 0] + local[:, 0] * c - local[:, 1] * s
        y = b[:, 1] + local[:, 0] * s + local[:, 1] * c
        return np.column_stack([x, y, b[:, 2] + local[:, 2]])

    xyz = np.concatenate([around(n_lidar), rng.uniform([-5, -40, -3], [60, 40, 3], (5000, 3))])
    xyz[::7, 0] = xyz[1::7, 0][: len(xyz[::7])]  # ties in x
    lidar = np.column_stack([xyz, rng.integers(0, 256, len(xyz)).astype(np.float64)])
    rxyz = around(n_radar)
    vc = np.round(rng.normal(0.0, 3.0, n_radar), 1)
    vc[::3] = 0.0
    vc[1::9] = -0.0
    scans = rng.integers(0, rng.integers(1, 6, n_radar) + 1)
    radar = np.column_stack(
        [rxyz, rng.normal(0, 10, n_radar), vc + rng.normal(0, 1, n_radar), vc, -scans]
    )
    return boxes, lidar.astype(np.float32), radar.astype(np.float32)


@pytest.mark.parametrize("seed", range(6))
def test_fast_point_evidence_is_bit_identical_to_the_reference(seed):
    boxes, lidar, radar = _scene_like(seed)
    for fast, ref, pts in (
        (lidar_evidence, _reference_lidar_evidence, lidar),
        (radar_evidence, _reference_radar_evidence, radar),
    ):
        got, want = fast(boxes, pts), ref(boxes, pts)
        assert got.dtype == want.dtype and got.tobytes() == want.tobytes()
        assert (want[:, -1] > 0).sum() >= len(boxes) // 2  # most boxes do hold points
    # Degenerate inputs: no boxes, no points, one point, a single scan.
    assert lidar_evidence(np.zeros((0, 7)), lidar).shape == (0, 4)
    assert not radar_evidence(boxes, np.zeros((0, 7))).any()
    one = radar[:1].copy()
    assert radar_evidence(boxes, one).tobytes() == _reference_radar_evidence(boxes, one).tobytes()
    single = radar.copy()
    single[:, 6] = 0.0
    assert radar_evidence(boxes, single).tobytes() == (
        _reference_radar_evidence(boxes, single).tobytes()
    )


@pytest.mark.parametrize("seed", range(3))
def test_point_evidence_is_the_same_from_float32_and_float64_clouds(seed):
    # float32 clouds (the model's) order each box's points by one sort of integer keys, others
    # by two stable sorts; both must be the reference order, -0.0 and +0.0 being equal x.
    boxes, lidar, radar = _scene_like(seed)
    lidar[::11, 0] = np.where(np.abs(lidar[::11, 0]) < 0.05, -0.0, lidar[::11, 0])
    lidar[1::11, 0] = np.where(np.abs(lidar[1::11, 0]) < 0.05, 0.0, lidar[1::11, 0])
    for fast, ref, pts in (
        (lidar_evidence, _reference_lidar_evidence, lidar),
        (radar_evidence, _reference_radar_evidence, radar),
    ):
        want = ref(boxes, pts).tobytes()
        assert fast(boxes, pts).tobytes() == want
        assert fast(boxes, pts.astype(np.float64)).tobytes() == want


def test_fast_point_evidence_matches_on_a_generated_scene(tiny_root):
    root = Talk2RadarRoot(tiny_root)
    sample = root.load(root.ids("train")[0])
    rng = np.random.default_rng(3)
    meta = root.load_meta(root.ids("train")[0])
    boxes = np.array([a.box for a in meta.actors], dtype=np.float64).reshape(-1, 7)
    boxes = np.concatenate([boxes, boxes + rng.normal(0, 0.3, boxes.shape)])
    for fast, ref, pts in (
        (lidar_evidence, _reference_lidar_evidence, sample.lidar),
        (radar_evidence, _reference_radar_evidence, sample.radar),
    ):
        assert fast(boxes, pts).tobytes() == ref(boxes, pts).tobytes()


def _heatmap_case(
    rng: np.random.Generator, k: int, xs: tuple[float, float], ys: tuple[float, float]
) -> tuple[BevGrid, np.ndarray, np.ndarray, np.ndarray]:
    """A head grid, random detector heatmaps ``(3, 80, 80)`` and ``k`` boxes of random classes
    whose centres are uniform in ``xs`` x ``ys``."""
    grid = BevGrid(0.0, 51.2, -25.6, 25.6, 0.64)
    detection = rng.random((3, 80, 80)).astype(np.float32)
    boxes = np.column_stack(
        [
            rng.uniform(*xs, k), rng.uniform(*ys, k), np.zeros(k),
            rng.uniform(0.5, 5, k), rng.uniform(0.5, 2.5, k), np.ones(k), rng.uniform(-4, 4, k),
        ]
    )  # fmt: skip
    return grid, detection, boxes, rng.integers(0, 3, k)


@pytest.mark.parametrize("seed", range(4))
def test_fast_referent_heatmap_is_bit_identical_to_the_reference(seed):
    from model.referent.heatmap import referent_heatmap

    rng = np.random.default_rng(seed)
    k = 40
    # Anchors inside the grid, on its border and well outside it (their Gaussians' tails still
    # reach in, or not); probabilities from certain to vanishing, and exactly 0.
    grid, detection, boxes, labels = _heatmap_case(rng, k, (-20, 70), (-45, 45))
    probs = rng.random(k) ** rng.choice([1, 4, 40], k)
    probs[:3] = (0.0, 1e-30, 1.0)
    for anchor in ("corner", "center"):
        for p in (probs, probs * 1e-20, np.zeros(k)):
            got = referent_heatmap(detection, boxes, labels, p, grid, anchor)
            want = _reference_heatmap(detection, boxes, labels, p, grid, anchor)
            assert got.tobytes() == want.tobytes()
    none = referent_heatmap(detection, np.zeros((0, 7)), labels[:0], probs[:0], grid, "corner")
    assert (
        not none.any()
        and none.tobytes()
        == (
            _reference_heatmap(detection, np.zeros((0, 7)), labels[:0], probs[:0], grid, "corner")
        ).tobytes()
    )


def test_extended_language_banks_empty_answers_and_reworded_prompts(tiny_root):
    """``--language extended --text-noise``: the bank holds prompts whose right answer is no box
    (an all-zero target row) and reworded ones; the base bank is what it always was."""
    from model.training.config import TrainConfig, TrainingError, parse_args
    from model.training.referent_cache import cache_scenes

    flags = ["--language", "extended", "--text-noise", "0.5", "--phrasing", "all"]
    cfg, _ = parse_args(["--data", str(tiny_root), "--out", "/tmp/x", *flags])
    assert (cfg.language, cfg.text_noise, cfg.phrasing) == ("extended", 0.5, "all")
    with pytest.raises(TrainingError, match="--text-noise"):
        TrainConfig(data=str(tiny_root), out="/tmp/x", text_noise=1.5)
    draw = TrainConfig(
        data=str(tiny_root), out="/tmp/x", language="extended", text_noise=1.0
    ).prompt_draw()
    assert draw.config.p_perturb == 1.0 and draw.config.language == "extended"
    torch.manual_seed(0)
    model = build_model("small", grounding="referent")
    frames = FrameDataset(Talk2RadarRoot(tiny_root), "train")
    base, _ = cache_scenes(model, frames, 12, progress=False)
    extended, _ = cache_scenes(model, frames, 12, progress=False, prompt_config=draw.config)
    empty = [t for s in extended for t in s.targets if not t.any()]
    assert empty, "extended prompts include answers with no box"
    assert not any(not t.any() for s in base for t in s.targets)
    base_texts = {t for s in base for t in s.prompts}
    assert not base_texts & {t for s in extended for t in s.prompts}


def test_family_rates_reach_the_generator_and_bad_ones_are_one_line_errors(tiny_root):
    """``--family-rate``, given once per family, sets the extended generator's shares; a wrong
    count, a negative share, a sum above 1 or the base language is refused with a one-line error."""
    from model.training.config import TrainingError, parse_args

    rates = ["0.05", "0.12", "0.06", "0.06", "0.17", "0.17", "0.03"]
    flags = [x for r in rates for x in ("--family-rate", r)]
    base = ["--data", str(tiny_root), "--out", "/tmp/x"]
    cfg, _ = parse_args([*base, "--language", "extended", *flags])
    assert cfg.family_rates == tuple(float(r) for r in rates)
    assert cfg.prompt_draw().config.family_rates == cfg.family_rates
    default = parse_args([*base, "--language", "extended"])[0].prompt_draw()
    assert default.config.family_rates != cfg.family_rates
    for bad in (flags[:4], [*flags[:-1], "-0.1"], [*flags[:-1], "0.9"]):
        with pytest.raises(TrainingError, match="--family-rate") as err:
            parse_args([*base, "--language", "extended", *bad])
        assert "\n" not in str(err.value)
    with pytest.raises(TrainingError, match="--language extended"):
        parse_args([*base, *flags])


def test_a_scene_canvas_draws_every_prompt_as_the_heatmap_function_does():
    # ReferentCanvas holds the text-free part (shading, windows at the widest radius); drawing
    # any probabilities on it must give referent_heatmap's bits, and it refuses a probability
    # above the p_max it was built for (its windows would be too narrow).
    from model.referent.heatmap import ReferentCanvas, referent_heatmap

    rng, k = np.random.default_rng(7), 25
    grid, detection, boxes, labels = _heatmap_case(rng, k, (-10, 60), (-30, 30))
    canvas = ReferentCanvas.of(detection, boxes, labels, grid, "corner")
    for scale in (1.0, 1e-3, 1e-30, 0.0):
        p = rng.random(k) * scale
        want = referent_heatmap(detection, boxes, labels, p, grid, "corner")
        assert canvas.draw(p).tobytes() == want.tobytes()
    with pytest.raises(ValueError, match="p_max"):
        ReferentCanvas.of(detection, boxes, labels, grid, "corner", p_max=0.5).draw(np.ones(k))
    with pytest.raises(ValueError, match="probabilities"):
        canvas.draw(np.ones(k + 1))


@pytest.mark.parametrize("seed", range(3))
def test_box_point_pairs_are_the_brute_force_pairs_in_order(seed):
    # Each box against every point with the definition's arithmetic (float64, in the box's
    # frame, the x range), ordered by box, then x, then point index: the compiled pass's pairs.
    from model.referent.point_pairs import box_point_pairs

    boxes, lidar, _ = _scene_like(seed, k=12, n_lidar=3000)
    for pts in (lidar.astype(np.float32), lidar):
        for margin, use_z in ((0.2, True), (0.5, False)):
            want_box, want_point = [], []
            p = np.asarray(pts[:, :3], dtype=np.float64)
            for b, box in enumerate(boxes):
                c, s = np.cos(box[6]), np.sin(box[6])
                dx, dy = p[:, 0] - box[0], p[:, 1] - box[1]
                r = 0.5 * np.hypot(box[3], box[4]) + margin
                inside = (np.abs(dx * c + dy * s) <= box[3] / 2 + margin) & (
                    np.abs(-dx * s + dy * c) <= box[4] / 2 + margin
                )
                if use_z:
                    inside &= np.abs(p[:, 2] - box[2]) <= box[5] / 2 + margin
                inside &= (p[:, 0] >= box[0] - r) & (p[:, 0] < box[0] + r)
                idx = np.flatnonzero(inside)
                idx = idx[np.argsort(pts[idx, 0], kind="stable")]
                want_box += [b] * len(idx)
                want_point += idx.tolist()
            got_box, got_point = box_point_pairs(pts, boxes, margin, use_z)
            assert got_box.tolist() == want_box and got_point.tolist() == want_point
    empty = box_point_pairs(lidar, boxes[:0], 0.2, True)
    assert len(empty[0]) == len(empty[1]) == 0


def test_a_singular_description_and_a_command_get_the_best_box_only(tiny_root):
    """Issue 49: "the X closest to us" and a command mean one object; a plural keeps its set."""
    torch.manual_seed(0)
    model = build_model("small", grounding="referent").eval()
    sample = Talk2RadarRoot(tiny_root).load(Talk2RadarRoot(tiny_root).ids("test")[0])
    features = model.encode_scene(sample.lidar, sample.radar)
    ranked = model.ground(features, "the nearest car on the left", score_threshold=0.0, ranked=True)
    assert len(ranked.boxes) > 1
    one = model.ground(features, "the nearest car on the left", score_threshold=0.0)
    assert len(one.boxes) == 1 and one.reading.single
    np.testing.assert_allclose(one.boxes[0], ranked.boxes[0])
    command = model.ground(features, "park behind the silver van on the left", score_threshold=0.0)
    assert len(command.boxes) == 1 and command.reading.command
    assert command.reading.texts == ("the car on the left",)
    plural = model.ground(features, "the cars on the left", score_threshold=0.0)
    assert len(plural.boxes) == len(ranked.boxes) and not plural.reading.single
    # a command is never answered with nothing while a candidate of its class is there
    high = model.ground(features, "park behind the silver van on the left", score_threshold=1.0)
    assert len(high.boxes) == 1 and high.classes == ("Car",)
