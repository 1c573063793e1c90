"""LiDAR-frame geometry into the camera image: points to pixels, 3D box wireframes to 2D line
segments, which boxes the camera sees (:func:`in_camera_view`) and VoD annotates
(:func:`in_annotated_area`), and the calibration of a resized image.

Conventions
    Inputs are in the LiDAR (sensor) frame of a :class:`~scenes.geometry.calib.Calibration` (x forward,
    y left, z up); ``calib.velo_to_img`` (``P2 · R0_rect · Tr_velo_to_cam``) maps them to
    homogeneous pixels ``(u·w, v·w, w)``, where ``w`` is the depth in front of the camera (the
    rectified camera z for VoD's P2, whose last column is zero). Pixel coordinates are continuous:
    the image covers ``[0, W] x [0, H]`` and pixel ``(row j, column i)`` has its centre at
    ``(i + 0.5, j + 0.5)`` (as :func:`scenes.geometry.calib.boxes_2d` clips). Nothing at a depth below
    :data:`MIN_DEPTH` is drawn: a segment reaching behind the camera is cut where it crosses that
    plane, so it never wraps around through the perspective division.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.geometry.boxes import box_corners
from scenes.geometry.calib import IMAGE_SIZE, Calibration, boxes_2d, boxes_lidar_to_camera

MIN_DEPTH = 0.1
"""Metres in front of the camera below which points are not projected and segments are cut."""

BOX_EDGES = np.array(
    [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]
)
"""The 12 edges of a box as index pairs into :func:`scenes.geometry.boxes.box_corners` (bottom ring, top
ring, verticals)."""


def image_size_at(scale: float, base: tuple[int, int] = IMAGE_SIZE) -> tuple[int, int]:
    """``(width, height)`` of VoD's 1936 x 1216 image (or ``base``) resized by ``scale``.

    Raises:
        ValueError: ``scale`` is not positive or the size would not be whole pixels.
    """
    if not scale > 0:
        raise ValueError(f"image scale must be > 0, got {scale}")
    width, height = base[0] * scale, base[1] * scale
    if abs(width - round(width)) > 1e-9 or abs(height - round(height)) > 1e-9:
        raise ValueError(
            f"image scale {scale} gives {width} x {height} pixels; use one that divides "
            f"{base[0]} x {base[1]} exactly"
            + (" (1, 1/2, 1/4, 1/8)" if tuple(base) == tuple(IMAGE_SIZE) else "")
        )
    return round(width), round(height)


def scale_calibration(
    calib: Calibration, scale: float, scale_y: float | None = None
) -> Calibration:
    """The calibration of the image resized by ``scale`` (horizontally; vertically by ``scale_y``,
    default the same): the first two rows of ``P0..P3`` times those factors (exact under the
    continuous pixel convention: ``u' = scale · u``, ``v' = scale_y · v``); ``R0_rect`` and
    ``Tr_velo_to_cam`` unchanged."""
    rows = np.diag([scale, scale if scale_y is None else scale_y, 1.0])
    return Calibration(
        P2=rows @ calib.P2,
        R0_rect=calib.R0_rect,
        Tr_velo_to_cam=calib.Tr_velo_to_cam,
        P0=rows @ calib.P0,
        P1=rows @ calib.P1,
        P3=rows @ calib.P3,
    )


@dataclass(frozen=True)
class ProjectedPoints:
    """Points projected into the image.

    Attributes:
        uv: ``(N, 2)`` pixel coordinates ``u`` (right), ``v`` (down); NaN where behind the camera.
        depth: ``(N,)`` metres in front of the camera (``w``; negative behind it).
        visible: ``(N,)`` in front (depth >= :data:`MIN_DEPTH`) and inside ``[0, W) x [0, H)``.
    """

    uv: np.ndarray
    depth: np.ndarray
    visible: np.ndarray


def _homogeneous(points: np.ndarray, calib: Calibration) -> np.ndarray:
    """``(..., 3)`` LiDAR-frame points -> ``(..., 3)`` homogeneous pixels ``(u·w, v·w, w)``."""
    m = calib.velo_to_img
    return np.asarray(points, dtype=np.float64)[..., :3] @ m[:3, :3].T + m[:3, 3]


def project_points(
    points: np.ndarray, calib: Calibration, image_size: tuple[int, int] = IMAGE_SIZE
) -> ProjectedPoints:
    """Project LiDAR-frame ``points (N, >=3)`` (extra columns ignored) into an image of
    ``(width, height)``."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise ValueError(f"points must have shape (N, >=3), got {pts.shape}")
    uvw = _homogeneous(pts, calib)
    depth = uvw[:, 2]
    front = depth >= MIN_DEPTH
    uv = np.full((len(pts), 2), np.nan)
    uv[front] = uvw[front, :2] / depth[front, None]
    width, height = image_size
    with np.errstate(invalid="ignore"):
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
    return ProjectedPoints(uv=uv, depth=depth, visible=front & inside)


