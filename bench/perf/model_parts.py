"""The parts of a TPCNet that the benchmarks time or count one by one (a scene encoder and a
grounding head: ``model.scene``, ``model.grounding``), for this repository's model and for an older
copy of ``model`` loaded beside it by :mod:`bench.perf.floor` (``--baseline-package``; a copy of commit
094cf30 or later: the flat layout before it, whose parts were attributes of the model itself, is
refused with a message). The stages run are the model's own pipeline
(:meth:`model.grounding.scene_encoder.SceneEncoder.sensors`, the FPN, the head, the referent head's
``proposals`` and ``describe``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from torch import Tensor, nn

from model import SceneMaps


@dataclass(frozen=True)
class ModelParts:
    """One model's parts.

    Attributes:
        lidar, radar: The sensor branches (``pillars``, ``backbone``), None when unused.
        fusion: The LiDAR-radar fusion blocks (None for one sensor).
        neck, head: The SECOND-FPN and the C3D-RECHead.
        sensors: ``(lidar (N, 4), radar (M, 7)) -> (fused stages, lidar stage 1, radar stage 1)``
            of one scene (batch 1).
        proposals: The head output -> the detections of item 0 at the referent path's candidate
            threshold, at most ``max_candidates``.
        maps: ``(neck, lidar stage 1, radar stage 1) -> SceneMaps`` of item 0.
        describe: ``(boxes, labels, scores, maps, lidar, radar) -> SceneCandidates``.
        refer: ``(candidates, text) -> logits (N, K)``.
    """

    lidar: nn.Module | None
    radar: nn.Module | None
    fusion: nn.ModuleList | None
    neck: nn.Module
    head: nn.Module
    sensors: Callable[[Tensor, Tensor], tuple[list[Tensor], Tensor | None, Tensor | None]]
    proposals: Callable[[object], object]
    maps: Callable[[Tensor, Tensor | None, Tensor | None], object]
    describe: Callable[..., object]
    refer: Callable[..., Tensor]


def model_parts(model: nn.Module) -> ModelParts:
    """The parts of ``model`` (this code's or an older copy's, module docstring).

    Raises:
        ValueError: a model of the flat layout (before commit 094cf30).
    """
    cfg = model.cfg
    if not hasattr(model, "scene"):
        raise ValueError(
            f"{type(model).__module__}: a model of the flat layout (before commit 094cf30, no "
            "scene encoder): make the baseline package from a later commit"
        )
    scene, head = model.scene, model.grounding

    def sensors(lidar: Tensor, radar: Tensor):
        lid = [lidar] if scene.lidar is not None else None
        s = scene.sensors(lid, [radar] if scene.radar is not None else None)
        first_l = None if s.lidar is None else s.lidar[0]
        return list(s.fused), first_l, None if s.radar is None else s.radar[0]

    def describe(*args: object) -> object:
        return head.describe(scene, *args)

    return ModelParts(
        scene.lidar,
        scene.radar,
        scene.fusion,
        scene.neck,
        scene.head,
        sensors,
        lambda out: head.proposals(scene, out, cfg.referent.max_candidates)[0],
        lambda neck, lid, rad: SceneMaps(neck[0], _item(lid), _item(rad)),
        describe,
        getattr(head, "refer", None),
    )


def _item(stage: Tensor | None) -> Tensor | None:
    return None if stage is None else stage[0]


def keep_candidates(dets: object, limit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first ``limit`` detections' ``boxes``, ``labels`` and ``scores``."""
    keep = slice(0, limit)
    return dets.boxes[keep], dets.labels[keep], dets.scores[keep]  # type: ignore[attr-defined]


__all__ = ["ModelParts", "keep_candidates", "model_parts"]
