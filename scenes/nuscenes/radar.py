"""How nuScenes radar fields map onto the model's radar channels: the one place.

The model's radar point is View-of-Delft's ``x, y, z, rcs, v_r, v_r_compensated, time``
(docs/DESIGN.md, Frames). A nuScenes radar (Continental ARS 408-21) point has 18 fields
(:data:`scenes.nuscenes.sensorfiles.RADAR_FIELDS`), in that radar's own frame (x forward of the
radar, y left, z up). They map as follows:

=================== ===========================================================================
model channel       from the nuScenes fields
=================== ===========================================================================
x, y, z             ``x, y, z`` moved sensor -> ego(t_sweep) -> global -> ego(t_key) ->
                    LIDAR_TOP(key) -> model frame (:mod:`scenes.nuscenes.geometry`)
rcs                 ``rcs`` (dBsm), as it is (VoD's RCS is in dBsm too)
v_r                 ``(vx, vy)`` projected on the horizontal line of sight from *that* radar to
                    the point: ``(vx x + vy y) / hypot(x, y)`` in the radar's frame (m/s,
                    positive receding). The ARS 408 measures only the radial speed; nuScenes
                    stores it resolved into x and y along the line of sight, so the projection
                    recovers it exactly
v_r_compensated     the same from ``(vx_comp, vy_comp)`` (ego motion removed)
time                ``-k`` for the k-th sweep before the key frame's (0 for the key frame), as
                    View-of-Delft's scan index; the lag in seconds is kept beside it
                    (``NuScenesFrame.radar_time``)
=================== ===========================================================================

The radial speeds are scalars measured in each radar's own frame, so they survive any rigid move
of the points unchanged; the line of sight is the radar's, not the LiDAR's (View-of-Delft's one
radar sits 0.4 m from its LiDAR; nuScenes' five sit around the car). Kept points follow the
devkit's default filters (:func:`default_filter`: ``invalid_state`` 0, ``dyn_prop`` 0-6,
``ambig_state`` 3). The rest (``id``, ``is_quality_valid``, ``x_rms``..., ``pdh0``) is not a
model channel. Sensor differences (a sparse, 2D-ish radar: elevation is not measured, z is the
mounting height; tens to a few hundred points a sweep): docs/TALK2CAR.md.
"""

from __future__ import annotations

import numpy as np

from scenes.nuscenes.sensorfiles import radar_dtype

__all__ = [
    "AMBIG_STATES",
    "DYN_PROP_STATES",
    "INVALID_STATES",
    "RADAR_CHANNELS",
    "default_filter",
    "line_of_sight",
    "model_channels",
    "radial_components",
]

RADAR_CHANNELS = ("RADAR_FRONT", "RADAR_FRONT_LEFT", "RADAR_FRONT_RIGHT", "RADAR_BACK_LEFT",
                  "RADAR_BACK_RIGHT")  # fmt: skip
"""The five radars of nuScenes."""
INVALID_STATES = (0,)
"""``invalid_state`` values the devkit keeps by default."""
DYN_PROP_STATES = tuple(range(7))
"""``dyn_prop`` values the devkit keeps by default."""
AMBIG_STATES = (3,)
"""``ambig_state`` values the devkit keeps by default."""


def default_filter(points: np.ndarray) -> np.ndarray:
    """``(M,)`` bool: the points of a radar record array the devkit's default filters keep."""
    return (
        np.isin(points["invalid_state"], INVALID_STATES)
        & np.isin(points["dyn_prop"], DYN_PROP_STATES)
        & np.isin(points["ambig_state"], AMBIG_STATES)
    )


def line_of_sight(xy: np.ndarray) -> np.ndarray:
    """``(M, 2)`` the horizontal unit line of sight from a radar to its points ``(M, >=2)``
    (its own frame); a point at the radar's axis origin gets ``(1, 0)``."""
    xy = np.asarray(xy, dtype=np.float64)[:, :2]
    norm = np.hypot(xy[:, 0], xy[:, 1])[:, None]
    out = np.tile([1.0, 0.0], (len(xy), 1))
    ok = norm[:, 0] > 1e-9
    out[ok] = xy[ok] / norm[ok]
    return out


def model_channels(points: np.ndarray) -> np.ndarray:
    """``(M, 3)`` float64 ``rcs, v_r, v_r_compensated`` of a radar record array (its frame)."""
    u = line_of_sight(np.c_[points["x"], points["y"]])
    v_r = points["vx"] * u[:, 0] + points["vy"] * u[:, 1]
    v_c = points["vx_comp"] * u[:, 0] + points["vy_comp"] * u[:, 1]
    return np.c_[points["rcs"].astype(np.float64), v_r, v_c]


def radial_components(
    xyz: np.ndarray, rcs: np.ndarray, v_r: np.ndarray, v_r_compensated: np.ndarray
) -> np.ndarray:
    """The inverse of :func:`model_channels` for a writer: a record array of
    :func:`~scenes.nuscenes.sensorfiles.radar_dtype` with ``x, y, z`` (the radar's frame),
    ``rcs``, ``vx, vy`` and ``vx_comp, vy_comp`` (the radial speeds resolved along the line of
    sight), ``dyn_prop`` (0 moving, 1 stationary by the compensated speed), ``ambig_state`` 3,
    ``invalid_state`` 0 (kept by the default filters), ``id`` the point's index, the rest 0 (rms
    and pdh0 as a clean detection: 0 and 1)."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    rec = np.zeros(len(xyz), dtype=radar_dtype())
    u = line_of_sight(xyz)
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    rec["rcs"] = rcs
    rec["vx"], rec["vy"] = v_r * u[:, 0], v_r * u[:, 1]
    rec["vx_comp"], rec["vy_comp"] = v_r_compensated * u[:, 0], v_r_compensated * u[:, 1]
    rec["dyn_prop"] = np.where(np.abs(v_r_compensated) > 0.5, 0, 1)
    rec["id"] = np.arange(len(xyz)) % 32768
    rec["ambig_state"] = 3
    rec["invalid_state"] = 0
    rec["is_quality_valid"] = 1
    rec["pdh0"] = 1
    return rec
