"""The scene encoder both grounding heads share (fig. 3 without the text): each sensor's pillar
encoder and backbone, the LiDAR-radar fusion (BACA or a baseline), the SECOND-FPN and the
C3D-RECHead detector, assembled from a :class:`model.config.ModelConfig`.

Data flow per sample (LiDAR frame throughout)::

    lidar (N, 4) -> PillarEncoder -> SecondBackbone -> f^l_1..3 --+
                                                                   +-> fusion_i -> lr_i  (no text)
    radar (M, 7) -> PillarEncoder -> SecondBackbone -> f^r_1..3 --+
    stages (lr_1..3, or text-conditioned lc_1..3) -> FPN -> f ; head(f) -> heatmap, regression

:meth:`SceneEncoder.sensors` is the text-independent part; :meth:`SceneEncoder.detector` runs the
FPN and the head on three stages (the fused ones on the referent path, the DGGF-conditioned ones
on the paper's path); :meth:`SceneEncoder.detect` is both on a batch, with the BEV maps the
referent stage pools from. A single-modality model has no branch (and ignores the points) of the
other sensor.

The detector's geometry is the encoder's to answer, so that training code never assembles the
head grid and the head's anchor rule itself: :meth:`SceneEncoder.anchors_in_grid` (which boxes the
detector can see), :meth:`SceneEncoder.anchor_scores` (its score of a box at the box's anchor
cell) and :meth:`SceneEncoder.detection_targets` (its training targets for given boxes).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from model.config import LIDAR_FEATURES, RADAR_FEATURES, ModelConfig
from model.core.anchors import anchor_points
from model.core.candidates import SceneMaps
from model.core.features import (
    Clock,
    MissingSensorError,
    PointsLike,
    SceneFeatures,
    SceneTimings,
    as_points,
)
from model.core.labelled import anchor_scores
from model.head.detector import C3DRecHead, HeadOutput
from model.head.targets import BatchTargets, collate_targets, draw_targets
from model.nets.backbone import SecondBackbone
from model.nets.fpn import SecondFpn
from model.nets.fusion import build_fusion
from model.nets.pillars import PillarEncoder


class SensorBranch(nn.Module):
    """Pillar encoder + three-stage backbone of one sensor."""

    def __init__(self, cfg: ModelConfig, sensor: str) -> None:
        super().__init__()
        p = cfg.pillars
        if sensor == "lidar":
            self.pillars = PillarEncoder(p, LIDAR_FEATURES, p.lidar_max_points, p.lidar_scale)
        else:
            self.pillars = PillarEncoder(p, RADAR_FEATURES, p.radar_max_points, p.radar_scale)
        self.backbone = SecondBackbone(p.channels, cfg.backbone)


@dataclass(frozen=True)
class SensorStages:
    """The text-independent stages of a batch.

    Attributes:
        fused: ``(lr_1, lr_2, lr_3)``, each ``(B, C_i, H_i, W_i)``.
        lidar, radar: Each sensor's own backbone stages (None for an unused sensor).
        timings: Time of the pillars, backbones and fusion (0 when not timed).
    """

    fused: tuple[Tensor, ...]
    lidar: tuple[Tensor, ...] | None
    radar: tuple[Tensor, ...] | None
    timings: SceneTimings

    def features(
        self,
        lidar: list[Tensor] | None,
        radar: list[Tensor] | None,
        detect_ms: float = 0.0,
        **objects: Any,
    ) -> SceneFeatures:
        """The :class:`SceneFeatures` of one scene (batch 1) of clouds ``lidar`` / ``radar``,
        with ``detect_ms`` as the detection stage's time and the referent path's ``objects``
        (``objects``, ``detection_heatmaps``, ``answerable``)."""
        return SceneFeatures(
            stages=self.fused,
            num_lidar=0 if lidar is None else int(lidar[0].shape[0]),
            num_radar=0 if radar is None else int(radar[0].shape[0]),
            timings=dataclasses.replace(self.timings, detect=detect_ms),
            **objects,
        )

    def maps(self, neck: Tensor, item: int) -> SceneMaps:
        """Item ``item``'s BEV maps for the referent stage: the FPN output ``neck`` ``(B, C, H,
        W)`` and stage 1 of each sensor's backbone."""
        return SceneMaps(
            fused=neck[item],
            lidar=None if self.lidar is None else self.lidar[0][item],
            radar=None if self.radar is None else self.radar[0][item],
        )


