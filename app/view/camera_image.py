"""Drawing the camera overlay: the frame's image, scaled for display, with LiDAR-frame boxes and
points projected into it (pure numpy + Pillow; no GUI).

Conventions: boxes are ``(K, 7)`` ``x, y, z, l, w, h, yaw`` and points ``(N, >=3)`` in the LiDAR
frame; :mod:`scenes.geometry.projection` maps them into pixels (continuous coordinates: the image covers
``[0, W] x [0, H]``; what lies behind the camera is cut, segments are clipped at the border).

Speed: a camera image is decoded once per frame (:attr:`scenes.frame.Sample.image`) and scaled
down once to :data:`DISPLAY_WIDTH` (VoD's 1936 px halve exactly); its calibration is scaled with
it (:func:`display_image`), so projections land on the small image directly. The points overlay
(:func:`paint_points`) is painted into a cached background; each redraw copies that background
and draws the box wireframes and their labels with Pillow (:func:`compose`), a few milliseconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw

from app.view.colors import RGB, depth_colors, label_font, velocity_colors
from scenes.geometry.calib import Calibration
from scenes.geometry.projection import project_box_edges, project_points, scale_calibration

DISPLAY_WIDTH = 968
"""Width (px) of the displayed image: VoD's 1936 x 1216 image halved."""

LABEL_FONT_SIZE = 18
"""Pixel size of the box labels drawn on the image."""

LIDAR_DOT = 2
"""Side (px) of a LiDAR point's square on the displayed image."""

RADAR_DOT = 5
"""Side (px) of a radar point's square (larger: a radar cloud is sparse)."""


