"""The paper's grounding head (``grounding="tpcnet"``, section III-C/D): DGGF (or GGF) gates each
fused stage with the prompt's tokens, then the shared FPN and C3D-RECHead rank the referred boxes
by their heatmap peaks. Training: :meth:`PaperGrounding.forward_batch` and
:meth:`PaperGrounding.loss` (:func:`model.head.losses.grounding_loss`)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from model.config import ConfigError, ModelConfig
from model.core.features import Clock, GroundTimings, PointsLike, Predictions, SceneFeatures
from model.core.labelled import LabelledBoxes
from model.grounding.interface import GroundingHead
from model.grounding.scene_encoder import SceneEncoder
from model.head.decode import decode
from model.head.detector import HeadOutput
from model.head.losses import LossTerms, grounding_loss
from model.head.targets import BatchTargets
from model.nets.dggf import DynamicGatedGraphFusion, GatedGraphFusion
from model.nets.text import TextFeatures, validate_prompt


class PaperGrounding(GroundingHead):
    """DGGF per stage (``text_fusion``) before the shared detector."""

    def __init__(self, cfg: ModelConfig, text_dim: int) -> None:
        super().__init__()
        if cfg.pillars.ground != "sensor":
            raise ConfigError(
                "ModelConfig.pillars.ground 'estimated' needs grounding='referent' (the paper's "
                "path decodes its boxes inside ground())",
                "pillars.ground",
            )
        self.cfg = cfg
        channels = cfg.backbone.channels
        tf = cfg.text_fusion
        if tf.kind == "dggf":
            self.text_fusion = nn.ModuleList(
                DynamicGatedGraphFusion(c, text_dim, k, tf.ffn_ratio)
                for c, k in zip(channels, tf.graph_k, strict=True)
            )
        else:
            self.text_fusion = nn.ModuleList(
                GatedGraphFusion(c, text_dim, tf.ggf_k) for c in channels
            )

    @classmethod
    def build(cls, cfg: ModelConfig, text_dim: int, neck_channels: int) -> PaperGrounding:
        return cls(cfg, text_dim)

    @property
    def min_score(self) -> float:
        return float(self.cfg.head.score_threshold)

    @property
    def uncalibrated_threshold(self) -> float:
        return float(self.cfg.head.score_threshold)

    def encode(
        self,
        scene: SceneEncoder,
        lidar: list[Tensor] | None,
        radar: list[Tensor] | None,
        candidates: LabelledBoxes | None,
    ) -> SceneFeatures:
        return scene.sensors(lidar, radar, timed=True).features(lidar, radar)

    def check(self, scene: SceneEncoder, features: SceneFeatures) -> None:
        expected = scene.stage_channels
        got = tuple(int(s.shape[1]) for s in features.stages)
        if got != expected or any(s.shape[0] != 1 for s in features.stages):
            raise ValueError(
                f"scene features with stage widths {got} do not come from this model "
                f"(expects {expected}, batch 1)"
            )

    def condition(
        self, scene: SceneEncoder, stages: Sequence[Tensor], text: TextFeatures, timed: bool = False
    ) -> tuple[HeadOutput, tuple[float, float, float]]:
        """DGGF of each stage with the text, then the shared detector; the times of the three."""
        clock = Clock(scene.device, timed)
        conditioned = [
            fuse(lr, text.tokens, text.padding_mask)
            for fuse, lr in zip(self.text_fusion, stages, strict=True)
        ]
        t_dggf = clock.lap()
        neck = scene.neck(conditioned)
        t_neck = clock.lap()
        out = scene.head(neck)
        return out, (t_dggf, t_neck, clock.lap())

    def answer(
        self,
        scene: SceneEncoder,
        features: SceneFeatures,
        text: TextFeatures,
        prompt: str,
        score_threshold: float | None,
    ) -> Predictions:
        out, (t_dggf, t_neck, t_head) = self.condition(scene, features.stages, text, timed=True)
        clock = Clock(scene.device)
        detections = decode(out, scene.head_grid, self.cfg.head, score_threshold)[0]
        heatmaps = torch.sigmoid(out.heatmap[0]).float().cpu().numpy()
        t_decode = clock.lap()
        return Predictions(
            boxes=detections.boxes,
            scores=detections.scores,
            labels=detections.labels,
            classes=detections.classes,
            heatmaps=heatmaps,
            grid=scene.head_grid,
            prompt=prompt,
            truncated=text.truncated[0],
            timings=GroundTimings(0.0, t_dggf, t_neck, t_head, t_decode),
        )

    def forward_batch(
        self,
        scene: SceneEncoder,
        text_encoder: nn.Module,
        lidar: Sequence[PointsLike | None] | None,
        radar: Sequence[PointsLike | None] | None,
        prompts: Sequence[str],
    ) -> HeadOutput:
        batch = len(prompts)
        if batch == 0:
            raise ValueError("forward needs at least one sample")
        prompts = [validate_prompt(p) for p in prompts]  # fail before any network work
        lidar_t = scene.clouds(lidar, batch, "lidar")
        radar_t = scene.clouds(radar, batch, "radar")
        stages = scene.sensors(lidar_t, radar_t)
        text = text_encoder(prompts)
        out, _ = self.condition(scene, stages.fused, text)
        return out

    @staticmethod
    def loss(out: HeadOutput, targets: BatchTargets) -> LossTerms:
        """:func:`model.head.losses.grounding_loss` of :meth:`forward_batch`'s output."""
        return grounding_loss(out, targets)