def _clip_to_rectangle(
    p0: np.ndarray, p1: np.ndarray, width: float, height: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liang-Barsky clipping of segments ``p0 -> p1`` (each ``(S, 2)``) to ``[0, W] x [0, H]``;
    the clipped end points and whether anything is left."""
    d = p1 - p0
    p = np.stack([-d[:, 0], d[:, 0], -d[:, 1], d[:, 1]], axis=1)
    q = np.stack([p0[:, 0], width - p0[:, 0], p0[:, 1], height - p0[:, 1]], axis=1)
    t0, t1 = np.zeros(len(p0)), np.ones(len(p0))
    keep = ~np.any((p == 0) & (q < 0), axis=1)  # parallel to a border and outside it
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = q / p
    entering = np.where(p < 0, ratio, -np.inf).max(axis=1)
    leaving = np.where(p > 0, ratio, np.inf).min(axis=1)
    t0 = np.maximum(t0, entering)
    t1 = np.minimum(t1, leaving)
    keep &= t0 <= t1
    limit = np.array([width, height], dtype=np.float64)
    start = np.clip(p0 + t0[:, None] * d, 0.0, limit)  # clip: rounding may overshoot by 1e-13
    end = np.clip(p0 + t1[:, None] * d, 0.0, limit)
    return start, end, keep


def project_box_edges(
    boxes: np.ndarray, calib: Calibration, image_size: tuple[int, int] = IMAGE_SIZE
) -> tuple[np.ndarray, np.ndarray]:
    """The 12 edges (:data:`BOX_EDGES`) of LiDAR-frame boxes ``(K, 7)`` as 2D segments, cut at
    :data:`MIN_DEPTH` in front of the camera and clipped at the image border.

    Returns:
        ``segments (K, 12, 2, 2)``: ``[box, edge, end, (u, v)]`` in pixels (NaN where not drawn),
        and ``drawn (K, 12)`` bool: False for an edge wholly behind the camera or outside the image.
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    k = len(b)
    segments = np.full((k, 12, 2, 2), np.nan)
    if k == 0:
        return segments, np.zeros((0, 12), dtype=bool)
    uvw = _homogeneous(box_corners(b), calib)  # (K, 8, 3)
    a = uvw[:, BOX_EDGES[:, 0]].reshape(-1, 3)
    c = uvw[:, BOX_EDGES[:, 1]].reshape(-1, 3)
    wa, wc = a[:, 2], c[:, 2]
    front = (wa >= MIN_DEPTH) | (wc >= MIN_DEPTH)
    # Cut at the w = MIN_DEPTH plane (linear in homogeneous coordinates along the 3D segment).
    span = wc - wa
    t = np.divide(MIN_DEPTH - wa, span, out=np.zeros_like(span), where=span != 0)
    cut = a + t[:, None] * (c - a)
    a = np.where((wa < MIN_DEPTH)[:, None], cut, a)
    c = np.where((wc < MIN_DEPTH)[:, None], cut, c)
    with np.errstate(divide="ignore", invalid="ignore"):
        p0 = a[:, :2] / a[:, 2:3]
        p1 = c[:, :2] / c[:, 2:3]
    width, height = image_size
    q0, q1, inside = _clip_to_rectangle(
        np.where(front[:, None], p0, 0.0), np.where(front[:, None], p1, 0.0), width, height
    )
    drawn = front & inside
    flat = segments.reshape(-1, 2, 2)
    flat[drawn, 0] = q0[drawn]
    flat[drawn, 1] = q1[drawn]
    return flat.reshape(k, 12, 2, 2), drawn.reshape(k, 12)


def in_camera_view(
    boxes: np.ndarray, calib: Calibration, image_size: tuple[int, int] = IMAGE_SIZE
) -> np.ndarray:
    """Which LiDAR-frame boxes ``(K, 7)`` the camera sees: the box centre in front of the camera
    (camera-frame depth > 0) and the projected 2D box, clipped to ``image_size`` (width, height),
    of positive area (``model.evaluation.predict``'s image rule). Returns ``(K,)`` bool."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    if len(b) == 0:
        return np.zeros(0, dtype=bool)
    cam = boxes_lidar_to_camera(b, calib)
    depth = cam.location[:, 2]  # bottom centre; the geometric centre has the same depth
    box2d = boxes_2d(cam, calib, image_size)
    area_ok = (box2d[:, 2] > box2d[:, 0]) & (box2d[:, 3] > box2d[:, 1])
    return (depth > 0.0) & area_ok


ANNOTATED_RANGE = 50.0
"""Metres from the LiDAR within which VoD annotates (box centre, 3D distance)."""


def in_annotated_area(
    boxes: np.ndarray,
    calib: Calibration,
    image_size: tuple[int, int] = IMAGE_SIZE,
    max_range: float = ANNOTATED_RANGE,
) -> np.ndarray:
    """Which LiDAR-frame boxes ``(K, 7)`` VoD would annotate: centre within ``max_range`` metres
    of the LiDAR and partly in the camera's view (:func:`in_camera_view`). Returns ``(K,)`` bool."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    return in_camera_view(b, calib, image_size) & (np.linalg.norm(b[:, :3], axis=1) <= max_range)
