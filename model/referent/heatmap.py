"""The answer's heatmap: what the app shows of a referent-path answer.

The detector's class heatmaps kept where a candidate the sentence refers to sits: a Gaussian at
each candidate's anchor cell, weighted by its referent probability, so that a person sees where
the answer is and how sure it is (:func:`referent_heatmap`).

Everything but the probabilities belongs to the scene: :class:`ReferentCanvas` computes it once
(the shading from the detector's heatmaps, each candidate's Gaussian window) and
:meth:`ReferentCanvas.draw` adds a prompt's probabilities, so that the referent head pays for the
windows once per scene rather than once per prompt (issue 20). Drawing on a canvas gives the
same bits as :func:`referent_heatmap` on the same probabilities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from model.core.anchors import anchor_points
from model.core.grid import BevGrid

_FLOAT32_ZERO = 151 * math.log(2.0)
"""``-ln`` of a value (``2**-151``) below half the smallest float32 subnormal: it rounds to 0."""

SIGMA_CELLS = 1.5
"""Width (cells) of the Gaussian drawn at each candidate's anchor cell."""


def _gaussian_radius(p_max: float, sigma_cells: float) -> int:
    """Cells beyond which ``p * exp(-d^2 / (2 sigma^2))`` rounds to 0 in float32 for every
    ``p <= p_max`` (at least 0; one cell more than needed, against rounding)."""
    d2 = 2 * sigma_cells**2 * (_FLOAT32_ZERO + math.log(max(p_max, 1e-300)))
    return int(math.ceil(math.sqrt(max(d2, 0.0)))) + 1


