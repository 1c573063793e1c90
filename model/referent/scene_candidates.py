"""Candidates of one scene for the referent stage.

:func:`describe_candidates` turns boxes (detections at inference, actors plus false detections in
training) and the scene's BEV maps into the per-candidate tensors of
:class:`model.referent.stage.CandidateBatch`; :func:`stack_candidates` pads several scenes into one
batch (the answer's heatmap is :mod:`model.referent.heatmap`'s).

Maps (all on the head grid, ``(C, H, W)``, ``[c, iy, ix]``):

- ``fused``: the FPN output (what the C3D-RECHead reads), pooled at the box centre and at the
  box's anchor point (the corner nearest the ego vehicle by default), so ``2 * C_fpn`` values;
- ``lidar`` / ``radar``: stage 1 of that sensor's backbone (before the LiDAR-radar fusion), pooled
  at the centre and the anchor, plus :func:`model.referent.candidates.lidar_evidence` /
  :func:`model.referent.candidates.radar_evidence` from the raw points.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from model.core.anchors import anchor_points
from model.core.candidates import SceneCandidates, SceneMaps
from model.core.grid import BevGrid
from model.referent.candidates import (
    geometry_features,
    lidar_evidence,
    pool_bev,
    radar_evidence,
)
from model.referent.context import context_features
from model.referent.stage import CandidateBatch
from model.referent.subsets import subset_features


def _pooled(feature_map: Tensor, grid: BevGrid, centres: Tensor, anchors: Tensor) -> Tensor:
    """``(K, 2 C)``: the map pooled at the centres, then at the anchors (``(K, 2)`` each), in
    one sampling call (each position is sampled on its own: the same values as two calls)."""
    k = centres.shape[0]
    both = pool_bev(feature_map, grid, torch.cat([centres, anchors]))
    return torch.cat([both[:k], both[k:]], dim=1)


def describe_candidates(
    boxes: np.ndarray,
    labels: np.ndarray,
    scores: np.ndarray,
    maps: SceneMaps,
    grid: BevGrid,
    anchor: str,
    lidar_points: np.ndarray | None,
    radar_points: np.ndarray | None,
    *,
    context: bool,
    subsets: bool,
    num_classes: int = 3,
) -> SceneCandidates:
    """Everything the referent stage reads about ``K`` candidates of one scene.

    Args:
        boxes: ``(K, 7)`` LiDAR frame; labels ``(K,)`` class indices; scores ``(K,)``.
        maps: The scene's BEV maps on ``grid``.
        grid: The head grid.
        anchor: The head's anchor kind (``corner``, ``edge``, ``center``).
        lidar_points: ``(N, 4)`` (None when the model has no LiDAR).
        radar_points: ``(M, 7)`` in the LiDAR frame (None when the model has no radar).
        context: Append :func:`model.referent.context.context_features` to the geometry
            (``ReferentConfig.context``).
        subsets: Then append :func:`model.referent.subsets.subset_features` (text-free, so
            computed once per scene rather than per prompt; ``ReferentConfig.subset_ranks``).
        num_classes: The size of the model's class set (3: ``vod``); ``labels`` index it.

    Returns:
        :class:`model.core.candidates.SceneCandidates`; the pooled parts are differentiable in ``maps``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    labels = np.asarray(labels, dtype=np.int64).reshape(-1)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    device, dtype = maps.fused.device, maps.fused.dtype

    def t(a: np.ndarray) -> Tensor:
        return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(device, dtype)

    centres = t(boxes[:, :2])
    anchors = t(anchor_points(boxes, anchor)) if len(boxes) else centres
    geometry = geometry_features(boxes, labels, scores, num_classes)
    if context:
        geometry = np.concatenate(
            [geometry, context_features(boxes, labels, scores, num_classes)], axis=1
        )
    geometry = t(geometry)
    fused = _pooled(maps.fused, grid, centres, anchors)
    lidar = radar = None
    if maps.lidar is not None:
        pts = np.zeros((0, 4)) if lidar_points is None else np.asarray(lidar_points)
        lidar = torch.cat(
            [_pooled(maps.lidar, grid, centres, anchors), t(lidar_evidence(boxes, pts))], dim=1
        )
    if maps.radar is not None:
        pts = np.zeros((0, 7)) if radar_points is None else np.asarray(radar_points)
        radar = torch.cat(
            [_pooled(maps.radar, grid, centres, anchors), t(radar_evidence(boxes, pts))], dim=1
        )
    if subsets:
        padding = torch.zeros((1, len(boxes)), dtype=torch.bool, device=device)
        sub = subset_features(
            geometry[None], None if radar is None else radar[None], padding, num_classes
        )
        geometry = torch.cat([geometry, sub[0].to(dtype)], dim=1)
    return SceneCandidates(boxes, labels, scores, geometry, fused, lidar, radar)


def _pad(parts: Sequence[Tensor], k: int) -> Tensor:
    out = parts[0].new_zeros((len(parts), k, parts[0].shape[1]))
    for i, p in enumerate(parts):
        out[i, : p.shape[0]] = p
    return out


def stack_candidates(scenes: Sequence[SceneCandidates]) -> CandidateBatch:
    """Pad ``S`` scenes' candidates into a :class:`CandidateBatch` of ``S`` rows (``K`` = the
    largest count, at least 1; padding True where a scene has fewer)."""
    if not scenes:
        raise ValueError("stack_candidates: no scenes")
    k = max(1, max(len(s) for s in scenes))
    geometry = _pad([s.geometry for s in scenes], k)
    padding = torch.ones((len(scenes), k), dtype=torch.bool, device=geometry.device)
    for i, s in enumerate(scenes):
        padding[i, : len(s)] = False
    lidar = _pad([s.lidar for s in scenes], k) if scenes[0].lidar is not None else None
    radar = _pad([s.radar for s in scenes], k) if scenes[0].radar is not None else None
    return CandidateBatch(geometry, _pad([s.fused for s in scenes], k), lidar, radar, padding)


__all__ = [
    "describe_candidates",
    "stack_candidates",
]
