"""Ranks within a subset of a class, and references picked by speed, side or motion: text-free.

:mod:`model.referent.context` ranks each candidate among its whole class (nearest, leftmost) and
relates it to each class's extreme candidates. People also rank by speed ("the second fastest
cyclist", "the runner-up in speed", "second slowest") and within a part of a class ("the second
cyclist on the left", "the second closest moving car"), and relate to an object picked by its
speed, side or motion ("the car nearest to the fastest cyclist", "the cyclist closest to the
parked car", "the pedestrian closest to the car on the left"). Stage 3f read these from attention
alone and got them right about half as often as the whole-class forms (docs/RESULTS.md, the
language suite's per-sentence figures). This module states them, for all candidates of a scene at
once, as a pure function of the stage's inputs (one compiled pass per scene, numba, float64):

- **Subset ranks** (:data:`SUBSET_ORDERS`): a soft rank ``r_i = sum_j w_j m_ij sigmoid((key_j -
  key_i) / tau)`` over the other candidates ``j`` of ``i``'s class, ``w_j`` the objectness
  (:func:`model.referent.context.objectness`) and ``m_ij`` the membership of ``j`` in ``i``'s
  subset: 1 for speed ranks (fastest, slowest; ``tau`` :data:`SPEED_TAU` m/s), the probability
  that ``i`` and ``j`` are on the same side (left / ahead / right of the ego corridor,
  :data:`LANE_HALF_WIDTH`) or in the same motion state (moving above
  :data:`scenes.geometry.actors.MOVING_SPEED`) for depth ranks (nearest, farthest; ``tau``
  :data:`DEPTH_TAU` m). Each rank is given as ``min(r, 6) / 4`` and bumps at ``0 .. 3``, as in
  :mod:`model.referent.context`; plus the candidate's own moving probability.
- **Picked references** (:data:`PICKED`): for each class ``c``, its fastest, slowest, moving,
  stationary, left, ahead and right candidate, a softmax over ``c``'s candidates of the key plus
  the log objectness; from it, as :mod:`model.referent.context` does for its references: ``dx``,
  ``dy``, the BEV distance, the depth beyond the reference's far edge, the candidate's own weight
  in the reference, and its soft rank by distance to the reference among its own class
  (``min(r, 6) / 4``, bumps at 0 and 1).

Speeds are the radar's (:func:`model.referent.compare.candidate_speed`), so a LiDAR-only model sees
every candidate as stationary. Frames: LiDAR (x forward, y left), metres; padding candidates are
no rival and no reference, and their own rows are zeros.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit
from torch import Tensor

from model.referent.candidates import DEPTH_COLUMN, DEPTH_SCALE, LATERAL_SCALE, class_columns
from model.referent.compare import candidate_speed
from model.referent.context import (
    BUMPS,
    OBJECT_SCORE,
    OBJECT_WIDTH,
    RELATION_SCALE,
    rank_code_into,
    softmax_into,
)
from scenes.geometry.actors import MOVING_SPEED
from scenes.language.prompts.atoms import AHEAD_MAX_BEARING_DEG, LANE_HALF_WIDTH

SPEED_TAU = 0.5
"""Metres per second over which a speed rank's step goes from 0.27 to 0.73."""
DEPTH_TAU = 0.5
MOTION_WIDTH = 0.1
"""m/s: the width of the soft step of 'moving' at :data:`scenes.geometry.actors.MOVING_SPEED`."""
SIDE_WIDTH = 0.3
"""Metres: the width of the soft steps of the sides at ``+-LANE_HALF_WIDTH``."""
PICK_TAU = 0.5
"""Metres per second per unit of a speed-picked reference's logit."""
PICK_STATE_TAU = 0.1
"""Units of probability (moving, on a side) per unit of a state-picked reference's logit."""
SUBSET_ORDERS = (
    "fastest",
    "slowest",
    "nearest_same_side",
    "farthest_same_side",
    "nearest_same_motion",
    "farthest_same_motion",
)
PICKED = ("fastest", "slowest", "moving", "stationary", "left", "ahead", "right")
PER_PICKED = 8
"""dx, dy, distance, depth beyond the far edge, own weight, rank / 4, bump 0, bump 1."""
SUBSET_RANK_FEATURES = len(SUBSET_ORDERS) * (1 + len(BUMPS)) + 1
"""The subset ranks' columns and the moving probability (the same for every class set)."""
SUBSET_FEATURES = SUBSET_RANK_FEATURES + 3 * len(PICKED) * PER_PICKED
"""Width of :func:`subset_features` of a three-class (``vod``) model; :func:`subset_width`."""


