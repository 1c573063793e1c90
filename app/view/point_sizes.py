"""Point sizes that stay legible from every viewpoint: :class:`LegibleSizes`.

viser 1.1.1 draws a point cloud's points with one size in metres, perspective-attenuated: a point
``z`` metres in front of the camera is ``size * H / (tan(fov / 2) * z)`` pixels across on a view
``H`` pixels tall (its client's point shader). From the bird's eye (70 m up) a 0.2 m radar disc is
a few pixels; from the frame's camera (the View tab's *Camera* preset) the returns a metre or two
ahead become discs hundreds of pixels wide that cover the view.

So each browser's sizes follow its camera: the size drawn is the size chosen in the View tab, but
never more than makes the nearest :data:`NEAR_SHARE` of the cloud's points in front of the camera
:data:`MAX_POINT_PX` pixels across (a cap from a fixed sample of the cloud, recomputed when the
camera moves and sent only when it changes by more than :data:`RESEND_RATIO`). Far from the
points (the BEV and chase presets) the cap is above the chosen size and nothing changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import viser

MAX_POINT_PX = 16.0
"""Pixels across that the nearest points of a cloud may reach (a radar disc a finger wide at
arm's length on a laptop screen: legible, never a ball that hides what is behind it)."""

NEAR_SHARE = 0.1
"""The share of a cloud's points in front of the camera held to :data:`MAX_POINT_PX` (the
nearest 10 %: a few stray returns at the bumper do not shrink the whole cloud)."""

SAMPLE_POINTS = 4096
"""Points of a cloud the cap is computed from (a fixed sample, so that a camera move costs a
fraction of a millisecond whatever the cloud's size)."""

RESEND_RATIO = 1.1
"""A new size is sent to the browser when it differs from the one drawn by more than this factor."""

NEAR_DEPTH = 0.1
"""Points less than this many metres in front of the camera are ignored (the near clip)."""


@dataclass(frozen=True)
class Eye:
    """A browser's camera as the cap needs it.

    Attributes:
        position: ``(3,)`` LiDAR frame.
        forward: ``(3,)`` unit viewing direction.
        tan_half_fov: ``tan`` of half the vertical field of view.
        height_px: The view's height in pixels.
    """

    position: np.ndarray
    forward: np.ndarray
    tan_half_fov: float
    height_px: float

    @classmethod
    def of(cls, camera: viser.CameraHandle) -> Eye | None:
        """The eye of viser's camera handle (None: a degenerate camera)."""
        position = np.asarray(camera.position, dtype=np.float64)
        forward = np.asarray(camera.look_at, dtype=np.float64) - position
        norm = float(np.linalg.norm(forward))
        height = float(camera.image_height or 0)
        if norm < 1e-9 or height <= 0 or not 0 < camera.fov < math.pi:
            return None
        return cls(position, forward / norm, math.tan(camera.fov / 2.0), height)


def size_cap(points: np.ndarray, eye: Eye) -> float | None:
    """The largest point size (m) at which the nearest :data:`NEAR_SHARE` of ``points``
    ``(N, 3)`` in front of ``eye`` are at most :data:`MAX_POINT_PX` pixels across (None: no
    point in front)."""
    depth = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - eye.position) @ eye.forward
    front = depth[depth > NEAR_DEPTH]
    if not len(front):
        return None
    near = float(np.quantile(front, NEAR_SHARE))
    return MAX_POINT_PX * eye.tan_half_fov * near / eye.height_px


class LegibleSizes:
    """The point sizes of one browser's clouds, held legible from its camera (see the module
    docstring). Not thread-safe by itself: the session calls it holding its lock.
    """

    def __init__(self, seed: int = 0) -> None:
        self._rng = np.random.default_rng(seed)
        self._eye: Eye | None = None
        self._clouds: dict[str, tuple[viser.PointCloudHandle, np.ndarray, float]] = {}

    def add(self, handle: viser.PointCloudHandle, points: np.ndarray, wanted: float) -> None:
        """Follow a new cloud (replacing the one of the same name): ``points`` ``(N, 3)``, the
        size chosen for it ``wanted``; its size is set for the camera now."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(pts) > SAMPLE_POINTS:
            pts = pts[self._rng.choice(len(pts), SAMPLE_POINTS, replace=False)]
        self._clouds[handle.name] = (handle, pts, float(wanted))
        self._apply(handle.name)

    def want(self, handle: viser.PointCloudHandle, wanted: float) -> None:
        """The size chosen for a followed cloud changed (the View tab's slider)."""
        found = self._clouds.get(handle.name)
        if found is not None:
            self._clouds[handle.name] = (found[0], found[1], float(wanted))
            self._apply(handle.name)

    def view_from(self, eye: Eye | None) -> None:
        """The camera moved: the sizes for it."""
        self._eye = eye
        for name in list(self._clouds):
            self._apply(name)

    def size(self, name: str) -> float | None:
        """The size a followed cloud is drawn with (None: not followed)."""
        found = self._clouds.get(name)
        return None if found is None else float(found[0].point_size)

    def _apply(self, name: str) -> None:
        handle, sample, wanted = self._clouds[name]
        cap = size_cap(sample, self._eye) if self._eye is not None else None
        size = wanted if cap is None else min(wanted, cap)
        drawn = float(handle.point_size)
        if drawn <= 0 or max(size / drawn, drawn / size) > RESEND_RATIO or size == wanted != drawn:
            handle.point_size = size


__all__ = ["MAX_POINT_PX", "NEAR_SHARE", "Eye", "LegibleSizes", "size_cap"]