@dataclass(frozen=True)
class CameraImage:
    """A frame's camera image at display size, with the calibration that projects into it.

    Attributes:
        image: ``(h, w, 3)`` uint8 RGB, row 0 at the top.
        calib: The frame's LiDAR calibration with ``P2`` (and ``P0, P1, P3``) scaled to ``image``.
        full_size: ``(width, height)`` of the image file.
    """

    image: np.ndarray
    calib: Calibration
    full_size: tuple[int, int]

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` of :attr:`image`."""
        return int(self.image.shape[1]), int(self.image.shape[0])


def display_image(
    image: np.ndarray, calib: Calibration, max_width: int = DISPLAY_WIDTH
) -> CameraImage:
    """Scale ``image (H, W, 3)`` uint8 down to at most ``max_width`` pixels wide (aspect kept;
    never up) and ``calib`` with it. An integer factor (1936 -> 968) uses Pillow's box
    ``reduce``, which is exact and fast; other sizes a bilinear resize."""
    arr = np.asarray(image)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"the camera image must be (H, W, 3) uint8, got {arr.shape} {arr.dtype}")
    height, width = arr.shape[:2]
    if width <= max_width:
        return CameraImage(arr, calib, (width, height))
    pil = Image.fromarray(arr)
    factor = width / max_width
    if factor == int(factor) and height % int(factor) == 0:
        small = pil.reduce(int(factor))
    else:
        size = (max_width, max(1, round(height * max_width / width)))
        small = pil.resize(size, Image.Resampling.BILINEAR, reducing_gap=2.0)
    out = np.asarray(small, dtype=np.uint8)
    sx, sy = out.shape[1] / width, out.shape[0] / height
    return CameraImage(out, scale_calibration(calib, sx, sy), (width, height))


@dataclass(frozen=True)
class BoxLayer:
    """Boxes drawn on the image as 3D wireframes.

    Attributes:
        boxes: ``(K, 7)`` LiDAR frame.
        colors: ``K`` RGB colours.
        labels: ``K`` texts drawn above each box (``""``: none).
        width: Line width in pixels.
    """

    boxes: np.ndarray
    colors: tuple[RGB, ...]
    labels: tuple[str, ...]
    width: int = 2

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 7)
        object.__setattr__(self, "boxes", boxes)
        if not len(boxes) == len(self.colors) == len(self.labels):
            raise ValueError(
                f"BoxLayer: {len(boxes)} boxes, {len(self.colors)} colours, "
                f"{len(self.labels)} labels"
            )

    def same_as(self, other: BoxLayer | None) -> bool:
        """Whether ``other`` draws exactly the same thing."""
        return (
            other is not None
            and self.width == other.width
            and self.colors == other.colors
            and self.labels == other.labels
            and self.boxes.shape == other.boxes.shape
            and bool(np.array_equal(self.boxes, other.boxes))
        )


EMPTY_LAYER = BoxLayer(np.zeros((0, 7)), (), ())
"""No boxes."""


def overlay_points(
    points: np.ndarray, calib: Calibration, size: tuple[int, int], colors: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The points of ``points (N, >=3)`` (LiDAR frame) that land in an image of ``(width,
    height)``, far first (so that near points are painted over far ones).

    Args:
        colors: ``(N, 3)`` uint8 colour of each point.

    Returns:
        ``uv (M, 2)`` int pixel columns and rows and ``colors (M, 3)`` uint8.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(len(points), -1)
    if len(pts) == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3), np.uint8)
    proj = project_points(pts, calib, size)
    keep = np.nonzero(proj.visible)[0]
    order = keep[np.argsort(-proj.depth[keep], kind="stable")]
    uv = np.floor(proj.uv[order]).astype(np.int64)
    return uv, np.asarray(colors, dtype=np.uint8).reshape(-1, 3)[order]


def lidar_overlay(
    lidar: np.ndarray, calib: Calibration, size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """LiDAR points ``(N, 4)`` coloured by their depth in front of the camera
    (:func:`app.view.colors.depth_colors`), as :func:`overlay_points` returns them."""
    pts = np.asarray(lidar, dtype=np.float64).reshape(-1, 4)
    depth = (pts[:, :3] @ calib.velo_to_cam[2, :3]) + calib.velo_to_cam[2, 3]
    return overlay_points(pts, calib, size, depth_colors(depth))


def radar_overlay(
    radar: np.ndarray, calib: Calibration, size: tuple[int, int], velocity_range: float
) -> tuple[np.ndarray, np.ndarray]:
    """Radar points ``(M, 7)`` (LiDAR frame) coloured by ``v_r_compensated`` on the radar map
    of the 3D view (:func:`app.view.colors.velocity_colors`), as :func:`overlay_points` returns them."""
    pts = np.asarray(radar, dtype=np.float64).reshape(-1, 7)
    return overlay_points(pts, calib, size, velocity_colors(pts[:, 5], velocity_range))


def paint_points(image: np.ndarray, uv: np.ndarray, colors: np.ndarray, dot: int) -> None:
    """Paint ``dot x dot`` squares centred on pixels ``uv (M, 2)`` (columns, rows) into
    ``image (h, w, 3)`` in place, later points over earlier ones; squares are cut at the border."""
    if len(uv) == 0:
        return
    height, width = image.shape[:2]
    offsets = np.arange(dot) - (dot - 1) // 2
    for dy in offsets:
        rows = uv[:, 1] + dy
        for dx in offsets:
            cols = uv[:, 0] + dx
            ok = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
            image[rows[ok], cols[ok]] = colors[ok]


def draw_box_layer(
    draw: ImageDraw.ImageDraw, layer: BoxLayer, calib: Calibration, size: tuple[int, int]
) -> int:
    """Draw a layer's wireframes and labels; returns the number of boxes with a visible edge.

    Each label sits above the highest drawn point of its box, centred on the drawn edges, on a
    dark backdrop; labels of boxes wholly outside the image are not drawn.
    """
    if not len(layer.boxes):
        return 0
    segments, drawn = project_box_edges(layer.boxes, calib, size)
    font = label_font(LABEL_FONT_SIZE)
    shown = 0
    for k in range(len(layer.boxes)):
        if not drawn[k].any():
            continue
        shown += 1
        color = tuple(int(c) for c in layer.colors[k])
        for (u0, v0), (u1, v1) in segments[k][drawn[k]]:
            draw.line([(u0, v0), (u1, v1)], fill=color, width=layer.width)
        text = layer.labels[k]
        if not text:
            continue
        ends = segments[k][drawn[k]].reshape(-1, 2)
        top = float(ends[:, 1].min())
        centre = float((ends[:, 0].min() + ends[:, 0].max()) / 2.0)
        left, upper, right, lower = draw.textbbox((0, 0), text, font=font)
        text_w, text_h = right - left, lower - upper
        x = min(max(centre - text_w / 2.0, 0.0), max(size[0] - text_w - 4.0, 0.0))
        y = max(top - text_h - 6.0, 0.0)
        draw.rectangle([x, y, x + text_w + 4, y + text_h + 4], fill=(20, 20, 24))
        draw.text((x + 2 - left, y + 2 - upper), text, fill=color, font=font)
    return shown


def compose(
    background: np.ndarray,
    calib: Calibration,
    layers: Sequence[BoxLayer],
) -> np.ndarray:
    """A copy of ``background (h, w, 3)`` uint8 with ``layers`` drawn in order (later on top)."""
    pil = Image.fromarray(np.array(background, dtype=np.uint8, copy=True))
    draw = ImageDraw.Draw(pil)
    size = pil.size
    for layer in layers:
        draw_box_layer(draw, layer, calib, size)
    return np.asarray(pil, dtype=np.uint8)
