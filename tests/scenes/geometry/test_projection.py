"""Projection of LiDAR-frame points and box wireframes into the camera image, against pixels
computed by hand from VoD's intrinsics (fx = fy = 1495.468642, cx = 961.272442, cy = 624.89592)
and the synthetic camera at (0.92, 0.15, -0.46) in the LiDAR frame, looking along +x, untilted."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.geometry.calib import CAMERA_IN_LIDAR, IMAGE_SIZE, vod_lidar_calibration
from scenes.geometry.projection import (
    BOX_EDGES,
    MIN_DEPTH,
    image_size_at,
    project_box_edges,
    project_points,
    scale_calibration,
)

F, CX, CY = 1495.468642, 961.272442, 624.89592
CAM = np.array(CAMERA_IN_LIDAR)
CALIB = vod_lidar_calibration()


def _at(forward: float, right: float = 0.0, up: float = 0.0) -> np.ndarray:
    """A LiDAR-frame point ``forward`` m ahead of the camera, ``right`` m right, ``up`` m up."""
    return CAM + np.array([forward, -right, up])


def test_points_project_to_hand_computed_pixels():
    pts = np.stack([_at(10.0), _at(10.0, right=1.0), _at(10.0, up=1.0), _at(5.0, -2.0, -0.5)])
    proj = project_points(np.c_[pts, np.zeros(4)], CALIB)  # an intensity column is ignored
    expected = [
        (CX, CY),
        (CX + F / 10, CY),  # right is +u
        (CX, CY - F / 10),  # up is -v
        (CX - 2 * F / 5, CY + 0.5 * F / 5),
    ]
    np.testing.assert_allclose(proj.uv, expected, atol=1e-6)
    np.testing.assert_allclose(proj.depth, [10.0, 10.0, 10.0, 5.0], atol=1e-9)
    assert proj.visible.all()


def test_points_behind_the_camera_or_outside_the_image_are_not_visible():
    pts = np.stack([_at(-5.0), _at(MIN_DEPTH / 2), _at(10.0, right=8.0), _at(10.0, up=-5.0)])
    proj = project_points(pts, CALIB)
    assert np.isnan(proj.uv[:2]).all()  # behind, or nearer than MIN_DEPTH: no pixel at all
    assert proj.uv[2, 0] == pytest.approx(CX + 8 * F / 10)  # 2157.6 > 1936: right of the image
    assert proj.uv[3, 1] == pytest.approx(CY + 5 * F / 10)  # 1372.6 > 1216: below it
    assert not proj.visible.any()
    assert proj.depth[0] == pytest.approx(-5.0)
    with pytest.raises(ValueError, match="shape"):
        project_points(np.zeros((3, 2)), CALIB)


def test_scaled_calibration_scales_pixels_exactly():
    assert image_size_at(0.5) == (968, 608) and image_size_at(0.125) == (242, 152)
    half = scale_calibration(CALIB, 0.5)
    np.testing.assert_allclose(half.P2[:2, :3], CALIB.P2[:2, :3] / 2)
    np.testing.assert_array_equal(half.P2[2], CALIB.P2[2])
    np.testing.assert_array_equal(half.Tr_velo_to_cam, CALIB.Tr_velo_to_cam)
    assert np.array_equal(half.P0, half.P2) and np.array_equal(half.P3, half.P2)
    pts = np.stack([_at(10.0, 1.0, 1.0), _at(7.0, -3.0, 0.2)])
    full = project_points(pts, CALIB).uv
    np.testing.assert_allclose(project_points(pts, half, (968, 608)).uv, full / 2, atol=1e-9)
    squeezed = scale_calibration(CALIB, 0.5, 0.25)  # a display resize that is not uniform
    np.testing.assert_allclose(project_points(pts, squeezed).uv, full * [0.5, 0.25], atol=1e-9)
    for bad in (0.3, 0.0, -1.0):
        with pytest.raises(ValueError, match="scale"):
            image_size_at(bad)


def _same_segments(got: np.ndarray, expected: np.ndarray, atol: float = 1e-6) -> bool:
    """Whether two sets of segments ``(S, 2, 2)`` are equal, in any order and either direction."""
    if len(got) != len(expected):
        return False
    left = list(range(len(got)))
    for seg in expected:
        for i in left:
            if np.allclose(got[i], seg, atol=atol) or np.allclose(got[i][::-1], seg, atol=atol):
                left.remove(i)
                break
        else:
            return False
    return True


def test_cube_wireframe_matches_hand_computed_segments():
    # A 2 m cube centred on the optical axis 10 m ahead: near face at depth 9, far face at 11.
    centre = _at(10.0)
    box = np.array([[*centre, 2.0, 2.0, 2.0, 0.0]])
    segments, drawn = project_box_edges(box, CALIB)
    assert segments.shape == (1, 12, 2, 2) and drawn.all()
    corner = {}
    for depth in (9.0, 11.0):
        for sx in (-1, 1):
            for sy in (-1, 1):
                corner[(depth, sx, sy)] = (CX + sx * F / depth, CY + sy * F / depth)
    expected = []
    for depth in (9.0, 11.0):  # the square of each face
        for a, b in (
            ((-1, -1), (1, -1)),
            ((1, -1), (1, 1)),
            ((1, 1), (-1, 1)),
            ((-1, 1), (-1, -1)),
        ):
            expected.append((corner[(depth, *a)], corner[(depth, *b)]))
    for sx in (-1, 1):  # the four edges along the depth
        for sy in (-1, 1):
            expected.append((corner[(9.0, sx, sy)], corner[(11.0, sx, sy)]))
    assert _same_segments(segments[0][drawn[0]], np.array(expected))
    assert not _same_segments(segments[0][drawn[0]], np.array(expected) + 0.01)
    assert len(BOX_EDGES) == 12 and len({tuple(sorted(e)) for e in BOX_EDGES.tolist()}) == 12


def test_wireframe_is_clipped_at_the_image_border():
    # A flat 20 m wide box whose right part leaves the image: at depth 10 the border u = 1936 is
    # 10 * (1936 - cx) / f = 6.518 m right of the axis.
    centre = _at(10.0, right=5.0)
    box = np.array([[*centre, 0.01, 10.0, 0.01, 0.0]])  # l (depth) 1 cm, w 10 m: 0..10 m right
    segments, drawn = project_box_edges(box, CALIB)
    ends = segments[0][drawn[0]].reshape(-1, 2)
    assert ends[:, 0].max() == pytest.approx(IMAGE_SIZE[0])
    assert ends[:, 0].min() == pytest.approx(CX, abs=1.0)  # left end on the axis
    assert (ends[:, 1] > CY - F * 0.006).all() and (ends[:, 1] < CY + F * 0.006).all()
    # Wholly outside (left of the image): nothing drawn.
    outside = np.array([[*_at(10.0, right=-30.0), 1.0, 1.0, 1.0, 0.0]])
    assert not project_box_edges(outside, CALIB)[1].any()


def test_nothing_is_drawn_behind_the_camera_and_straddling_boxes_are_cut():
    behind = np.array([[*_at(-6.0), 4.0, 2.0, 1.5, 0.0]])
    segments, drawn = project_box_edges(behind, CALIB)
    assert not drawn.any() and np.isnan(segments).all()
    # A box from 2 m behind to 2 m ahead of the camera: its rear face is not drawn, the edges
    # along x are cut at MIN_DEPTH (then at the border), and everything drawn is in the image.
    straddle = np.array([[*_at(0.0), 4.0, 1.0, 1.0, 0.0]])
    segments, drawn = project_box_edges(straddle, CALIB)
    corners_x = np.array([1, -1, -1, 1, 1, -1, -1, 1])  # box_corners: front, rear, rear, front
    for e, (a, b) in enumerate(BOX_EDGES):
        if corners_x[a] < 0 and corners_x[b] < 0:
            assert not drawn[0, e]  # rear face: wholly behind
        if corners_x[a] > 0 and corners_x[b] > 0:
            assert drawn[0, e]  # front face at depth 2: in view (0.5 m off axis -> 374 px)
    ends = segments[drawn].reshape(-1, 2)
    assert (ends[:, 0] >= 0).all() and (ends[:, 0] <= IMAGE_SIZE[0]).all()
    assert (ends[:, 1] >= 0).all() and (ends[:, 1] <= IMAGE_SIZE[1]).all()
    assert drawn.sum() == 8  # front face 4 + the 4 cut edges along x
    assert project_box_edges(np.zeros((0, 7)), CALIB)[0].shape == (0, 12, 2, 2)
