"""Colour maps and legends of the app (pure numpy + Pillow; no matplotlib).

- LiDAR by height: a muted blue -> teal -> green -> sand ramp, so that the LiDAR reads as the
  background and the saturated radar colours stand out on the dark viewer.
- LiDAR by intensity: a grey ramp on ``sqrt(intensity / 255)`` (most returns are weak).
- Radar by compensated radial velocity ``v_r_compensated`` (m/s, LiDAR frame): a diverging map
  centred on zero. Negative values (the range shrinks: the object **approaches**) are blue, positive
  values (it **recedes**) red, static returns grey. Values beyond ``+-v_max`` saturate.
- Classes: one colour per class, shared by predicted boxes, the labelled objects and the heatmap
  (:attr:`scenes.geometry.classes.ObjectClass.color`, chosen so that any two of a class set, and
  each and the referents' :data:`GT_COLOR`, are told apart with normal vision, deuteranopia and
  protanopia: :mod:`app.view.color_vision`, ``tests/app/test_class_colors.py``); the referents of the
  frame's prompt or command use :data:`GT_COLOR` whatever their class.
- Depth (the camera panel's LiDAR overlay): warm near, cold far (:func:`depth_colors`), so that
  the depth ordering reads at a glance on a camera image of any colour.

Every map returns ``(N, 3)`` uint8 RGB, the format ``viser`` point clouds take.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from scenes.geometry.classes import PRESETS as CLASS_SETS

RGB = tuple[int, int, int]

HEIGHT_STOPS: tuple[RGB, ...] = (
    (52, 72, 140),
    (38, 140, 170),
    (92, 190, 130),
    (200, 210, 120),
    (245, 235, 200),
)
"""LiDAR height ramp, low to high (evenly spaced stops)."""

INTENSITY_STOPS: tuple[RGB, ...] = ((70, 70, 78), (255, 255, 255))
"""LiDAR intensity ramp, weak to strong."""

VELOCITY_STOPS: tuple[RGB, ...] = (
    (20, 90, 255),
    (110, 150, 235),
    (135, 135, 142),
    (235, 140, 110),
    (255, 40, 25),
)
"""Diverging radar map from ``-v_max`` (approaching, blue) over 0 (grey) to ``+v_max`` (red). The
static returns (most of a radar cloud) are a quiet grey, so that moving objects stand out."""

CLASS_COLORS: dict[str, RGB] = {c.name: c.color for s in CLASS_SETS.values() for c in s.classes}
"""Colour of each class of every class set (predicted boxes, labels, heatmap channels, the
legend): :attr:`scenes.geometry.classes.ObjectClass.color` by name."""

FALLBACK_COLOR: RGB = (200, 200, 200)
"""Colour of a class name that is not in :data:`CLASS_COLORS`."""

GT_COLOR: RGB = (110, 255, 110)
"""The referents among the ground truth (of the frame's prompt, or the command in play), whatever
their class."""

DEPTH_STOPS: tuple[RGB, ...] = (
    (255, 40, 40),
    (255, 190, 0),
    (90, 230, 90),
    (0, 200, 255),
    (120, 90, 255),
)
"""LiDAR depth ramp of the camera overlay, near (red) to far (violet)."""

DEPTH_RANGE = (2.0, 50.0)
"""Metres in front of the camera mapped to the ends of :data:`DEPTH_STOPS`."""


def class_color(name: str) -> RGB:
    """The colour of a class name (:data:`FALLBACK_COLOR` for unknown names)."""
    return CLASS_COLORS.get(name, FALLBACK_COLOR)


def lut_map(values: np.ndarray, lo: float, hi: float, stops: Sequence[RGB]) -> np.ndarray:
    """Map scalars linearly onto a piecewise-linear colour ramp.

    Args:
        values: ``(N,)`` scalars.
        lo, hi: The values mapped to the first and the last stop; outside values saturate.
        stops: ``S >= 2`` RGB colours, evenly spaced over ``[lo, hi]``.

    Returns:
        ``(N, 3)`` uint8 RGB.
    """
    if hi <= lo:
        raise ValueError(f"lut_map: hi ({hi}) must exceed lo ({lo})")
    table = np.asarray(stops, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] != 3 or len(table) < 2:
        raise ValueError(f"lut_map: stops must be (S >= 2, 3) RGB, got shape {table.shape}")
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    t = np.clip((v - lo) / (hi - lo), 0.0, 1.0) * (len(table) - 1)
    t = np.nan_to_num(t, nan=0.0)
    i0 = np.minimum(np.floor(t).astype(np.int64), len(table) - 2)
    frac = (t - i0)[:, None]
    rgb = table[i0] * (1.0 - frac) + table[i0 + 1] * frac
    return np.round(rgb).astype(np.uint8)


def height_colors(z: np.ndarray, z_min: float, z_max: float) -> np.ndarray:
    """LiDAR colours by height ``z`` (m, LiDAR frame) over ``[z_min, z_max]``; ``(N, 3)`` uint8."""
    return lut_map(z, z_min, z_max, HEIGHT_STOPS)


def intensity_colors(intensity: np.ndarray, max_intensity: float = 255.0) -> np.ndarray:
    """LiDAR colours by intensity (0..``max_intensity``, VoD scale), ``(N, 3)`` uint8.

    The ramp runs on ``sqrt(intensity / max_intensity)`` to spread the many weak returns.
    """
    scaled = np.sqrt(np.clip(np.asarray(intensity, dtype=np.float64) / max_intensity, 0.0, 1.0))
    return lut_map(scaled, 0.0, 1.0, INTENSITY_STOPS)


def velocity_colors(v_r_compensated: np.ndarray, v_max: float) -> np.ndarray:
    """Radar colours by compensated radial velocity (m/s; negative = approaching), ``(N, 3)``.

    ``-v_max`` maps to blue, 0 to grey and ``+v_max`` to red (saturating beyond).
    """
    if v_max <= 0:
        raise ValueError(f"velocity_colors: v_max must be positive, got {v_max}")
    return lut_map(v_r_compensated, -v_max, v_max, VELOCITY_STOPS)


def depth_colors(
    depth: np.ndarray, near: float = DEPTH_RANGE[0], far: float = DEPTH_RANGE[1]
) -> np.ndarray:
    """Colours of points by their depth in front of the camera (m), ``(N, 3)`` uint8; ``near``
    is red, ``far`` violet (saturating beyond)."""
    return lut_map(depth, near, far, DEPTH_STOPS)


def label_font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    """Pillow's default font at ``size`` px (the fixed bitmap font where FreeType is missing)."""
    return _font(size)


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except (OSError, TypeError):  # Pillow without FreeType: the fixed bitmap font.
        return ImageFont.load_default()


def colorbar_image(
    stops: Sequence[RGB],
    ticks: Sequence[str],
    caption_left: str = "",
    caption_right: str = "",
    *,
    width: int = 320,
    bar_height: int = 16,
    font_size: int = 13,
) -> np.ndarray:
    """A legend: a horizontal colour bar with evenly spaced tick labels and two captions.

    Args:
        stops: The ramp (as given to :func:`lut_map`), drawn left to right.
        ticks: Labels placed evenly under the bar, first at the left end, last at the right end.
        caption_left, caption_right: Text under the ticks, left- and right-aligned.

    Returns:
        ``(H, width, 3)`` uint8 RGB image (light text on a dark grey background).
    """
    margin = 8
    line = font_size + 4
    height = margin + bar_height + 4 + line + (line if caption_left or caption_right else 0) + 4
    image = Image.new("RGB", (width, height), (37, 38, 43))
    draw = ImageDraw.Draw(image)
    bar_w = width - 2 * margin
    ramp = lut_map(np.linspace(0.0, 1.0, bar_w), 0.0, 1.0, stops)
    bar = np.repeat(ramp[None], bar_height, axis=0)
    image.paste(Image.fromarray(bar, "RGB"), (margin, margin))
    font = _font(font_size)
    text_color = (230, 230, 230)
    y_ticks = margin + bar_height + 4
    for i, tick in enumerate(ticks):
        x = margin + (bar_w * i / (len(ticks) - 1) if len(ticks) > 1 else bar_w / 2)
        text_w = draw.textlength(tick, font=font)
        left = min(max(x - text_w / 2, 0), width - text_w)
        draw.line([(x, margin + bar_height), (x, margin + bar_height + 3)], fill=text_color)
        draw.text((left, y_ticks), tick, fill=text_color, font=font)
    y_caption = y_ticks + line
    if caption_left:
        draw.text((margin, y_caption), caption_left, fill=text_color, font=font)
    if caption_right:
        text_w = draw.textlength(caption_right, font=font)
        draw.text((width - margin - text_w, y_caption), caption_right, fill=text_color, font=font)
    return np.asarray(image, dtype=np.uint8)


def velocity_legend(v_max: float) -> np.ndarray:
    """Legend of :func:`velocity_colors`: m/s ticks, "approaching" (blue) and "receding" (red)."""
    half = v_max / 2
    ticks = [f"{-v_max:g}", f"{-half:g}", "0", f"+{half:g}", f"+{v_max:g} m/s"]
    return colorbar_image(VELOCITY_STOPS, ticks, "< approaching (blue)", "receding (red) >")


def height_legend(z_min: float, z_max: float) -> np.ndarray:
    """Legend of :func:`height_colors`: heights in metres above the ground estimate."""
    ticks = [f"{z_min:.1f}", f"{(z_min + z_max) / 2:.1f}", f"{z_max:.1f} m"]
    return colorbar_image(HEIGHT_STOPS, ticks, "LiDAR height above ground", "")


def intensity_legend() -> np.ndarray:
    """Legend of :func:`intensity_colors`."""
    return colorbar_image(INTENSITY_STOPS, ["0", "64", "255"], "LiDAR intensity (sqrt scale)", "")


def legend_swatches(
    count: int, *, width: int = 320, font_size: int = 13
) -> tuple[tuple[int, int, int, int], ...]:
    """Where :func:`class_legend` paints the swatches of ``count`` classes, two to a row: per
    class ``(x0, y0, x1, y1)``, image pixels, both ends inclusive (PIL's rectangle)."""
    margin, line, swatch = 8, font_size + 6, font_size
    column = (width - 2 * margin) // 2
    out = []
    for i in range(count):
        x = margin + (i % 2) * column
        y = margin + (i // 2) * line
        out.append((x, y + 2, x + swatch, y + 2 + swatch))
    return tuple(out)


def class_legend(names: Sequence[str], *, width: int = 320, font_size: int = 13) -> np.ndarray:
    """The legend of the box colours: a swatch of :func:`class_color` (at
    :func:`legend_swatches`) and the name of each class of ``names`` (the served model's class
    set), two to a row.

    Returns:
        ``(H, width, 3)`` uint8 RGB image (light text on a dark grey background).
    """
    margin, line = 8, font_size + 6
    rows = (len(names) + 1) // 2
    image = Image.new("RGB", (width, 2 * margin + rows * line), (37, 38, 43))
    draw = ImageDraw.Draw(image)
    font = _font(font_size)
    swatches = legend_swatches(len(names), width=width, font_size=font_size)
    for name, (x0, y0, x1, y1) in zip(names, swatches, strict=True):
        draw.rectangle([x0, y0, x1, y1], fill=class_color(name))
        draw.text((x1 + 6, y0 - 2), name, fill=(230, 230, 230), font=font)
    return np.asarray(image, dtype=np.uint8)
