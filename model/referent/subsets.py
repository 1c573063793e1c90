"""Ranks within a subset of a class, and references picked by speed, side or motion: text-free.

:mod:`model.referent.context` ranks each candidate among its whole class (nearest, leftmost) and
relates it to each class's extreme candidates. People also rank by speed ("the second fastest
cyclist", "the runner-up in speed", "second slowest") and within a part of a class ("the second
cyclist on the left", "the second closest moving car"), and relate to an object picked by its
speed, side or motion ("the car nearest to the fastest cyclist", "the cyclist closest to the
parked car", "the pedestrian closest to the car on the left"). Stage 3f read these from attention
alone and got them right about half as often as the whole-class forms (docs/RESULTS.md, the
language suite's per-sentence figures). This module states them, for all candidates and prompt
rows at once, as pure torch functions of the stage's inputs:

- **Subset ranks** (:data:`SUBSET_ORDERS`): a soft rank ``r_i = sum_j w_j m_ij sigmoid((key_j -
  key_i) / tau)`` over the other candidates ``j`` of ``i``'s class, ``w_j`` the objectness
  (:func:`model.referent.context.objectness`) and ``m_ij`` the membership of ``j`` in ``i``'s
  subset: 1 for speed ranks (fastest, slowest; ``tau`` :data:`SPEED_TAU` m/s), the probability
  that ``i`` and ``j`` are on the same side (left / ahead / right of the ego corridor,
  :data:`LANE_HALF_WIDTH`) or in the same motion state (moving above
  :data:`scenes.actors.MOVING_SPEED`) for depth ranks (nearest, farthest; ``tau``
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

import torch
from torch import Tensor

from model.referent.candidates import DEPTH_COLUMN, DEPTH_SCALE, LATERAL_SCALE
from model.referent.compare import candidate_speed
from model.referent.context import BUMP_WIDTH, BUMPS, OBJECT_SCORE, OBJECT_WIDTH, RELATION_SCALE
from scenes.actors import CLASSES, MOVING_SPEED
from scenes.prompts.atoms import AHEAD_MAX_BEARING_DEG, LANE_HALF_WIDTH

SPEED_TAU = 0.5
"""Metres per second over which a speed rank's step goes from 0.27 to 0.73."""
DEPTH_TAU = 0.5
MOTION_WIDTH = 0.1
"""m/s: the width of the soft step of 'moving' at :data:`scenes.actors.MOVING_SPEED`."""
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
SUBSET_FEATURES = (
    len(SUBSET_ORDERS) * (1 + len(BUMPS)) + 1 + len(CLASSES) * len(PICKED) * PER_PICKED
)
_X_COLUMN, _Y_COLUMN, _SCORE_COLUMN = 4, 5, 3


def _rank_code(rank: Tensor, bumps: tuple[int, ...]) -> Tensor:
    """``(..., 1 + len(bumps))`` of soft ranks ``(...)``."""
    cols = [rank.clamp(max=6.0) / 4.0]
    cols += [torch.exp(-((rank - n) ** 2) / (2 * BUMP_WIDTH**2)) for n in bumps]
    return torch.stack(cols, dim=-1)


def side_probabilities(x: Tensor, y: Tensor) -> Tensor:
    """``(..., 3)`` soft left / ahead / right of candidates at ``x``, ``y`` (metres): left of the
    ego corridor (``y > LANE_HALF_WIDTH``), right of it, or in it within the bearing the prompts
    call ahead; the rest (beside the bumper) is on no side."""
    left = torch.sigmoid((y - LANE_HALF_WIDTH) / SIDE_WIDTH)
    right = torch.sigmoid((-y - LANE_HALF_WIDTH) / SIDE_WIDTH)
    bearing = torch.rad2deg(torch.atan2(y.abs(), x.clamp(min=1e-3)))
    ahead = (1.0 - left - right).clamp(min=0.0) * torch.sigmoid(AHEAD_MAX_BEARING_DEG - bearing)
    return torch.stack([left, ahead, right], dim=-1)