@dataclass(frozen=True)
class ReferentCanvas:
    """The text-free part of one scene's answer heatmap (build it with :meth:`of`).

    Attributes:
        shading: ``(3, H, W)`` float32: the detector's heatmap relative to its peak per class,
            ``0.5 + 0.5 * detection / peak`` (half from it: bright at the referred objects).
        windows: ``(K, S, S)`` float64, ``exp(-d^2 / (2 sigma^2))`` on the ``S = 2 R + 1``
            cells around each candidate's anchor cell, rows ``y`` then columns ``x``; ``R`` is
            the radius beyond which ``p * window`` rounds to 0 in float32 for every
            ``p <= p_max``.
        rows, cols: ``(K,)`` int64: where each window starts on a canvas padded by ``S`` cells
            on every side.
        labels: ``(K,)`` class indices.
        inside: ``(K,)`` bool: whether the window reaches the grid at all.
        p_max: The largest probability :meth:`draw` accepts.
    """

    shading: np.ndarray
    windows: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    labels: np.ndarray
    inside: np.ndarray
    p_max: float

    @classmethod
    def of(
        cls,
        detection: np.ndarray,
        boxes: np.ndarray,
        labels: np.ndarray,
        grid: BevGrid,
        anchor: str,
        sigma_cells: float = SIGMA_CELLS,
        p_max: float = 1.0,
    ) -> ReferentCanvas:
        """The canvas of ``K`` candidates: ``detection (3, H, W)`` sigmoid heatmaps of the
        text-agnostic detector on ``grid``, ``boxes (K, 7)`` (LiDAR frame) and ``labels (K,)``,
        the head's ``anchor`` kind; ``p_max``: the largest probability it will draw."""
        _, h, w = detection.shape
        labels = np.asarray(labels).reshape(-1)
        peak = np.maximum(detection.reshape(detection.shape[0], -1).max(axis=1), 1e-6)
        shading = 0.5 + 0.5 * detection / peak[:, None, None]
        radius = _gaussian_radius(p_max, sigma_cells)
        size = 2 * radius + 1
        k = len(labels)
        if k == 0:
            empty = np.zeros(0, dtype=np.int64)
            return cls(shading, np.zeros((0, size, size)), empty, empty, labels, empty > 0, p_max)
        cells = grid.xy_to_cell(anchor_points(np.asarray(boxes).reshape(-1, 7), anchor))
        # Candidate k only reaches the grid columns x0[k] - radius .. x0[k] + radius around its
        # anchor cell (beyond, its value rounds to 0 in float32), and the same rows: a window of
        # size x size cells, drawn on a canvas padded by `size` cells on every side.
        x0 = np.floor(cells[:, 0]).astype(np.int64)
        y0 = np.floor(cells[:, 1]).astype(np.int64)
        inside = (x0 > -radius - 1) & (x0 < w + radius) & (y0 > -radius - 1) & (y0 < h + radius)
        offsets = np.arange(size) - radius + 0.5
        # exp(-d2 / (2 sigma^2)), element for element the same operations as on the whole grid
        # (-d2 / s is d2 / -s exactly).
        dx2 = ((x0[:, None] + offsets[None, :]) - cells[:, 0, None]) ** 2
        dy2 = ((y0[:, None] + offsets[None, :]) - cells[:, 1, None]) ** 2
        windows = np.add(dx2[:, None, :], dy2[:, :, None])
        np.divide(windows, -2 * sigma_cells**2, out=windows)
        np.exp(windows, out=windows)
        return cls(shading, windows, y0 + radius + 1, x0 + radius + 1, labels, inside, float(p_max))

    def draw(self, probabilities: np.ndarray) -> np.ndarray:
        """The answer's heatmap ``(3, H, W)`` in ``[0, 1]`` for referent probabilities ``(K,)``
        (each at most :attr:`p_max`): for each class, the largest ``p_k * window_k`` over the
        class's candidates, times :attr:`shading`."""
        probabilities = np.asarray(probabilities, dtype=np.float64).reshape(-1)
        if len(probabilities) != len(self.labels):
            raise ValueError(
                f"{len(probabilities)} probabilities for a canvas of {len(self.labels)} candidates"
            )
        if len(probabilities) and float(probabilities.max()) > self.p_max:
            raise ValueError(f"a probability above this canvas's p_max {self.p_max}")
        _, h, w = self.shading.shape
        size = self.windows.shape[1]
        weight = np.zeros(self.shading.shape, dtype=np.float32)
        # (a candidate of probability 0 adds only zeros: left out)
        drawn = self.inside & (probabilities > 0)
        for c in range(weight.shape[0]):
            mine = np.flatnonzero((self.labels == c) & drawn)
            if not len(mine):
                continue
            # p_k * window_k rounded to float32 as it is stored (the class maximum is taken after
            # the rounding: it is monotone)
            scaled = np.empty((len(mine), size, size), dtype=np.float32)
            np.multiply(
                self.windows[mine], probabilities[mine, None, None], out=scaled, casting="same_kind"
            )
            canvas = np.zeros((h + 2 * size, w + 2 * size), dtype=np.float32)
            rows, cols = self.rows[mine].tolist(), self.cols[mine].tolist()
            for k, (row, col) in enumerate(zip(rows, cols, strict=True)):
                view = canvas[row : row + size, col : col + size]
                np.maximum(view, scaled[k], out=view)
            weight[c] = canvas[size : size + h, size : size + w]
        return np.clip(weight * self.shading, 0.0, 1.0).astype(np.float32)


def referent_heatmap(
    detection: np.ndarray,
    boxes: np.ndarray,
    labels: np.ndarray,
    probabilities: np.ndarray,
    grid: BevGrid,
    anchor: str,
    sigma_cells: float = SIGMA_CELLS,
) -> np.ndarray:
    """The answer's heatmap ``(3, H, W)`` in ``[0, 1]`` (:meth:`ReferentCanvas.draw` on a
    canvas made for these candidates).

    Args:
        detection: ``(3, H, W)`` sigmoid heatmaps of the text-agnostic detector on ``grid``.
        boxes: ``(K, 7)`` candidates; labels ``(K,)``; probabilities ``(K,)`` referent scores.
        grid: The head grid; anchor: the head's anchor kind.
        sigma_cells: Width of the Gaussian drawn at each candidate's anchor cell.

    Returns:
        For each class, the largest ``p_k * gaussian_k`` over the class's candidates, shaded by
        the detector's heatmap (half from it, relative to its peak): bright at the referred
        objects, dark elsewhere.
    """
    probabilities = np.asarray(probabilities, dtype=np.float64).reshape(-1)
    p_max = float(probabilities.max()) if len(probabilities) else 0.0
    canvas = ReferentCanvas.of(detection, boxes, labels, grid, anchor, sigma_cells, p_max)
    return canvas.draw(probabilities)


__all__ = ["SIGMA_CELLS", "ReferentCanvas", "referent_heatmap"]