class SceneEncoder(nn.Module):
    """Sensor branches, LiDAR-radar fusion, FPN and detector head (no text)."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.grid = cfg.pillars.grid
        self.head_grid = cfg.head_grid
        self.lidar = SensorBranch(cfg, "lidar") if cfg.uses_lidar else None
        self.radar = SensorBranch(cfg, "radar") if cfg.uses_radar else None
        channels = cfg.backbone.channels
        self.fusion = (
            nn.ModuleList(build_fusion(cfg.fusion, c) for c in channels)
            if cfg.modalities == "both"
            else None
        )
        self.neck = SecondFpn(channels, cfg.backbone.cumulative_strides, cfg.fpn)
        self.head = C3DRecHead(cfg.head, self.neck.out_channels)

    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    @property
    def stage_channels(self) -> tuple[int, ...]:
        """Channels of the three stages ``lr_1..3``."""
        return tuple(self.cfg.backbone.channels)

    def anchors_in_grid(self, boxes: np.ndarray) -> np.ndarray:
        """``(K,)`` bool: the boxes ``(K, 7)`` (LiDAR frame) whose anchor point
        (``cfg.head.anchor``) lies in the head grid, the ones the detector can be trained on and
        can find."""
        return self.head_grid.contains(anchor_points(boxes, self.cfg.head.anchor))

    def anchor_scores(self, heat: np.ndarray, boxes: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """``(K,)``: the detector's sigmoid heatmap ``heat (C, H, W)`` read at each box's anchor
        cell in its class's channel (:func:`model.core.labelled.anchor_scores`); boxes ``(K,
        7)`` LiDAR frame, ``labels (K,)`` indices into the model's class set."""
        return anchor_scores(heat, boxes, labels, self.head_grid, self.cfg.head.anchor)

    def detection_targets(
        self, boxes: Sequence[np.ndarray], classes: Sequence[Sequence[str]]
    ) -> BatchTargets:
        """The detector's training targets of a batch: item ``b``'s boxes ``(K_b, 7)`` (LiDAR
        frame) with their class names (:func:`model.head.targets.draw_targets` on the head
        grid; names outside the model's class set are ignored), collated, on the CPU."""
        return collate_targets(
            [
                draw_targets(b, c, self.head_grid, self.cfg.head)
                for b, c in zip(boxes, classes, strict=True)
            ]
        )

    def clouds(
        self, clouds: Sequence[PointsLike | None] | None, batch: int, sensor: str
    ) -> list[Tensor] | None:
        """A batch of one sensor's clouds checked (:func:`model.core.features.as_points`) and on the
        model's device; None for a sensor the model does not use.

        Raises:
            MissingSensorError: a used sensor's clouds (or one of them) are None.
        """
        used = self.lidar is not None if sensor == "lidar" else self.radar is not None
        if not used:
            return None
        label = "LiDAR" if sensor == "lidar" else "radar"
        num_features = LIDAR_FEATURES if sensor == "lidar" else RADAR_FEATURES
        if clouds is None or any(c is None for c in clouds):
            raise MissingSensorError(
                f"this model was built with modalities={self.cfg.modalities!r} and needs {label} "
                f"points, but none were given; pass an empty (0, {num_features}) array for a "
                f"{label} that returned nothing"
            )
        if len(clouds) != batch:
            raise ValueError(f"{len(clouds)} {label} clouds for a batch of {batch}")
        return [
            as_points(c, num_features, f"{label} cloud {i}").to(self.device)
            for i, c in enumerate(clouds)
        ]

    def sensors(
        self, lidar: list[Tensor] | None, radar: list[Tensor] | None, timed: bool = False
    ) -> SensorStages:
        """Pillars, backbones and fusion of a batch of checked clouds (:meth:`clouds`)."""
        clock = Clock(self.device, timed)
        canvases: dict[str, Tensor] = {}
        for name, branch, clouds in (("l", self.lidar, lidar), ("r", self.radar, radar)):
            if branch is not None and clouds is not None:
                canvases[name] = branch.pillars(clouds)
        t_pillars = clock.lap()
        stages: dict[str, tuple[Tensor, ...]] = {}
        for name, branch in (("l", self.lidar), ("r", self.radar)):
            if branch is not None:
                stages[name] = branch.backbone(canvases[name])
        t_backbone = clock.lap()
        if self.fusion is not None:
            fused = tuple(
                fuse(f_l, f_r)
                for fuse, f_l, f_r in zip(self.fusion, stages["l"], stages["r"], strict=True)
            )
        else:
            fused = stages["l"] if "l" in stages else stages["r"]
        return SensorStages(
            tuple(fused),
            stages.get("l"),
            stages.get("r"),
            SceneTimings(t_pillars, t_backbone, clock.lap()),
        )

    def detector(self, stages: Sequence[Tensor]) -> tuple[Tensor, HeadOutput]:
        """The FPN output ``(B, C, H, W)`` and the head's output on three stages."""
        neck = self.neck(list(stages))
        return neck, self.head(neck)

    def detect(
        self, lidar: list[Tensor] | None, radar: list[Tensor] | None
    ) -> tuple[HeadOutput, list[SceneMaps]]:
        """The text-agnostic detector on a batch of checked clouds.

        Returns:
            The head output (``heatmap (B, 3, H, W)`` logits, ``regression (B, 8, H, W)``) and,
            per item, the BEV maps the referent stage pools from (:class:`SceneMaps`).
        """
        stages = self.sensors(lidar, radar)
        neck, out = self.detector(stages.fused)
        return out, [stages.maps(neck, b) for b in range(neck.shape[0])]
