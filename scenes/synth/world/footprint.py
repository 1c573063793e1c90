"""Bird's-eye-view footprints ``(x, y, l, w, yaw)`` that must not overlap (trunks, poles,
clutter, actors, the ego vehicle), and the overlap test used when placing things."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Obstacle:
    """A static footprint actors must not overlap: a BEV box ``(x, y, l, w, yaw)``."""

    x: float
    y: float
    l: float
    w: float
    yaw: float


def bev_overlap(a: np.ndarray, b: np.ndarray, margin: float) -> bool:
    """Separating-axis test of two BEV boxes ``(x, y, l, w, yaw)``, each grown by ``margin / 2``."""
    axes, halves = [], []
    for box in (a, b):
        c, s = math.cos(box[4]), math.sin(box[4])
        axes.append((np.array([c, s]), np.array([-s, c])))
        halves.append(((box[2] + margin) / 2, (box[3] + margin) / 2))
    d = np.array([b[0] - a[0], b[1] - a[1]])
    for ax_pair in axes:
        for axis in ax_pair:
            reach = 0.0
            for (ua, va), (hl, hw) in zip(axes, halves, strict=True):
                reach += hl * abs(axis @ ua) + hw * abs(axis @ va)
            if abs(axis @ d) > reach:
                return False
    return True


def overlaps_any(
    bev: np.ndarray, margin: float, taken: list[np.ndarray], taken_margin: list[float]
) -> bool:
    """Whether ``bev`` overlaps any taken box (bounding circles first, then the exact test)."""
    others = np.asarray(taken)
    margins = np.maximum(margin, np.asarray(taken_margin))
    reach = 0.5 * (np.hypot(bev[2], bev[3]) + np.hypot(others[:, 2], others[:, 3])) + margins
    near = np.hypot(others[:, 0] - bev[0], others[:, 1] - bev[1]) < reach
    return any(bev_overlap(bev, others[k], margins[k]) for k in np.flatnonzero(near))
