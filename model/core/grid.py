"""The bird's-eye-view grid shared by the pillar encoders, the head's targets and decoding.

Frame: LiDAR (x forward, y left). The canvas of shape ``(H, W)`` = ``(ny, nx)`` stores row index
``iy`` along +y and column index ``ix`` along +x, i.e. ``canvas[:, iy, ix]``: cell ``(iy, ix)``
covers ``x in [x_min + ix * cell, x_min + (ix + 1) * cell)`` and likewise for y. This matches the
pillar scatter of PointPillars ("x index -> width, y index -> height").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BevGrid:
    """An axis-aligned BEV grid in the LiDAR frame.

    Attributes:
        x_min, x_max, y_min, y_max: The covered range in metres.
        cell: Cell edge length in metres (square cells).
    """

    x_min: float = 0.0
    x_max: float = 51.2
    y_min: float = -25.6
    y_max: float = 25.6
    cell: float = 0.32

    def __post_init__(self) -> None:
        if self.cell <= 0 or self.x_max <= self.x_min or self.y_max <= self.y_min:
            raise ValueError(f"invalid BevGrid {self}")
        for extent, name in ((self.x_max - self.x_min, "x"), (self.y_max - self.y_min, "y")):
            n = extent / self.cell
            if abs(n - round(n)) > 1e-6:
                raise ValueError(
                    f"BevGrid {name} extent {extent} is not a multiple of cell {self.cell}"
                )

    @property
    def nx(self) -> int:
        """Number of columns (cells along x)."""
        return int(round((self.x_max - self.x_min) / self.cell))

    @property
    def ny(self) -> int:
        """Number of rows (cells along y)."""
        return int(round((self.y_max - self.y_min) / self.cell))

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` = ``(ny, nx)``."""
        return (self.ny, self.nx)

    def downsample(self, stride: int) -> BevGrid:
        """The grid of a feature map ``stride`` times coarser over the same range."""
        return BevGrid(self.x_min, self.x_max, self.y_min, self.y_max, self.cell * stride)

    def xy_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """Continuous cell coordinates ``(..., 2)`` as ``(col, row)`` floats for points ``(..., 2)``.

        ``floor`` of the result is the integer cell; the fractional part is the sub-cell offset.
        """
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[..., 0] - self.x_min) / self.cell
        row = (xy[..., 1] - self.y_min) / self.cell
        return np.stack([col, row], axis=-1)

    def cell_to_xy(self, colrow: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`xy_to_cell`: metric ``(x, y)`` for continuous ``(col, row)``."""
        colrow = np.asarray(colrow, dtype=np.float64)
        x = colrow[..., 0] * self.cell + self.x_min
        y = colrow[..., 1] * self.cell + self.y_min
        return np.stack([x, y], axis=-1)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Boolean mask ``(...)`` of points strictly inside the grid's range."""
        xy = np.asarray(xy, dtype=np.float64)
        return (
            (xy[..., 0] >= self.x_min)
            & (xy[..., 0] < self.x_max)
            & (xy[..., 1] >= self.y_min)
            & (xy[..., 1] < self.y_max)
        )
