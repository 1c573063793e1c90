"""Augmentation consistency: each training view of a frame is the cloud and its pseudo-labels
transformed alike (ST3D trains on augmented views of its pseudo-labelled frames, so the detector
must find the same objects however the scene is turned).

A view (:class:`View`, drawn per frame and step from the run's seed by :func:`draw_view`) is, in
this order: an optional left-right flip (:func:`scenes.datasets.augment.mirror_points` /
``mirror_boxes``: ``y`` and ``yaw`` negated), a rotation by ``angle`` about the LiDAR's z axis and
a global scaling by ``scale`` about the LiDAR origin. Points ``(N, C)``: ``x, y, z`` move, the
other columns (intensity; radar RCS, radial velocities, time) stay as they are (a rotation about
the sensor keeps radial speeds, and the scaling is a few percent). Boxes ``(K, 7)``: centres move
as the points do, ``yaw`` turns by ``angle`` (wrapped to ``[-pi, pi)``), sizes scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.datasets.augment import mirror_boxes, mirror_points
from scenes.geometry.boxes import wrap_yaw


@dataclass(frozen=True)
class View:
    """One augmentation: ``flip`` (left-right), then ``angle`` (rad, about +z,
    counter-clockwise), then ``scale``."""

    flip: bool = False
    angle: float = 0.0
    scale: float = 1.0

    def points(self, points: np.ndarray) -> np.ndarray:
        """``(N, C)`` points (LiDAR frame, ``C >= 3``) of this view; dtype kept."""
        out = mirror_points(points) if self.flip else np.array(points, copy=True)
        c, s = np.cos(self.angle), np.sin(self.angle)
        x, y = out[:, 0].astype(np.float64), out[:, 1].astype(np.float64)
        out[:, 0] = (c * x - s * y) * self.scale
        out[:, 1] = (s * x + c * y) * self.scale
        out[:, 2] = out[:, 2] * self.scale
        return out

    def boxes(self, boxes: np.ndarray) -> np.ndarray:
        """``(K, 7)`` float64 boxes (LiDAR frame) of this view."""
        out = mirror_boxes(boxes) if self.flip else np.array(boxes, np.float64).reshape(-1, 7)
        out = out.copy()
        c, s = np.cos(self.angle), np.sin(self.angle)
        x, y = out[:, 0].copy(), out[:, 1].copy()
        out[:, 0] = (c * x - s * y) * self.scale
        out[:, 1] = (s * x + c * y) * self.scale
        out[:, 2] *= self.scale
        out[:, 3:6] *= self.scale
        out[:, 6] = wrap_yaw(out[:, 6] + self.angle)
        return out


def draw_view(
    rng: np.random.Generator,
    flip_probability: float,
    max_rotation: float,
    scale_range: tuple[float, float],
) -> View:
    """A random :class:`View`: a flip with ``flip_probability``, an angle uniform in
    ``+-max_rotation``, a scale uniform in ``scale_range``."""
    flip = bool(rng.random() < flip_probability)
    angle = float(rng.uniform(-max_rotation, max_rotation))
    scale = float(rng.uniform(*scale_range))
    return View(flip, angle, scale)


__all__ = ["View", "draw_view"]
