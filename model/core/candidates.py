"""A scene's BEV maps and its candidates as the referent stage reads them: the types the scene
encoder, the encoded scene (:class:`model.core.features.SceneFeatures`), the referent head and
training share (:func:`model.referent.scene_candidates.describe_candidates` makes them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from torch import Tensor


@dataclass(frozen=True)
class SceneMaps:
    """BEV maps of one scene, each ``(C, H, W)`` on the head grid (None for an unused sensor)."""

    fused: Tensor
    lidar: Tensor | None
    radar: Tensor | None


@dataclass(frozen=True)
class SceneCandidates:
    """The candidates of one scene.

    Attributes:
        boxes: ``(K, 7)`` float64, LiDAR frame.
        labels: ``(K,)`` int64 class indices.
        scores: ``(K,)`` float64 detection scores.
        geometry, fused, lidar, radar: ``(K, F)`` tensors as in :class:`model.referent.stage.CandidateBatch`.
    """

    boxes: np.ndarray
    labels: np.ndarray
    scores: np.ndarray
    geometry: Tensor
    fused: Tensor
    lidar: Tensor | None
    radar: Tensor | None

    def __len__(self) -> int:
        return len(self.boxes)