def subset_width(num_classes: int) -> int:
    """Width of :func:`subset_features` of a model of ``num_classes`` classes (a block of picked
    references per class)."""
    return SUBSET_RANK_FEATURES + num_classes * len(PICKED) * PER_PICKED


_X_COLUMN, _Y_COLUMN, _SCORE_COLUMN = 4, 5, 3


@njit(inline="always")
def _sigmoid(z: float) -> float:  # pragma: no cover - compiled into the kernel
    return 1.0 / (1.0 + math.exp(-z))


@njit(inline="always")
def _side(x: float, y: float) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """Soft left / ahead / right of a candidate at ``x``, ``y`` (metres)."""
    left = _sigmoid((y - LANE_HALF_WIDTH) / SIDE_WIDTH)
    right = _sigmoid((-y - LANE_HALF_WIDTH) / SIDE_WIDTH)
    bearing = math.degrees(math.atan2(abs(y), max(x, 1e-3)))
    ahead = max(1.0 - left - right, 0.0) * _sigmoid(AHEAD_MAX_BEARING_DEG - bearing)
    return left, ahead, right


@njit(nogil=True, cache=True)
def _one_scene(  # pragma: no cover - compiled; its Python body is what numba compiles
    onehot, x, y, depth, score, speed, out,
):  # fmt: skip
    """The features of one scene's ``K`` real candidates into ``out (K, SUBSET_FEATURES)``
    (float64 arithmetic; the module docstring's definitions, term for term)."""
    k = x.shape[0]
    n_cls = onehot.shape[1]
    w = np.empty(k)
    moving = np.empty(k)
    sides = np.empty((k, 3))
    for i in range(k):
        w[i] = _sigmoid((min(max(score[i], 0.0), 1.0) - OBJECT_SCORE) / OBJECT_WIDTH)
        moving[i] = _sigmoid((speed[i] - MOVING_SPEED) / MOTION_WIDTH)
        sides[i, 0], sides[i, 1], sides[i, 2] = _side(x[i], y[i])
    rivals = np.zeros((k, k))  # [i, j]: j a rival of i (same class, weighted)
    for i in range(k):
        for j in range(k):
            if i != j:
                same = 0.0
                for c in range(n_cls):
                    same += onehot[i, c] * onehot[j, c]
                rivals[i, j] = same * w[j]
    col = 0
    for order in range(6):
        for i in range(k):
            rank = 0.0
            for j in range(k):
                if rivals[i, j] == 0.0:
                    continue
                if order < 2:  # fastest, slowest: every rival of the class
                    sign = 1.0 if order == 0 else -1.0
                    step = _sigmoid(sign * (speed[j] - speed[i]) / SPEED_TAU)
                    member = 1.0
                else:  # nearest / farthest within the same side (2, 3) or motion state (4, 5)
                    sign = -1.0 if order % 2 == 0 else 1.0
                    step = _sigmoid(sign * (depth[j] - depth[i]) / DEPTH_TAU)
                    if order < 4:
                        member = (
                            sides[i, 0] * sides[j, 0]
                            + sides[i, 1] * sides[j, 1]
                            + sides[i, 2] * sides[j, 2]
                        )
                    else:
                        member = moving[i] * moving[j] + (1.0 - moving[i]) * (1.0 - moving[j])
                rank += step * rivals[i, j] * member
            rank_code_into(out, i, col, rank, BUMPS)
        col += 1 + len(BUMPS)
    for i in range(k):
        out[i, col] = moving[i]
    col += 1
    # Picked references: a[j] = j's share in class c's reference p (softmax over c's candidates).
    n_picked = len(PICKED)
    a = np.empty(k)
    logit = np.empty(k)
    allowed = np.empty(k, np.bool_)
    to_ref = np.empty(k)
    for c in range(n_cls):
        for p in range(n_picked):
            base = col + (c * n_picked + p) * PER_PICKED
            for j in range(k):
                allowed[j] = onehot[j, c] > 0.5
                if allowed[j]:
                    if p == 0:
                        key = speed[j] / PICK_TAU
                    elif p == 1:
                        key = -speed[j] / PICK_TAU
                    elif p == 2:
                        key = moving[j] / PICK_STATE_TAU
                    elif p == 3:
                        key = (1.0 - moving[j]) / PICK_STATE_TAU
                    else:
                        key = sides[j, p - 4] / PICK_STATE_TAU
                    logit[j] = key + math.log(max(w[j], 1e-6))
            softmax_into(a, logit, allowed, k)
            if not allowed.any():  # no candidate of class c: its block stays zeros
                continue
            rx = ry = redge = 0.0
            for j in range(k):
                rx += a[j] * x[j]
                ry += a[j] * y[j]
                redge += a[j] * (2.0 * x[j] - depth[j])
            for i in range(k):
                to_ref[i] = math.hypot(rx - x[i], ry - y[i])
            for i in range(k):
                rank = 0.0
                for j in range(k):
                    if rivals[i, j] != 0.0:
                        step = _sigmoid((to_ref[i] - to_ref[j]) / DEPTH_TAU)
                        rank += step * rivals[i, j] * (1.0 - a[j])
                out[i, base + 0] = (rx - x[i]) / RELATION_SCALE
                out[i, base + 1] = (ry - y[i]) / RELATION_SCALE
                out[i, base + 2] = to_ref[i] / RELATION_SCALE
                out[i, base + 3] = (depth[i] - redge) / RELATION_SCALE
                out[i, base + 4] = a[i]
                rank_code_into(out, i, base + 5, rank, (0, 1))


