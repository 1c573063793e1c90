"""A synthetic world a moment later: the next frames of a drive (``--sequence-length``).

A :class:`~scenes.synth.world.World` is described in the LiDAR frame at its time stamp ``t = 0``; the
ego drives along +x at ``ego_speed`` without yaw rate and every actor moves with its constant
ground velocity (:mod:`scenes.synth.world`). :func:`world_at` is the same world ``time`` seconds later,
described in the LiDAR frame of the ego *then*: the static scene shifted back by the ego's travel,
each actor moved by ``velocity * time`` minus that travel (headings and velocities kept). Sensing
it as any world gives the frame of that moment; its ego pose is :func:`scenes.talk2radar.poses.synthetic_pose`
at ``ego_speed * time``.

Over the short sequences this is meant for (about a second at 10 Hz) straight-line motion is what
VoD's actors do between frames; over many seconds a faster ego would drive into a slower lead car.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenes.geometry.actors import Actor
from scenes.geometry.calib import Calibration
from scenes.synth.world import Clutter, World
from scenes.synth.world.meshes import TaggedMesh
from scenes.talk2radar.poses import Pose, synthetic_pose


def world_at(world: World, time: float) -> World:
    """``world`` ``time`` seconds later, in the ego's LiDAR frame then (see the module docstring).

    The road layout is not carried (None): its centreline is written in the first frame's
    coordinates, and nothing that senses a world reads it.
    """
    shift = np.array([world.ego_speed * time, 0.0, 0.0])
    actors = []
    for actor in world.actors:
        box = actor.box.copy()
        box[:2] += actor.velocity * time - shift[:2]
        actors.append(Actor(actor.actor_id, actor.cls, box, actor.velocity.copy()))
    clutter = tuple(
        Clutter(c.cls, np.asarray(c.box, dtype=np.float64) - np.r_[shift, 0.0, 0.0, 0.0, 0.0])
        for c in world.clutter
    )
    static: TaggedMesh = world.static_mesh.transformed(np.eye(3), -shift)
    return dataclasses.replace(
        world, road=None, actors=tuple(actors), static_mesh=static, clutter=clutter
    )


UTM_ORIGIN = (500_000.0, 5_760_000.0)
"""Where synthetic drives are placed in UTM (easting, northing; m); world ``i`` starts
:data:`UTM_SPACING` ``* i`` m further east, so frames of two worlds are never taken as consecutive
(:func:`scenes.talk2radar.poses.consecutive`)."""
UTM_SPACING = 1000.0


def sequence_pose(world_id: int, ego_x: float, lidar_calib: Calibration) -> Pose:
    """The pose file of a frame of world ``world_id``'s drive, ``ego_x`` m after its first frame
    (:func:`scenes.talk2radar.poses.synthetic_pose`: odometry and map are the first frame's LiDAR frame)."""
    origin = (UTM_ORIGIN[0] + UTM_SPACING * world_id, UTM_ORIGIN[1])
    return synthetic_pose(ego_x, lidar_calib, origin)
