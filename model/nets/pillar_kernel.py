"""The pillar encoder of one cloud at inference, as one compiled pass over the points (issue 20).

:class:`model.nets.pillars.PillarEncoder` groups a cloud into pillars with array passes (a range
mask, a sort of the cell keys, gathers, a scatter of the per-point maxima): on a full
View-of-Delft spin of ~190k LiDAR points that is some twenty passes over arrays of the cloud's
size and 5-9 ms, for a few million multiply-adds. Here the same arithmetic is one loop over the
points, compiled by numba (a pinned wheel; compiled on first use and cached beside this file):

1. each point in range (the grid's x/y range and ``[z_min, z_max)``, tested and binned in float32
   as :func:`model.nets.pillars.voxelize` does) finds its pillar; the first ``max_points`` of a
   pillar in input order are kept, and each kept point adds its ``x, y, z`` to the pillar's sum
   and takes part in the max of the PFN's linear map ``M p`` over the pillar's points;
2. each pillar's value is ``ReLU(BN((max M p - W_mean mean - W_centre centre) * sign))``, the
   eval-mode factorisation of :meth:`model.nets.pillars.PillarEncoder._pooled_eval` (its
   docstring says why it equals the per-point form), written into the canvas.

The same values as the array form up to float rounding (the products' and the BatchNorm's
summation order); the tests hold it to the module form. Per-thread scratch arrays the size of
the grid are kept between calls, so that a call allocates nothing but the canvas it returns.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np
import torch
from numba import njit
from torch import Tensor

_FASTMATH = {"nnan", "ninf", "nsz", "contract"}
"""No NaN or infinity (the points are checked finite, the weights are a checkpoint's), signless
zeros, fused multiply-adds: the vectorised max and products; no reassociation, so each pillar's
sum keeps the points' order."""


@njit(nogil=True, cache=True, fastmath=_FASTMATH)
def _encode(  # pragma: no cover - compiled; its Python body is what numba compiles
    canvas, slot, keys, counts, sums, maxima, points, bounds, cell, nx, max_points, weights_t,
    pillar_weights, sign, scale, shift, z_centre,
):  # fmt: skip
    n, features = points.shape
    channels = weights_t.shape[1]
    x_min, x_max, y_min, y_max, z_min, z_max = (
        bounds[0], bounds[1], bounds[2], bounds[3], bounds[4], bounds[5],
    )  # fmt: skip
    ny = slot.shape[0] // nx
    h = np.empty(channels, np.float32)
    pillars = 0
    for i in range(n):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        if not (x >= x_min and x < x_max and y >= y_min and y < y_max and z >= z_min):
            continue
        if not z < z_max:
            continue
        col = int(math.floor((x - x_min) / cell))
        row = int(math.floor((y - y_min) / cell))
        if col < 0 or col >= nx or row < 0 or row >= ny:  # (rounding at the far edges)
            continue
        key = row * nx + col
        p = slot[key]
        if p < 0:
            p = pillars
            pillars += 1
            slot[key] = p
            keys[p] = key
            counts[p] = 0
            sums[p, 0] = 0.0
            sums[p, 1] = 0.0
            sums[p, 2] = 0.0
            for c in range(channels):
                maxima[p, c] = -3.0e38
        if counts[p] >= max_points:
            continue
        counts[p] += 1
        sums[p, 0] += x
        sums[p, 1] += y
        sums[p, 2] += z
        first = points[i, 0]
        for c in range(channels):
            h[c] = weights_t[0, c] * first
        for f in range(1, features):
            value = points[i, f]
            for c in range(channels):
                h[c] += weights_t[f, c] * value
        for c in range(channels):
            maxima[p, c] = max(maxima[p, c], h[c])
    half = np.float32(0.5)
    for p in range(pillars):
        key = keys[p]
        n_p = np.float32(counts[p])
        mx, my, mz = sums[p, 0] / n_p, sums[p, 1] / n_p, sums[p, 2] / n_p
        cx = x_min + (np.float32(key % nx) + half) * cell
        cy = y_min + (np.float32(key // nx) + half) * cell
        for c in range(channels):
            w = pillar_weights[c]
            term = w[0] * mx + w[1] * my + w[2] * mz + w[3] * cx + w[4] * cy + w[5] * z_centre
            value = (maxima[p, c] - term) * sign[c] * scale[c] + shift[c]
            canvas[c, key] = max(value, np.float32(0.0))
        slot[key] = -1  # (the scratch is left as it was found)
    return pillars


@dataclass(frozen=True)
class PillarWeights:
    """An eval-mode PFN's weights as :func:`encode_cloud` reads them (float32, contiguous).

    Attributes:
        raw_t: ``(F, C)``: the linear map of a raw point, ``M^T`` (sign-flipped channels,
            feature scale and the offsets' xyz columns folded in).
        pillar: ``(C, 6)``: ``[W_mean, W_centre]`` (sign-flipped), the per-pillar term.
        sign, scale, shift: ``(C,)``: each channel's sign flip and its BatchNorm as ``a x + b``.
    """

    raw_t: np.ndarray
    pillar: np.ndarray
    sign: np.ndarray
    scale: np.ndarray
    shift: np.ndarray


_SCRATCH = threading.local()


def _scratch(cells: int, channels: int) -> tuple[np.ndarray, ...]:
    """This thread's scratch arrays for a grid of ``cells`` (the slot of each cell is -1 between
    calls)."""
    kept = getattr(_SCRATCH, "arrays", None)
    if kept is None or kept[0].shape[0] != cells or kept[4].shape[1] != channels:
        kept = (
            np.full(cells, -1, np.int32),
            np.empty(cells, np.int32),
            np.empty(cells, np.int32),
            np.empty((cells, 3), np.float32),
            np.empty((cells, channels), np.float32),
        )
        _SCRATCH.arrays = kept
    return kept


def encode_cloud(
    points: Tensor,
    weights: PillarWeights,
    bounds: tuple[float, float, float, float, float, float],
    cell: float,
    shape: tuple[int, int],
    max_points: int,
) -> Tensor:
    """The canvas ``(1, C, H, W)`` of one cloud ``points (N, F)`` (CPU, finite, LiDAR frame).

    Args:
        weights: :class:`PillarWeights` of the encoder.
        bounds: ``(x_min, x_max, y_min, y_max, z_min, z_max)`` of the kept points.
        cell: The grid's cell size (m); shape: its ``(H, W)``.
        max_points: Points kept per pillar (the first in input order).
    """
    ny, nx = shape
    channels = weights.sign.shape[0]
    pts = np.ascontiguousarray(points.detach().numpy(), dtype=np.float32)
    canvas = torch.zeros(channels, ny * nx)
    limits = np.asarray(bounds, dtype=np.float32)
    _encode(
        canvas.numpy(), *_scratch(ny * nx, channels), pts, limits, np.float32(cell), nx,
        max_points, weights.raw_t, weights.pillar, weights.sign, weights.scale, weights.shift,
        np.float32(0.5 * (bounds[4] + bounds[5])),
    )  # fmt: skip
    return canvas.view(1, channels, ny, nx)


__all__ = ["PillarWeights", "encode_cloud"]