def subset_features(
    geometry: Tensor, radar: Tensor | None, padding: Tensor, num_classes: int = 3
) -> Tensor:
    """The module docstring's features, ``(N, K, subset_width(C))``, each row its own scene
    (:func:`model.referent.scene_candidates.describe_candidates` calls it once per scene).

    Text-free and without gradient (the inputs it reads, the geometry and the radar evidence,
    come from NumPy): each scene's real candidates go through one compiled pass (numba, cached
    beside this file; float64 arithmetic), padding rows are zeros.

    Args:
        geometry: ``(N, K, >= GEOMETRY_FEATURES)`` candidate geometry
            (:func:`model.referent.candidates.geometry_features` first).
        radar: ``(N, K, C_r + RADAR_EVIDENCE)`` or None.
        padding: ``(N, K)`` bool, True at padding.
        num_classes: ``C``, the size of the model's class set (3: ``vod``); the one-hot is read
            from :func:`model.referent.candidates.class_columns`.
    """
    n, k = padding.shape
    width = subset_width(num_classes)
    onehot_columns = class_columns(num_classes)
    out = np.zeros((n, k, width), dtype=np.float64)
    if k:
        g = geometry.detach().cpu().double().numpy()
        speed = candidate_speed(None if radar is None else radar.detach(), geometry.detach())
        speeds = speed.cpu().double().numpy()
        real = ~padding.cpu().numpy()
        for row in range(n):
            idx = np.flatnonzero(real[row])
            if not len(idx):
                continue
            part = g[row, idx]
            scene = np.zeros((len(idx), width))
            _one_scene(
                np.ascontiguousarray(part[:, onehot_columns]),
                part[:, _X_COLUMN] * DEPTH_SCALE,
                part[:, _Y_COLUMN] * LATERAL_SCALE,
                part[:, DEPTH_COLUMN] * DEPTH_SCALE,
                np.ascontiguousarray(part[:, _SCORE_COLUMN]),
                np.ascontiguousarray(speeds[row, idx]),
                scene,
            )
            out[row, idx] = scene
    return torch.from_numpy(out).to(device=geometry.device, dtype=geometry.dtype)


__all__ = ["PICKED", "SUBSET_FEATURES", "SUBSET_ORDERS", "subset_features", "subset_width"]
