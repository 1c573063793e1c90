"""Box geometry: corners, points in boxes, exact rotated IoU, anchor points (hand-computed)."""

import numpy as np
import pytest

from scenes.geometry.boxes import (
    bev_corners,
    bev_iou,
    box_corners,
    iou3d,
    nearest_bev_corner,
    nearest_edge_midpoint,
    paired_bev_iou,
    points_in_boxes,
    wrap_yaw,
)


def test_wrap_yaw_range_and_values():
    assert wrap_yaw(np.pi) == pytest.approx(-np.pi)
    assert wrap_yaw(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert wrap_yaw(-np.pi / 2) == pytest.approx(-np.pi / 2)
    values = wrap_yaw(np.linspace(-20, 20, 101))
    assert np.all(values >= -np.pi) and np.all(values < np.pi)


def test_bev_corners_of_a_rotated_box():
    # A 4 x 2 box at (10, 5) yawed by 90 degrees: its length runs along +y.
    corners = bev_corners(np.array([10, 5, 0, 4, 2, 1, np.pi / 2]))[0]
    expected = np.array([[9, 7], [9, 3], [11, 3], [11, 7]], dtype=float)
    np.testing.assert_allclose(corners, expected, atol=1e-12)


def test_box_corners_heights():
    corners = box_corners(np.array([0, 0, 1.0, 4, 2, 3, 0]))[0]
    np.testing.assert_allclose(corners[:4, 2], -0.5)
    np.testing.assert_allclose(corners[4:, 2], 2.5)


def test_points_in_boxes_rotated():
    box = np.array([[0, 0, 0, 4, 2, 2, np.pi / 4]])
    # Along the heading at 1.9 m: inside; 2.1 m: outside; across at 0.9: inside, 1.1: outside.
    d = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    n = np.array([-d[1], d[0]])
    pts = np.array(
        [[*(1.9 * d), 0], [*(2.1 * d), 0], [*(0.9 * n), 0], [*(1.1 * n), 0], [0, 0, 1.1]]
    )
    np.testing.assert_array_equal(
        points_in_boxes(pts, box)[:, 0], [True, False, True, False, False]
    )


def test_iou_identical_boxes_is_one():
    box = np.array([[12.3, -4.5, -0.7, 4.4, 1.9, 1.6, 2.9]])
    assert bev_iou(box, box)[0, 0] == pytest.approx(1.0)
    assert iou3d(box, box)[0, 0] == pytest.approx(1.0)


def test_iou_disjoint_and_touching_is_zero():
    a = np.array([[0, 0, 0, 2, 2, 2, 0]])
    far = np.array([[10, 0, 0, 2, 2, 2, 0.3]])
    touching = np.array([[2, 0, 0, 2, 2, 2, 0]])
    corner_touch = np.array([[2, 2, 0, 2, 2, 2, 0]])
    assert bev_iou(a, far)[0, 0] == 0.0
    assert bev_iou(a, touching)[0, 0] == pytest.approx(0.0, abs=1e-12)
    assert bev_iou(a, corner_touch)[0, 0] == pytest.approx(0.0, abs=1e-12)


def test_iou_shifted_axis_aligned():
    a = np.array([[0, 0, 0, 2, 2, 2, 0]])
    b = np.array([[1, 0, 0.5, 2, 2, 2, 0]])
    # BEV: overlap 1 x 2 = 2, union 4 + 4 - 2 = 6.
    assert bev_iou(a, b)[0, 0] == pytest.approx(2 / 6)
    # 3D: overlap 2 * 1.5 = 3, union 8 + 8 - 3 = 13.
    assert iou3d(a, b)[0, 0] == pytest.approx(3 / 13)


def test_iou_rotated_square_octagon():
    # A 2 x 2 square and the same square rotated by 45 degrees: the intersection is a regular
    # octagon with area 8 (sqrt(2) - 1).
    a = np.array([[0, 0, 0, 2, 2, 2, 0]])
    b = np.array([[0, 0, 0, 2, 2, 2, np.pi / 4]])
    inter = 8 * (np.sqrt(2) - 1)
    assert bev_iou(a, b)[0, 0] == pytest.approx(inter / (8 - inter))


def test_iou_is_symmetric_and_yaw_periodic():
    rng = np.random.default_rng(0)
    boxes = np.c_[rng.uniform(-3, 3, (30, 3)), rng.uniform(0.5, 4, (30, 3)), rng.uniform(-4, 4, 30)]
    m = bev_iou(boxes, boxes)
    np.testing.assert_allclose(m, m.T, atol=1e-9)
    np.testing.assert_allclose(np.diag(m), 1.0, atol=1e-9)
    flipped = boxes.copy()
    flipped[:, 6] += np.pi  # a box turned by 180 degrees covers the same area
    np.testing.assert_allclose(bev_iou(boxes, flipped), m, atol=1e-9)


def test_iou_matches_monte_carlo():
    rng = np.random.default_rng(1)
    a = np.array([[0, 0, 0, 4, 2, 1, 0.3]])
    b = np.array([[1, 0.5, 0, 3, 1.5, 1, -0.7]])
    pts = np.c_[rng.uniform(-3, 4, (400_000, 2)), np.zeros(400_000)]
    in_a, in_b = points_in_boxes(pts, a)[:, 0], points_in_boxes(pts, b)[:, 0]
    estimate = (in_a & in_b).sum() / (in_a | in_b).sum()
    assert bev_iou(a, b)[0, 0] == pytest.approx(estimate, abs=5e-3)


def test_nearest_corner_and_edge():
    # Axis-aligned 4 x 2 box centred 10 m ahead, 3 m left: corners x in {8, 12}, y in {2, 4}.
    box = np.array([[10, 3, 0, 4, 2, 1.5, 0]])
    np.testing.assert_allclose(nearest_bev_corner(box)[0], [8, 2])
    # The nearest edge is the rear one (x = 8, y from 2 to 4): distance to it is |(8, 2)| as well,
    # and it ties with the right edge (y = 2, x 8..12) only at the shared corner; the rear edge's
    # closest point is (8, 2), the right edge's is (8, 2) too -> the first in corner order wins.
    mid = nearest_edge_midpoint(box)[0]
    assert tuple(mid) in {(8.0, 3.0), (10.0, 2.0)}
    # Straight ahead, the rear edge is strictly nearest.
    ahead = np.array([[10, 0, 0, 4, 2, 1.5, 0]])
    np.testing.assert_allclose(nearest_edge_midpoint(ahead)[0], [8, 0])


def test_paired_iou_is_the_matrix_at_those_pairs():
    rng = np.random.default_rng(2)
    a = np.column_stack([rng.uniform(0, 6, (60, 2)), np.zeros(60), rng.uniform(0.5, 4, (60, 3)),
                         rng.uniform(-3, 3, 60)])  # fmt: skip
    b = a[rng.permutation(60)] + np.r_[rng.normal(0, 0.5, 2), np.zeros(5)]
    full = bev_iou(a, b)
    assert (full > 0).sum() > 60  # overlapping and disjoint pairs
    i, j = np.meshgrid(np.arange(60), np.arange(60), indexing="ij")
    assert np.array_equal(paired_bev_iou(a[i.ravel()], b[j.ravel()]), full.ravel())
    assert paired_bev_iou(np.zeros((0, 7)), np.zeros((0, 7))).shape == (0,)
    with pytest.raises(ValueError, match="against"):
        paired_bev_iou(a[:2], b[:3])


def test_points_in_footprints_per_box_with_margin() -> None:
    from scenes.geometry.boxes import points_in_footprints

    boxes = np.array(
        [[0.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0], [10.0, 0.0, 5.0, 4.0, 2.0, 1.5, np.pi / 2]]
    )
    xy = np.array([[1.9, 0.9, 99.0], [2.3, 0.0, 0.0], [10.0, 1.9, 0.0], [11.9, 0.0, 0.0]])
    inside = points_in_footprints(xy, boxes)
    assert inside.shape == (4, 2)
    np.testing.assert_array_equal(
        inside, [[True, False], [False, False], [False, True], [False, False]]
    )
    grown = points_in_footprints(xy, boxes, margin=0.5)
    np.testing.assert_array_equal(grown[:, 0], [True, True, False, False])
    assert points_in_footprints(np.zeros((0, 2)), boxes).shape == (0, 2)