def subset_features(geometry: Tensor, radar: Tensor | None, padding: Tensor) -> Tensor:
    """The module docstring's features, ``(N, K, SUBSET_FEATURES)``, each row its own scene
    (:func:`model.referent.scene_candidates.describe_candidates` calls it once per scene).

    Args:
        geometry: ``(N, K, >= GEOMETRY_FEATURES)`` candidate geometry
            (:func:`model.referent.candidates.geometry_features` first).
        radar: ``(N, K, C_r + RADAR_EVIDENCE)`` or None.
        padding: ``(N, K)`` bool, True at padding.
    """
    n, k = padding.shape
    if k == 0:
        return geometry.new_zeros((n, 0, SUBSET_FEATURES))
    onehot = geometry[..., : len(CLASSES)]
    x = geometry[..., _X_COLUMN] * DEPTH_SCALE
    y = geometry[..., _Y_COLUMN] * LATERAL_SCALE
    depth = geometry[..., DEPTH_COLUMN] * DEPTH_SCALE
    real = (~padding).to(geometry.dtype)
    w = torch.sigmoid((geometry[..., _SCORE_COLUMN].clamp(0, 1) - OBJECT_SCORE) / OBJECT_WIDTH)
    w = w * real  # (N, K)
    speed = candidate_speed(radar, geometry)
    moving = torch.sigmoid((speed - MOVING_SPEED) / MOTION_WIDTH)
    sides = side_probabilities(x, y)  # (N, K, 3)
    eye = torch.eye(k, dtype=torch.bool, device=geometry.device)
    same = (onehot @ onehot.transpose(1, 2)).masked_fill(eye, 0.0)  # (N, K, K)
    rivals = same * w[:, None, :]  # [n, i, j]: j a rival of i
    same_side = sides @ sides.transpose(1, 2)
    same_motion = moving[..., :, None] * moving[..., None, :]
    same_motion = same_motion + (1 - moving)[..., :, None] * (1 - moving)[..., None, :]
    orders = (
        (speed, SPEED_TAU, None),  # a larger key comes first
        (-speed, SPEED_TAU, None),
        (-depth, DEPTH_TAU, same_side),
        (depth, DEPTH_TAU, same_side),
        (-depth, DEPTH_TAU, same_motion),
        (depth, DEPTH_TAU, same_motion),
    )
    ranks = []
    for key, tau, member in orders:
        step = torch.sigmoid((key[:, None, :] - key[:, :, None]) / tau)
        weight = rivals if member is None else rivals * member
        ranks.append(_rank_code((step * weight).sum(-1), BUMPS))
    rank_part = torch.cat([*ranks, moving[..., None]], dim=-1)

    # Picked references: [n, c, p, j] = j's share in class c's reference p.
    keys = torch.stack(
        [speed, -speed, moving, 1 - moving, sides[..., 0], sides[..., 1], sides[..., 2]], dim=1
    )  # (N, P, K), larger = more the reference
    scales = geometry.new_tensor([PICK_TAU] * 2 + [PICK_STATE_TAU] * 5)[None, :, None]
    logit = keys / scales + torch.log(w.clamp(min=1e-6))[:, None, :]
    of_c = (onehot.transpose(1, 2) > 0.5) & ~padding[:, None, :]  # (N, C, K)
    allowed = of_c[:, :, None, :]
    z = logit[:, None, :, :].masked_fill(~allowed, float("-inf"))  # (N, C, P, K)
    any_c = allowed.any(-1, keepdim=True)
    a = torch.softmax(z.masked_fill(~any_c, 0.0), dim=-1) * any_c  # (N, C, P, K)
    rx, ry = (a * x[:, None, None, :]).sum(-1), (a * y[:, None, None, :]).sum(-1)
    redge = (a * (2.0 * x - depth)[:, None, None, :]).sum(-1)  # (N, C, P)
    dx = rx[..., None] - x[:, None, None, :]  # (N, C, P, K): from candidate i
    dy = ry[..., None] - y[:, None, None, :]
    own = a  # candidate i's weight in the reference
    to_ref = torch.hypot(dx, dy)  # (N, C, P, K)
    step = torch.sigmoid((to_ref[..., :, None] - to_ref[..., None, :]) / DEPTH_TAU)  # [.., i, j]
    rival = rivals[:, None, None] * (1.0 - a)[..., None, :]
    rank = (step * rival).sum(-1)
    place = torch.stack(
        [
            dx / RELATION_SCALE,
            dy / RELATION_SCALE,
            to_ref / RELATION_SCALE,
            (depth[:, None, None, :] - redge[..., None]) / RELATION_SCALE,
            own,
        ],
        dim=-1,
    )
    block = torch.cat([place, _rank_code(rank, (0, 1))], dim=-1)  # (N, C, P, K, 8)
    block = block * any_c[..., None]
    picked = block.permute(0, 3, 1, 2, 4).reshape(n, k, -1)
    out = torch.cat([rank_part, picked], dim=-1) * real[..., None]
    return out


__all__ = ["PICKED", "SUBSET_FEATURES", "SUBSET_ORDERS", "side_probabilities", "subset_features"]
