"""The C3D-RECHead heatmap as a translucent RGBA image lying on the ground.

The head's heatmaps are ``(3, H, W)`` sigmoid scores on its BEV grid (:class:`model.GridExtent`,
the grid type the app reads; the model's ``BevGrid`` has it:
``heatmaps[c, iy, ix]``, row ``iy`` along +y, column ``ix`` along +x, LiDAR frame). One image
shows all three classes: each cell takes the colour of its highest-scoring class
(:func:`app.view.colors.class_color` of the served model's classes) and an alpha of ``opacity * score``, so empty cells are clear.

Placement: viser draws an image in its node's local XY plane with image columns along +x and
rows (downwards) along +y, centred on the node's position. A ``[iy, ix]`` grid is therefore passed
unchanged, ``render_width`` is the grid's x extent, ``render_height`` its y extent, and the node
sits at the grid's centre a few centimetres above the ground estimate (no z-fighting with the
ground points). The image is sent as PNG (the only format with alpha).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import viser

from app.view.colors import RGB, class_color
from model import GridExtent
from scenes.geometry.classes import VOD

GROUND_LIFT = 0.05
"""Metres between the ground estimate and the heatmap plane."""


@dataclass(frozen=True)
class Placement:
    """Where the heatmap image lies: centre ``position`` (LiDAR frame) and its size in metres."""

    position: tuple[float, float, float]
    render_width: float
    render_height: float


def ground_placement(grid: GridExtent, ground_z: float, lift: float = GROUND_LIFT) -> Placement:
    """The placement of a heatmap on ``grid`` lying ``lift`` metres above ``ground_z``."""
    return Placement(
        position=(
            (grid.x_min + grid.x_max) / 2.0,
            (grid.y_min + grid.y_max) / 2.0,
            ground_z + lift,
        ),
        render_width=grid.x_max - grid.x_min,
        render_height=grid.y_max - grid.y_min,
    )


def heatmap_rgba(
    heatmaps: np.ndarray,
    opacity: float,
    colors: Sequence[RGB] | None = None,
) -> np.ndarray:
    """Colour a stack of per-class heatmaps into one RGBA image.

    Args:
        heatmaps: ``(C, H, W)`` scores in ``[0, 1]`` (values outside are clipped), ``[c, iy, ix]``.
        opacity: Global opacity in ``[0, 1]``; a cell's alpha is ``255 * opacity * max_c score``.
        colors: ``C`` RGB colours; default: the class colours of the ``vod`` class set (a
            three-channel stack).

    Returns:
        ``(H, W, 4)`` uint8 RGBA, row ``iy``, column ``ix`` (pass it to viser unchanged).
    """
    heat = np.clip(np.nan_to_num(np.asarray(heatmaps, dtype=np.float32)), 0.0, 1.0)
    if heat.ndim != 3:
        raise ValueError(f"heatmaps must be (C, H, W), got shape {heat.shape}")
    palette = np.asarray(
        colors if colors is not None else [class_color(c) for c in VOD.names], dtype=np.uint8
    ).reshape(-1, 3)
    if len(palette) != heat.shape[0]:
        raise ValueError(f"{heat.shape[0]} heatmap channels but {len(palette)} colours")
    best = heat.argmax(axis=0)
    score = heat.max(axis=0)
    alpha = np.round(255.0 * float(np.clip(opacity, 0.0, 1.0)) * score).astype(np.uint8)
    return np.concatenate([palette[best], alpha[..., None]], axis=-1)


class HeatmapView:
    """The heatmap image node ``name`` of one scene API (``client.scene`` per browser).

    :meth:`show` keeps the scores so that :meth:`set_opacity` can recolour without the model.
    """

    def __init__(
        self, scene: viser.SceneApi, name: str = "/heatmap", classes: Sequence[str] = VOD.names
    ) -> None:
        self.scene = scene
        self.name = name
        self.colors = [class_color(c) for c in classes]
        """A colour per heatmap channel: the served model's classes in channel order."""
        self._handle: viser.ImageHandle | None = None
        self._heatmaps: np.ndarray | None = None
        self._opacity = 0.7
        self._visible = True

    @property
    def shown(self) -> bool:
        """Whether an image node exists."""
        return self._handle is not None

    def show(self, heatmaps: np.ndarray, grid: GridExtent, ground_z: float, opacity: float) -> None:
        """Draw ``heatmaps (C, H, W)`` on ``grid`` (LiDAR frame) just above ``ground_z``."""
        self._heatmaps = np.asarray(heatmaps, dtype=np.float32)
        self._opacity = float(opacity)
        place = ground_placement(grid, ground_z)
        rgba = heatmap_rgba(self._heatmaps, self._opacity, self.colors)
        self.clear_node()
        self._handle = self.scene.add_image(
            self.name,
            rgba,
            render_width=place.render_width,
            render_height=place.render_height,
            format="png",
            cast_shadow=False,
            receive_shadow=False,
            position=place.position,
            visible=self._visible,
        )

    def set_opacity(self, opacity: float) -> None:
        """Recolour the shown heatmap with a new global opacity."""
        self._opacity = float(opacity)
        if self._handle is not None and self._heatmaps is not None:
            self._handle.image = heatmap_rgba(self._heatmaps, self._opacity, self.colors)

    @property
    def visible(self) -> bool:
        return self._visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self._visible = bool(value)
        if self._handle is not None:
            self._handle.visible = self._visible

    def clear_node(self) -> None:
        if self._handle is not None:
            self._handle.remove()
            self._handle = None

    def clear(self) -> None:
        """Remove the image and forget the scores."""
        self.clear_node()
        self._heatmaps = None
