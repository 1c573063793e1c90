"""A training frame with heights above the ground estimated from its own LiDAR cloud (issue 38).

A model whose ``PillarConfig.ground`` is ``estimated`` sees, at inference
(``TPCNet.encode_scene``), both clouds with ``z`` measured from the ground plane fitted to the
LiDAR cloud and that plane put ``ground_height`` below the origin
(:mod:`scenes.geometry.ground`). Training it must show it the same thing: :func:`level_item`
applies that shear to a :class:`~scenes.datasets.frames.FrameItem` after its augmentation (so a
drawn mounting-height offset is levelled away as a real one would be): both clouds, the actors'
boxes and the ignored boxes move by the plane's height under them; horizontal positions, sizes,
yaws, velocities and everything in the bird's-eye view (annotated regions, prompts) are unchanged.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from scenes.datasets.frames import FrameItem, shift_actor
from scenes.geometry.ground import level_clouds, level_points

__all__ = ["level_item"]


def level_item(item: FrameItem, reference_height: float) -> FrameItem:
    """``item`` with every height above the ground estimated from ``item.lidar`` and that ground
    at ``z = -reference_height`` (module docstring). A cloud with too few ground cells gets the
    level plane at the reference height (:func:`~scenes.geometry.ground.level_clouds`)."""
    plane, lidar, radar = level_clouds(item.lidar, item.radar, reference_height)
    actors = tuple(
        shift_actor(a, -float(plane.height_at(a.box[None, :2])[0]) - reference_height)
        for a in item.actors
    )
    ignore = item.ignore_boxes
    if ignore is not None:
        ignore = level_points(np.asarray(ignore, dtype=np.float64), plane, reference_height)
    return replace(item, lidar=lidar, radar=radar, actors=actors, ignore_boxes=ignore)
