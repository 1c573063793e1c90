"""Target drawing, decoding and rotated NMS of the C3D-RECHead: hand-computed cases and round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from model.config import HeadConfig
from model.core.grid import BevGrid
from model.head.decode import Detections, decode, rotated_nms
from model.head.detector import HeadOutput
from model.head.targets import collate_targets, draw_targets, gaussian_radius

# 0.5 m cells: every coordinate below is exact in binary floating point.
GRID = BevGrid(x_min=0.0, x_max=50.0, y_min=-25.0, y_max=25.0, cell=0.5)  # (H, W) = (100, 100)
# A grid around the ego vehicle, for boxes in every quadrant.
AROUND = BevGrid(x_min=-32.0, x_max=32.0, y_min=-32.0, y_max=32.0, cell=0.64)  # (100, 100)


def _cfg(anchor: str = "corner", **kw) -> HeadConfig:
    return HeadConfig(anchor=anchor, **kw)


# ----------------------------------------------------------------------------- worked examples


def test_worked_example_nearest_corner():
    # Box x in [8, 12], y in [4, 6]: corners (12, 6), (8, 6), (8, 4), (12, 4); the nearest to the
    # origin is (8, 4) (distance sqrt(80)). Cell 0.5: col = 8 / 0.5 = 16, row = (4 + 25) / 0.5 = 58.
    box = np.array([[10.0, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0]])
    t = draw_targets(box, ["Car"], GRID, _cfg("corner"))
    np.testing.assert_allclose(t.anchors, [[8.0, 4.0]])
    assert t.mask.tolist() == [True]
    assert t.labels.tolist() == [0]
    assert t.indices.tolist() == [58 * 100 + 16]
    # Anchor cell centre (8.25, 4.25); anchor - centre = (-0.25, -0.25); box centre - cell centre.
    np.testing.assert_allclose(t.anchor_offsets, [[-0.25, -0.25]])
    expected = [1.75, 0.75, -1.0, math.log(4.0), math.log(2.0), math.log(1.5), 0.0, 1.0]
    np.testing.assert_allclose(t.regression[0], expected, atol=1e-6)
    assert t.heatmap[0, 58, 16] == 1.0
    assert t.heatmap[0].max() == 1.0
    assert not t.heatmap[1:].any()


def test_worked_example_rotated_box_corner():
    # yaw = 90 degrees: the length runs along y. Box x in [9, 11], y in [3, 7]; nearest corner (9, 3).
    box = np.array([[10.0, 5.0, -1.0, 4.0, 2.0, 1.5, math.pi / 2]])
    t = draw_targets(box, ["Cyclist"], GRID, _cfg("corner"))
    np.testing.assert_allclose(t.anchors, [[9.0, 3.0]], atol=1e-12)
    assert t.labels.tolist() == [2]
    row, col = (3 + 25) * 2, 9 * 2
    assert t.indices.tolist() == [row * 100 + col]
    assert t.heatmap[2, row, col] == 1.0
    np.testing.assert_allclose(t.regression[0, :2], [10.0 - 9.25, 5.0 - 3.25], atol=1e-6)
    np.testing.assert_allclose(t.regression[0, 6:], [1.0, 0.0], atol=1e-6)


def test_worked_example_edge_and_center_anchors():
    # Box x in [8, 12], y in [-0.5, 1.5]. Nearest edge = the rear edge x = 8 (distance 8; the right
    # edge y = -0.5 is at distance sqrt(64.25)); its midpoint is (8, 0.5). Nearest corner (8, -0.5).
    box = np.array([[10.0, 0.5, -1.0, 4.0, 2.0, 1.5, 0.0]])
    edge = draw_targets(box, ["Car"], GRID, _cfg("edge"))
    corner = draw_targets(box, ["Car"], GRID, _cfg("corner"))
    center = draw_targets(box, ["Car"], GRID, _cfg("center"))
    np.testing.assert_allclose(edge.anchors, [[8.0, 0.5]])
    np.testing.assert_allclose(corner.anchors, [[8.0, -0.5]])
    np.testing.assert_allclose(center.anchors, [[10.0, 0.5]])
    assert edge.indices.tolist() == [(0.5 + 25) * 2 * 100 + 16]
    assert corner.indices.tolist() == [(-0.5 + 25) * 2 * 100 + 16]
    assert center.indices.tolist() == [(0.5 + 25) * 2 * 100 + 20]
    for t in (edge, corner, center):
        row, col = divmod(int(t.indices[0]), 100)
        assert t.heatmap[0, row, col] == 1.0


def test_gaussian_radius_hand_computed():
    # 10 x 10 cells, overlap 0.1: case 3 gives (-4 + sqrt(16 + 144)) / 2; cases 1 and 2 are larger.
    assert gaussian_radius(10.0, 10.0, 0.1) == pytest.approx((-4.0 + math.sqrt(160.0)) / 2.0)
    # Case 1 for the same box: (20 + sqrt(400 - 400 * 0.9 / 1.1)) / 2 is larger.
    assert gaussian_radius(10.0, 10.0, 0.1) < (20 + math.sqrt(400 - 400 * 0.9 / 1.1)) / 2


def test_gaussian_shape_and_min_radius():
    # A pedestrian (0.8 x 0.6 m = 1.6 x 1.2 cells) has radius int(...) = 0 -> min_radius 2,
    # sigma = 5/6. One cell right of the peak: exp(-1 / (2 sigma^2)) = exp(-0.72).
    box = np.array([[20.0, 0.1, -1.0, 0.8, 0.6, 1.7, 0.0]])
    t = draw_targets(box, ["Pedestrian"], GRID, _cfg("center"))
    row, col = divmod(int(t.indices[0]), 100)
    hm = t.heatmap[1]
    assert hm[row, col] == 1.0
    assert hm[row, col + 1] == pytest.approx(math.exp(-0.72), rel=1e-6)
    assert hm[row + 1, col + 1] == pytest.approx(math.exp(-1.44), rel=1e-6)
    assert hm[row, col + 2] > 0 and hm[row, col + 3] == 0.0  # radius 2
    assert (hm == 1.0).sum() == 1


def test_overlapping_gaussians_take_the_maximum():
    boxes = np.array([[20.0, 0.1, -1.0, 0.8, 0.6, 1.7, 0.0], [20.5, 0.1, -1.0, 0.8, 0.6, 1.7, 0.0]])
    t = draw_targets(boxes, ["Pedestrian", "Pedestrian"], GRID, _cfg("center"))
    hm = t.heatmap[1]
    for idx in t.indices:
        assert hm.flat[idx] == 1.0
    assert hm.max() == 1.0


def test_ignored_class_and_anchor_outside_grid():
    boxes = np.array(
        [
            [10.0, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # a truck: ignored
            [-5.0, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # behind the ego: anchor outside the grid
            [60.0, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # too far
            [20.0, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # valid
        ]
    )
    t = draw_targets(boxes, ["Truck", "Car", "Car", "Car"], GRID, _cfg())
    assert t.labels.tolist() == [-1, 0, 0, 0]
    assert t.mask.tolist() == [False, False, False, True]
    assert (t.heatmap == 1.0).sum() == 1
    assert not t.regression[:3].any()


def test_zero_boxes():
    t = draw_targets(np.zeros((0, 7)), [], GRID, _cfg())
    assert t.heatmap.shape == (3, 100, 100) and not t.heatmap.any()
    assert t.regression.shape == (0, 8) and t.mask.shape == (0,)
    batch = collate_targets([t, t])
    assert batch.regression.shape == (2, 0, 8)


@pytest.mark.parametrize("bad", [(0.0, 2.0, 1.5), (4.0, -1.0, 1.5), (4.0, 2.0, 0.0)])
def test_bad_sizes_rejected_with_box_index(bad):
    boxes = np.array([[10.0, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0], [20.0, 0.0, -1.0, *bad, 0.0]])
    with pytest.raises(ValueError, match="box 1"):
        draw_targets(boxes, ["Car", "Car"], GRID, _cfg())


def test_bad_input_shapes_rejected():
    with pytest.raises(ValueError, match=r"\(K, 7\)"):
        draw_targets(np.zeros((2, 6)), ["Car", "Car"], GRID, _cfg())
    with pytest.raises(ValueError, match="class names"):
        draw_targets(np.array([[10.0, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0]]), [], GRID, _cfg())
    with pytest.raises(ValueError, match="box 0 has non-finite"):
        draw_targets(np.array([[np.nan, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0]]), ["Car"], GRID, _cfg())


def test_collate_pads_with_mask():
    a = draw_targets(np.array([[10.0, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0]]), ["Car"], GRID, _cfg())
    b = draw_targets(np.zeros((0, 7)), [], GRID, _cfg())
    batch = collate_targets([a, b])
    assert batch.heatmap.shape == (2, 3, 100, 100)
    assert batch.mask.tolist() == [[True], [False]]
    assert batch.labels.tolist() == [[0], [-1]]
    assert batch.indices.dtype == torch.int64
    with pytest.raises(ValueError, match="empty batch"):
        collate_targets([])


# ----------------------------------------------------------------------------- round trips


def _scene_boxes() -> tuple[np.ndarray, list[str]]:
    """Separated boxes in all four quadrants around the ego, yaws including +-pi and 0, +-pi/2."""
    eps = 1e-7
    rows = [
        ([12.3, 7.1, -0.9, 4.2, 1.8, 1.6, 0.3], "Car"),  # front-left
        ([15.7, -9.4, -1.1, 3.9, 1.7, 1.5, math.pi - eps], "Car"),  # front-right, yaw ~ +pi
        ([-11.2, 13.6, -0.8, 4.5, 1.9, 1.7, -math.pi], "Car"),  # rear-left, yaw = -pi
        ([-18.9, -6.3, -1.0, 4.0, 1.8, 1.5, -math.pi + eps], "Car"),  # rear-right, yaw ~ -pi
        ([4.1, 21.3, -0.7, 0.7, 0.6, 1.8, 2.5], "Pedestrian"),
        ([-6.6, -22.4, -0.7, 0.6, 0.5, 1.7, -2.9], "Pedestrian"),
        ([25.2, 1.2, -0.8, 1.9, 0.7, 1.7, math.pi / 2], "Cyclist"),  # straight ahead
        ([-26.7, 0.4, -0.8, 1.8, 0.6, 1.7, -math.pi / 2], "Cyclist"),  # straight behind
        ([0.3, -17.8, -0.8, 1.7, 0.6, 1.6, 0.0], "Cyclist"),  # to the right
        ([-3.3, 27.9, -0.9, 4.1, 1.8, 1.5, 3.1], "Car"),
    ]
    return np.array([r[0] for r in rows]), [r[1] for r in rows]


def _flip_boxes() -> list[np.ndarray]:
    """The same car at one place with yaws either side of where its nearest corner flips."""
    base = [20.0, 6.0, -1.0, 4.4, 1.9, 1.6]
    flip_yaw = math.atan2(6.0, 20.0)  # heading along the line of sight: two corners tie
    return [
        np.array([[*base, flip_yaw + d]]) for d in (-1e-3, 1e-3, math.pi - 1e-3, -math.pi + 1e-3)
    ]


def _fake_output(targets_list, grid: BevGrid) -> HeadOutput:
    """A perfect head output: logit +10 at each anchor cell of its class, -10 elsewhere, and the
    regression targets written at the anchor cells (scattered through the collated indices)."""
    batch = collate_targets(targets_list)
    B = len(targets_list)
    H, W = grid.shape
    heatmap = torch.full((B, 3, H * W), -10.0)
    regression = torch.zeros((B, 8, H * W))
    for b in range(B):
        for k in torch.nonzero(batch.mask[b]).flatten().tolist():
            idx = int(batch.indices[b, k])
            heatmap[b, int(batch.labels[b, k]), idx] = 10.0
            regression[b, :, idx] = batch.regression[b, k]
    return HeadOutput(heatmap.reshape(B, 3, H, W), regression.reshape(B, 8, H, W))


def _assert_same_boxes(det: Detections, boxes: np.ndarray, classes: list[str]) -> None:
    assert len(det.boxes) == len(boxes)
    for box, cls in zip(boxes, classes, strict=True):
        j = int(np.argmin(np.linalg.norm(det.boxes[:, :2] - box[:2], axis=1)))
        np.testing.assert_allclose(det.boxes[j, :6], box[:6], atol=1e-5, rtol=0)
        dyaw = (det.boxes[j, 6] - box[6] + math.pi) % (2 * math.pi) - math.pi
        assert abs(dyaw) < 1e-5, (det.boxes[j, 6], box[6])
        assert -math.pi <= det.boxes[j, 6] < math.pi
        assert det.classes[j] == cls
        assert det.scores[j] == pytest.approx(1.0 / (1.0 + math.exp(-10.0)))


@pytest.mark.parametrize("anchor", ["corner", "edge", "center"])
def test_round_trip_exact_all_quadrants(anchor):
    cfg = _cfg(anchor)
    boxes, classes = _scene_boxes()
    t = draw_targets(boxes, classes, AROUND, cfg)
    assert t.mask.all()
    assert len(set(t.indices.tolist())) == len(boxes)
    (det,) = decode(_fake_output([t], AROUND), AROUND, cfg)
    _assert_same_boxes(det, boxes, classes)


@pytest.mark.parametrize("anchor", ["corner", "edge", "center"])
def test_round_trip_exact_across_anchor_flips(anchor):
    cfg = _cfg(anchor)
    samples = _flip_boxes()
    targets = [draw_targets(b, ["Car"], GRID, cfg) for b in samples]
    if anchor == "corner":
        # The nearest corner really changes across the flip (so the test covers it).
        assert not np.allclose(targets[0].anchors, targets[1].anchors, atol=0.5)
    dets = decode(_fake_output(targets, GRID), GRID, cfg)
    for det, boxes in zip(dets, samples, strict=True):
        _assert_same_boxes(det, boxes, ["Car"])


def test_round_trip_on_small_preset_grid():
    # The small preset's 0.32 m grid, downsampled like a stride-2 head: cells are not exact floats.
    grid = BevGrid(0.0, 51.2, -25.6, 25.6, 0.32).downsample(2)
    cfg = _cfg()
    boxes = np.array(
        [[13.37, -4.21, -0.95, 4.31, 1.83, 1.52, 2.2], [40.02, 19.99, -1.2, 0.61, 0.55, 1.8, -0.4]]
    )
    t = draw_targets(boxes, ["Car", "Pedestrian"], grid, cfg)
    (det,) = decode(_fake_output([t], grid), grid, cfg)
    _assert_same_boxes(det, boxes, ["Car", "Pedestrian"])


# ----------------------------------------------------------------------------- decoding


def test_decode_threshold_cap_and_order():
    H, W = GRID.shape
    logits = torch.full((1, 3, H, W), -10.0)
    # Four separated car peaks with scores sigmoid(2), sigmoid(1), sigmoid(0), sigmoid(-1).
    cells = [(10, 10), (10, 40), (40, 10), (40, 40)]
    for (r, c), v in zip(cells, (2.0, 1.0, 0.0, -1.0), strict=True):
        logits[0, 0, r, c] = v
    reg = torch.zeros(1, 8, H, W)
    reg[:, 3:6] = math.log(2.0)
    reg[:, 7] = 1.0
    out = HeadOutput(logits, reg)
    (det,) = decode(out, GRID, _cfg(score_threshold=0.4))
    assert len(det.boxes) == 3  # sigmoid(-1) = 0.27 is below the threshold
    assert np.all(np.diff(det.scores) <= 0)
    np.testing.assert_allclose(det.boxes[0, :2], GRID.cell_to_xy(np.array([10.5, 10.5])))
    np.testing.assert_allclose(det.boxes[0, 3:6], [2.0, 2.0, 2.0])
    (det,) = decode(out, GRID, _cfg(score_threshold=0.4), score_threshold=0.6)
    assert len(det.boxes) == 2
    (det,) = decode(out, GRID, _cfg(score_threshold=0.0, max_detections=1))
    assert len(det.boxes) == 1 and det.scores[0] == pytest.approx(1 / (1 + math.exp(-2)))


def test_decode_max_pool_keeps_only_local_maxima():
    H, W = GRID.shape
    logits = torch.full((1, 3, H, W), -10.0)
    logits[0, 1, 20, 20] = 3.0
    logits[0, 1, 20, 21] = 2.0  # neighbour of a higher peak: not a peak
    logits[0, 1, 20, 23] = 2.5  # two cells away: its own peak
    reg = torch.zeros(1, 8, H, W)
    reg[:, 3:6] = math.log(0.5)  # 0.5 m boxes: the two peaks' boxes do not overlap
    reg[:, 7] = 1.0
    (det,) = decode(HeadOutput(logits, reg), GRID, _cfg())
    assert len(det.boxes) == 2
    assert det.classes == ("Pedestrian", "Pedestrian")


def test_decode_nms_is_per_class():
    # The same box predicted as Car and Cyclist in neighbouring-class channels survives in both.
    H, W = GRID.shape
    logits = torch.full((1, 3, H, W), -10.0)
    logits[0, 0, 30, 30] = 3.0
    logits[0, 2, 30, 30] = 2.0
    logits[0, 0, 30, 32] = 2.0  # a second car peak whose 4 m box overlaps the first: suppressed
    reg = torch.zeros(1, 8, H, W)
    reg[:, 3] = math.log(4.0)
    reg[:, 4] = math.log(2.0)
    reg[:, 5] = math.log(1.5)
    reg[:, 7] = 1.0
    (det,) = decode(HeadOutput(logits, reg), GRID, _cfg())
    assert sorted(det.classes) == ["Car", "Cyclist"]


def test_decode_empty_and_shape_errors():
    H, W = GRID.shape
    out = HeadOutput(torch.full((2, 3, H, W), -10.0), torch.zeros(2, 8, H, W))
    dets = decode(out, GRID, _cfg())
    assert len(dets) == 2 and all(len(d.boxes) == 0 for d in dets)
    assert dets[0].boxes.shape == (0, 7)
    with pytest.raises(ValueError, match="grid shape"):
        decode(HeadOutput(torch.zeros(1, 3, 8, 8), torch.zeros(1, 8, 8, 8)), GRID, _cfg())
    with pytest.raises(ValueError, match="regression"):
        decode(HeadOutput(torch.zeros(1, 3, H, W), torch.zeros(1, 7, H, W)), GRID, _cfg())


# ----------------------------------------------------------------------------- rotated NMS


def test_rotated_nms_hand_made_boxes():
    boxes = np.array(
        [
            [0.0, 0.0, 0.0, 4.0, 2.0, 1.0, 0.0],  # A
            [1.5, 0.0, 0.0, 4.0, 2.0, 1.0, 0.0],  # B: IoU(A, B) = (2.5 * 2) / (16 - 5) = 5/11
            [0.0, 0.0, 0.0, 4.0, 2.0, 1.0, math.pi / 2],  # C: IoU(A, C) = 4 / (16 - 4) = 1/3
            [20.0, 0.0, 0.0, 4.0, 2.0, 1.0, 0.0],  # D: far away
        ]
    )
    scores = np.array([0.9, 0.8, 0.7, 0.95])
    assert rotated_nms(boxes, scores, 0.2).tolist() == [3, 0]
    assert rotated_nms(boxes, scores, 0.4).tolist() == [3, 0, 2]
    assert rotated_nms(boxes, scores, 0.5).tolist() == [3, 0, 1, 2]
    # IoU(B, C) = (1.5 * 2) / (16 - 3) = 3/13: once A is gone B suppresses C at 0.2, not at 0.25.
    assert rotated_nms(boxes[1:], scores[1:], 0.2).tolist() == [2, 0]
    assert rotated_nms(boxes[1:], scores[1:], 0.25).tolist() == [2, 0, 1]


def test_rotated_nms_empty_and_mismatch():
    assert rotated_nms(np.zeros((0, 7)), np.zeros(0), 0.2).tolist() == []
    with pytest.raises(ValueError, match="scores"):
        rotated_nms(np.zeros((2, 7)), np.zeros(3), 0.2)


def test_rotated_nms_max_keep_is_a_prefix_of_the_full_run():
    rng = np.random.default_rng(5)
    boxes = np.column_stack(
        [
            rng.uniform(0, 20, 200),
            rng.uniform(-10, 10, 200),
            np.zeros(200),
            rng.uniform(0.5, 4.5, 200),
            rng.uniform(0.5, 2.0, 200),
            np.ones(200),
            rng.uniform(-3, 3, 200),
        ]
    )
    scores = rng.random(200)
    full = rotated_nms(boxes, scores, 0.2)
    assert len(full) > 10
    for k in (1, 5, 10, len(full), len(full) + 3):
        assert rotated_nms(boxes, scores, 0.2, max_keep=k).tolist() == full[:k].tolist()


def _greedy_reference(boxes, scores, labels, iou_threshold):
    """Per class, the plain greedy NMS over the whole IoU matrix; merged by descending score
    (ties: lower class, then lower index) as the decoder has always merged the classes."""
    from scenes.geometry.boxes import bev_iou

    kept = []
    for c in np.unique(labels):
        idx = np.flatnonzero(labels == c)
        order = idx[np.argsort(-scores[idx], kind="stable")]
        iou = bev_iou(boxes[order], boxes[order])
        alive = np.ones(len(order), dtype=bool)
        for i in range(len(order)):
            if alive[i]:
                kept.append(order[i])
                alive[i + 1 :] &= ~(iou[i, i + 1 :] > iou_threshold)
    kept = np.asarray(kept, dtype=np.int64)
    return kept[np.lexsort((kept, labels[kept], -scores[kept]))]


@pytest.mark.parametrize("seed", range(4))
def test_class_nms_is_per_class_greedy_nms_merged_by_score(seed):
    from model.head.decode import class_nms

    rng = np.random.default_rng(seed)
    n = 400  # more than one block (4 * max_keep) for the small caps below
    boxes = np.column_stack(
        [
            rng.uniform(0, 15, n),
            rng.uniform(-8, 8, n),
            np.zeros(n),
            rng.uniform(0.5, 4.5, n),
            rng.uniform(0.5, 2.0, n),
            np.ones(n),
            rng.uniform(-3, 3, n),
        ]
    )
    scores = np.round(rng.random(n), 2)  # many ties, across and within classes
    labels = rng.integers(0, 3, n)
    want = _greedy_reference(boxes, scores, labels, 0.2)
    assert 40 < len(want) < n
    assert class_nms(boxes, scores, labels, 0.2).tolist() == want.tolist()
    for cap in (1, 7, 40, len(want), len(want) + 5):
        assert class_nms(boxes, scores, labels, 0.2, cap).tolist() == want[:cap].tolist()
    assert class_nms(boxes[:0], scores[:0], labels[:0], 0.2).tolist() == []


def test_decode_limit_is_a_prefix_of_the_full_decode():
    torch.manual_seed(0)
    out = HeadOutput(torch.randn(1, 3, 100, 100) - 1.0, torch.randn(1, 8, 100, 100) * 0.3)
    cfg = _cfg(score_threshold=0.05)
    (full,) = decode(out, GRID, cfg)
    assert len(full.boxes) == cfg.max_detections
    for limit in (1, 13, cfg.max_detections, cfg.max_detections + 10):
        (part,) = decode(out, GRID, cfg, limit=limit)
        k = min(limit, cfg.max_detections)
        np.testing.assert_array_equal(part.boxes, full.boxes[:k])
        np.testing.assert_array_equal(part.scores, full.scores[:k])
        assert part.classes == full.classes[:k]
