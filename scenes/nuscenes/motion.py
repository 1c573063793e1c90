"""The ground velocity of a nuScenes annotation, where the release lets one know it.

A nuScenes ``sample_annotation`` holds no velocity. Talk2Car's commands speak of motion ("the
approaching cyclist", "the car driving away from us faster than 30 km/h"), and label prompts
(:func:`model.training.referent_step.frame_prompts`) may speak of it only where every actor's
motion is known. Three sources, tried in this order for each annotation:

1. **A stationary attribute** (:data:`STATIONARY_ATTRIBUTES`: parked, stopped, standing, sitting
   or lying down, a bicycle without rider): zero.
2. **Its neighbours in time** (as the devkit's ``box_velocity``): the same instance's ``prev``
   and ``next`` annotations, the global centre's difference over the samples' timestamps (both
   neighbours when both exist, else one and this one), if the two are at most
   :data:`MAX_TIME_GAP` apart and the speed at most :data:`MAX_SPEED` (a root whose samples'
   global poses are drawn independently, as some converters write them, gives absurd speeds).
   Exact up to the annotators' boxes (``NuScenesRoot.neighbour_velocities``).
3. **The radar** (:func:`radar_velocity`): the median ego-compensated radial speed of the radar
   points of the key sweep (``time`` 0) in the box grown by :data:`RADAR_MARGIN`, resolved
   along the box's heading where the heading is at most 60 degrees off the line of sight
   (:data:`MIN_HEADING_COSINE`); an object moving across the line of sight, or without radar
   points, stays unknown. A radar measures only the radial speed, and a road user moves along
   its heading, so the estimate is ``v_r / cos(angle)`` along the heading.

Velocities are in the model frame (x forward, y left; m/s), ground velocities (ego motion
removed), as :class:`scenes.geometry.actors.Actor` holds them; unknown ones are NaN.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from scenes.geometry.boxes import points_in_footprints

__all__ = [
    "MAX_SPEED",
    "MAX_TIME_GAP",
    "MIN_HEADING_COSINE",
    "RADAR_MARGIN",
    "STATIONARY_ATTRIBUTES",
    "attribute_velocity",
    "combine",
    "radar_velocity",
]

STATIONARY_ATTRIBUTES = frozenset(
    {
        "vehicle.parked",
        "vehicle.stopped",
        "pedestrian.standing",
        "pedestrian.sitting_lying_down",
        "cycle.without_rider",
    }
)
"""nuScenes attributes that say an object does not move."""

MAX_TIME_GAP = 1.5
"""Seconds: neighbours further apart in time give no velocity (the devkit's default)."""

RADAR_MARGIN = 0.5
"""Metres the box grows by, in length and width each side, to collect its radar points (a
radar's positions scatter by a few decimetres, and its z is the mounting height: z is not
checked)."""

MIN_HEADING_COSINE = 0.5
"""Below this ``|cos|`` of the angle between heading and line of sight, the radial speed says
too little of the speed along the heading: the radar estimate is left unknown."""

MAX_SPEED = 40.0
"""m/s: an estimate above it is left unknown (radar: a point of another object, or noise;
neighbours: global poses that do not hold one world together)."""


def attribute_velocity(attributes: Sequence[Sequence[str]]) -> np.ndarray:
    """``(K, 2)`` float64: zero where an annotation's attributes say it stands still
    (:data:`STATIONARY_ATTRIBUTES`), NaN elsewhere."""
    out = np.full((len(attributes), 2), np.nan)
    for i, names in enumerate(attributes):
        if STATIONARY_ATTRIBUTES.intersection(names):
            out[i] = 0.0
    return out


def radar_velocity(boxes: np.ndarray, radar: np.ndarray) -> np.ndarray:
    """``(K, 2)`` float64 the radar estimate of each box's ground velocity (module docstring),
    NaN where unknown.

    Args:
        boxes: ``(K, 7)`` model frame ``x, y, z, l, w, h, yaw``.
        radar: ``(M, 7)`` model frame ``x, y, z, rcs, v_r, v_r_compensated, time``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    radar = np.asarray(radar, dtype=np.float64).reshape(-1, 7)
    out = np.full((len(boxes), 2), np.nan)
    key = radar[radar[:, 6] == 0]
    if not len(boxes) or not len(key):
        return out
    inside = points_in_footprints(key, boxes, RADAR_MARGIN).T  # (K, M)
    for k in np.flatnonzero(inside.any(axis=1)):
        v_r = float(np.median(key[inside[k], 5]))
        centre = boxes[k, :2]
        distance = float(np.hypot(*centre))
        if distance < 1e-6:
            continue
        heading = np.array([np.cos(boxes[k, 6]), np.sin(boxes[k, 6])])
        cosine = float(heading @ (centre / distance))
        if abs(cosine) < MIN_HEADING_COSINE:
            continue
        speed = v_r / cosine
        if abs(speed) <= MAX_SPEED:
            out[k] = speed * heading
    return out


def combine(*estimates: np.ndarray) -> np.ndarray:
    """``(K, 2)``: per row, the first estimate that is known (not NaN), in the order given."""
    out = np.full_like(estimates[0], np.nan)
    for e in estimates:
        unknown = np.isnan(out).any(axis=1)
        out[unknown] = e[unknown]
    return out
