"""TPCNet (fig. 3, section III-A): LiDAR and radar pillar branches, BACA fusion, text encoder,
DGGF, SECOND-FPN and the C3D-RECHead, assembled from a :class:`model.config.ModelConfig`.

Data flow per sample (LiDAR frame throughout)::

    lidar (N, 4) -> PillarEncoder -> SecondBackbone -> f^l_1..3 --+
                                                                   +-> fusion_i -> lr_i  (no text)
    radar (M, 7) -> PillarEncoder -> SecondBackbone -> f^r_1..3 --+
    prompt -> text encoder -> tokens (L, D), mask
    (lr_i, tokens) -> DGGF_i -> lc_i ;  FPN(lc_1..3) -> f ;  head(f) -> heatmap (3, H, W), regression

The sensor branches and the LiDAR-radar fusion do not depend on the text, so the model splits in
two calls for the app: :meth:`TPCNet.encode_scene` (once per scene) and :meth:`TPCNet.ground`
(once per prompt, from the cached :class:`SceneFeatures`). :meth:`TPCNet.forward` runs both on a
batch for training; in eval mode ``ground(encode_scene(l, r), p)`` gives the same head outputs as
``forward([l], [r], [p])`` (every normalisation is per sample or in running-statistics mode).

Input rules: points are numpy arrays or tensors ``(N, 4)`` (x, y, z, intensity) and ``(M, 7)``
(x, y, z, rcs, v_r, v_r_compensated, time), radar already in the LiDAR frame. NaN or inf raise
:class:`NonFiniteInputError` naming the sensor and row *before* anything reaches the network. An
empty array (a sensor that returned nothing) is fine. A single-modality model ignores the other
sensor (it may be ``None``); a missing required sensor (``None``) raises :class:`MissingSensorError`
that says which sensor the model was built for.

``encode_scene``/``ground`` run under ``torch.no_grad`` and do not switch the mode: call
``model.eval()`` first for inference.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor, nn

from model.baca import build_fusion
from model.backbone import SecondBackbone
from model.config import LIDAR_FEATURES, RADAR_FEATURES, ModelConfig
from model.decode import decode
from model.dggf import DynamicGatedGraphFusion, GatedGraphFusion
from model.fpn import SecondFpn
from model.grid import BevGrid
from model.grounder import (
    SceneCandidates,
    SceneMaps,
    describe_candidates,
    referent_heatmap,
    stack_candidates,
)
from model.head import C3DRecHead, HeadOutput
from model.labelled import LabelledBoxes, anchor_scores, with_context
from model.pillars import PillarEncoder
from model.referent import ReferentStage
from model.text import TextFeatures, build_text_encoder, validate_prompt
from scenes.actors import CLASSES

PointsLike = np.ndarray | Tensor


class NonFiniteInputError(ValueError):
    """A point cloud holds NaN or inf values."""


class MissingSensorError(ValueError):
    """The model needs a sensor's points that were not given."""


@dataclass(frozen=True)
class SceneTimings:
    """Milliseconds spent in :meth:`TPCNet.encode_scene`, per stage."""

    pillars: float
    backbone: float
    fusion: float
    detect: float = 0.0
    """``grounding="referent"``: neck, head, decoding and candidate description."""

    @property
    def total(self) -> float:
        return self.pillars + self.backbone + self.fusion + self.detect


@dataclass(frozen=True)
class GroundTimings:
    """Milliseconds spent in :meth:`TPCNet.ground`, per stage."""

    text: float
    dggf: float
    neck: float
    head: float
    decode: float
    referent: float = 0.0
    """``grounding="referent"``: the referent stage (then ``dggf``, ``neck``, ``head`` are 0)."""

    @property
    def total(self) -> float:
        return self.text + self.dggf + self.neck + self.head + self.decode + self.referent


@dataclass(frozen=True)
class SceneFeatures:
    """Text-independent features of one scene.

    Attributes:
        stages: ``(lr_1, lr_2, lr_3)``, each ``(1, C_i, H_i, W_i)`` on the model's device.
        num_lidar: LiDAR points given (before range filtering); 0 when unused.
        num_radar: Radar points given; 0 when unused.
        timings: Time per stage of the encoding.
        objects: ``grounding="referent"`` only: the text-agnostic detections of the scene as
            referent-stage candidates, and the detector's ``(3, H, W)`` sigmoid heatmaps.
        answerable: With labelled candidates (:mod:`model.labelled`): the first this many
            candidates are the labelled boxes, the only possible answers (the rest is context).
            None: every candidate may be an answer.
    """

    stages: tuple[Tensor, ...]
    num_lidar: int
    num_radar: int
    timings: SceneTimings
    objects: SceneCandidates | None = None
    detection_heatmaps: np.ndarray | None = None
    answerable: int | None = None


@dataclass(frozen=True)
class Predictions:
    """The answer to one prompt.

    Attributes:
        boxes: ``(K, 7)`` float64 ``x, y, z, l, w, h, yaw``, LiDAR frame, sorted by score.
        scores: ``(K,)`` float64 in ``[0, 1]``.
        labels: ``(K,)`` int64 indices into ``scenes.actors.CLASSES``.
        classes: ``K`` class names.
        heatmaps: ``(3, H, W)`` float32 sigmoid heatmaps (Car, Pedestrian, Cyclist) on ``grid``,
            ``heatmaps[c, iy, ix]``.
        grid: The head's BEV grid.
        prompt: The prompt as encoded (stripped).
        truncated: Whether the prompt exceeded the text encoder's token limit.
        timings: Time per stage of the grounding.
    """

    boxes: np.ndarray
    scores: np.ndarray
    labels: np.ndarray
    classes: tuple[str, ...]
    heatmaps: np.ndarray
    grid: BevGrid
    prompt: str
    truncated: bool
    timings: GroundTimings


def as_points(points: PointsLike, num_features: int, name: str) -> Tensor:
    """Validate one cloud and return it as a float32 CPU-or-device tensor ``(N, F)``.

    Raises:
        TypeError: not an array or tensor.
        ValueError: wrong shape.
        NonFiniteInputError: NaN or inf values (names the first bad row).
    """
    if isinstance(points, np.ndarray):
        tensor = torch.from_numpy(np.ascontiguousarray(points, dtype=np.float32))
    elif isinstance(points, Tensor):
        tensor = points.detach().to(torch.float32)
    else:
        raise TypeError(f"{name} must be a numpy array or a torch tensor, got {type(points)}")
    if tensor.numel() == 0:
        return tensor.reshape(0, num_features)
    if tensor.dim() != 2 or tensor.shape[1] != num_features:
        raise ValueError(f"{name} must have shape (N, {num_features}), got {tuple(tensor.shape)}")
    # One sum is finite exactly when every value is (or it overflowed: then look row by row).
    if not bool(torch.isfinite(tensor.sum())) and not bool(torch.isfinite(tensor).all()):
        finite = torch.isfinite(tensor).all(dim=1)
        row = int(torch.nonzero(~finite)[0, 0])
        raise NonFiniteInputError(
            f"{name} has NaN or inf values (first at row {row}: {tensor[row].tolist()}); "
            "remove or fix those points before running the model"
        )
    return tensor


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


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class _Clock:
    """Wall-clock lap timer in milliseconds (synchronising CUDA before each reading).

    Disabled (``enabled=False``, as in training) it returns 0 and never synchronises.
    """

    def __init__(self, device: torch.device, enabled: bool = True) -> None:
        self.device = device
        self.enabled = enabled
        if enabled:
            _sync(device)
        self.last = time.perf_counter()

    def lap(self) -> float:
        if not self.enabled:
            return 0.0
        _sync(self.device)
        now = time.perf_counter()
        ms, self.last = (now - self.last) * 1000.0, now
        return ms


class TPCNet(nn.Module):
    """The TPCNet model. Build it with :func:`model.build_model` or ``TPCNet(ModelConfig(...))``."""

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
        self.text_encoder = build_text_encoder(cfg.text)
        text_dim = self.text_encoder.out_dim
        self.text_fusion: nn.ModuleList | None = None
        if cfg.grounding == "tpcnet" and cfg.text_fusion.kind == "dggf":
            self.text_fusion = nn.ModuleList(
                DynamicGatedGraphFusion(c, text_dim, k, cfg.text_fusion.ffn_ratio)
                for c, k in zip(channels, cfg.text_fusion.graph_k, strict=True)
            )
        elif cfg.grounding == "tpcnet":
            self.text_fusion = nn.ModuleList(
                GatedGraphFusion(c, text_dim, cfg.text_fusion.ggf_k) for c in channels
            )
        self.neck = SecondFpn(channels, cfg.backbone.cumulative_strides, cfg.fpn)
        self.head = C3DRecHead(cfg.head, self.neck.out_channels)
        self.referent: ReferentStage | None = None
        if cfg.grounding == "referent":
            # Candidate maps are pooled at two points (centre, anchor): see model.grounder.
            self.referent = ReferentStage(
                cfg.referent,
                text_dim,
                2 * self.neck.out_channels,
                2 * channels[0] if cfg.uses_lidar else None,
                2 * channels[0] if cfg.uses_radar else None,
            )
        self.checkpoint_metadata: dict = {}
        """Metadata of the checkpoint this model was loaded from (see :mod:`model.checkpoint`)."""

    @property
    def device(self) -> torch.device:
        return next(self.parameters()).device

    # ------------------------------------------------------------------ input handling

    def _clouds(
        self,
        clouds: Sequence[PointsLike | None] | None,
        batch: int,
        sensor: str,
        num_features: int,
        used: bool,
    ) -> list[Tensor] | None:
        if not used:
            return None
        label = "LiDAR" if sensor == "lidar" else "radar"
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

    # ------------------------------------------------------------------ the two halves

    def _encode(
        self, lidar: list[Tensor] | None, radar: list[Tensor] | None, timed: bool = False
    ) -> tuple[tuple[Tensor, ...], dict[str, tuple[Tensor, ...]], SceneTimings]:
        """Fused stages ``lr_1..3``, each sensor's own stages (``"l"``, ``"r"``) and timings."""
        clock = _Clock(self.device, timed)
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
        return fused, stages, SceneTimings(t_pillars, t_backbone, clock.lap())

    def detect(
        self, lidar: list[Tensor] | None, radar: list[Tensor] | None
    ) -> tuple[HeadOutput, list[SceneMaps]]:
        """``grounding="referent"``: the text-agnostic detector on a batch of validated clouds.

        Returns:
            The head output (``heatmap (B, 3, H, W)`` logits, ``regression (B, 8, H, W)``) and,
            per item, the BEV maps the referent stage pools from (:class:`SceneMaps`).
        """
        fused, stages, _ = self._encode(lidar, radar)
        neck = self.neck(list(fused))
        out = self.head(neck)
        maps = [
            SceneMaps(
                fused=neck[b],
                lidar=stages["l"][0][b] if "l" in stages else None,
                radar=stages["r"][0][b] if "r" in stages else None,
            )
            for b in range(neck.shape[0])
        ]
        return out, maps

    def candidates(
        self,
        boxes: np.ndarray,
        labels: np.ndarray,
        scores: np.ndarray,
        maps: SceneMaps,
        lidar: np.ndarray | None,
        radar: np.ndarray | None,
    ) -> SceneCandidates:
        """:func:`model.grounder.describe_candidates` with this model's grid and anchor."""
        return describe_candidates(
            boxes,
            labels,
            scores,
            maps,
            self.head_grid,
            self.cfg.head.anchor,
            lidar if self.cfg.uses_lidar else None,
            radar if self.cfg.uses_radar else None,
        )

    def refer(self, cands: SceneCandidates | list[SceneCandidates], text: TextFeatures) -> Tensor:
        """Referent logits ``(N, K)`` of ``N`` prompts; ``cands`` is one scene shared by all the
        prompts, or one scene per prompt."""
        assert self.referent is not None
        scenes = [cands] if isinstance(cands, SceneCandidates) else list(cands)
        batch = stack_candidates(scenes)
        n = text.tokens.shape[0]
        if len(scenes) == 1 and n > 1:
            batch = batch.index(torch.zeros(n, dtype=torch.long, device=batch.padding.device))
        return self.referent(batch, text.tokens, text.numbers, text.padding_mask)

    def _ground(
        self, stages: Sequence[Tensor], text: TextFeatures, timed: bool = False
    ) -> tuple[HeadOutput, tuple[float, float, float]]:
        clock = _Clock(self.device, timed)
        conditioned = [
            fuse(lr, text.tokens, text.padding_mask)
            for fuse, lr in zip(self.text_fusion, stages, strict=True)
        ]
        t_dggf = clock.lap()
        neck = self.neck(conditioned)
        t_neck = clock.lap()
        out = self.head(neck)
        return out, (t_dggf, t_neck, clock.lap())

    # ------------------------------------------------------------------ public API

    def encode_scene(
        self,
        lidar: PointsLike | None = None,
        radar: PointsLike | None = None,
        candidates: LabelledBoxes | None = None,
    ) -> SceneFeatures:
        """Text-independent features of one scene (sensor branches + LiDAR-radar fusion; with
        ``grounding="referent"`` also the text-agnostic detections as candidates).

        Args:
            lidar: ``(N, 4)`` LiDAR points (x, y, z, intensity), LiDAR frame; ignored (may be
                ``None``) by a radar-only model.
            radar: ``(M, 7)`` radar points in the LiDAR frame; ignored by a LiDAR-only model.
            candidates: Referent path only: the frame's labelled boxes, among which the referent
                stage then chooses instead of the detector's proposals (each gets the detector's
                score at its anchor cell, :func:`model.labelled.anchor_scores`).

        Returns:
            :class:`SceneFeatures` with ``lr_i`` of shape ``(1, C_i, H_i, W_i)``.
        """
        if candidates is not None and self.referent is None:
            raise ValueError(
                "labelled candidates need a referent-path model; the paper's path ranks "
                "its own heatmap peaks"
            )
        lidar_t = self._clouds(
            None if lidar is None else [lidar], 1, "lidar", LIDAR_FEATURES, self.cfg.uses_lidar
        )
        radar_t = self._clouds(
            None if radar is None else [radar], 1, "radar", RADAR_FEATURES, self.cfg.uses_radar
        )
        objects, heat, answerable = None, None, None
        with torch.no_grad():
            stages, per_sensor, timings = self._encode(lidar_t, radar_t, timed=True)
            if self.referent is not None:
                clock = _Clock(self.device)
                neck = self.neck(list(stages))
                out = self.head(neck)
                heat = torch.sigmoid(out.heatmap[0]).float().cpu().numpy()
                dets = decode(
                    out,
                    self.head_grid,
                    self.cfg.head,
                    self.cfg.referent.candidate_threshold,
                    limit=self.cfg.referent.max_candidates,
                )[0]
                keep = slice(0, self.cfg.referent.max_candidates)
                boxes, labels = dets.boxes[keep], dets.labels[keep]
                scores = dets.scores[keep]
                if candidates is not None:
                    answerable = len(candidates)
                    boxes, labels, scores = with_context(
                        candidates,
                        anchor_scores(
                            heat,
                            candidates.boxes,
                            candidates.labels,
                            self.head_grid,
                            self.cfg.head.anchor,
                        ),
                        boxes,
                        labels,
                        scores,
                        self.cfg.referent.max_candidates,
                    )
                maps = SceneMaps(
                    neck[0],
                    per_sensor["l"][0][0] if "l" in per_sensor else None,
                    per_sensor["r"][0][0] if "r" in per_sensor else None,
                )
                objects = self.candidates(
                    boxes,
                    labels,
                    scores,
                    maps,
                    None if lidar_t is None else lidar_t[0].cpu().numpy(),
                    None if radar_t is None else radar_t[0].cpu().numpy(),
                )
                timings = dataclasses.replace(timings, detect=clock.lap())
        return SceneFeatures(
            stages=tuple(stages),
            num_lidar=0 if lidar_t is None else int(lidar_t[0].shape[0]),
            num_radar=0 if radar_t is None else int(radar_t[0].shape[0]),
            timings=timings,
            objects=objects,
            detection_heatmaps=heat,
            answerable=answerable,
        )

    def ground(
        self, features: SceneFeatures, prompt: str, score_threshold: float | None = None
    ) -> Predictions:
        """Answer one prompt on an encoded scene.

        Args:
            features: From :meth:`encode_scene` of this model.
            prompt: The referring sentence (non-empty; longer than the token limit is truncated
                and reported in :attr:`Predictions.truncated`).
            score_threshold: Smallest score returned. Default: ``cfg.head.score_threshold`` for
                the paper's path (a decoded heatmap peak), ``cfg.referent.min_score`` for the
                referent stage (a referent probability); the returned *set* at the checkpoint's
                operating threshold is :func:`model.predict.operating_threshold`'s business.

        Returns:
            :class:`Predictions` (boxes, scores, class names, sigmoid heatmaps, grid, timings).
        """
        text_prompt = validate_prompt(prompt)
        expected = tuple(self.cfg.backbone.channels)
        got = tuple(int(s.shape[1]) for s in features.stages)
        if got != expected or any(s.shape[0] != 1 for s in features.stages):
            raise ValueError(
                f"scene features with stage widths {got} do not come from this model "
                f"(expects {expected}, batch 1)"
            )
        if self.referent is not None:
            return self._ground_referent(features, text_prompt, score_threshold)
        clock = _Clock(self.device)
        with torch.no_grad():
            text = self.text_encoder([text_prompt])
            t_text = clock.lap()
            out, (t_dggf, t_neck, t_head) = self._ground(features.stages, text, timed=True)
            clock.lap()
            detections = decode(out, self.head_grid, self.cfg.head, score_threshold)[0]
            heatmaps = torch.sigmoid(out.heatmap[0]).float().cpu().numpy()
            t_decode = clock.lap()
        return Predictions(
            boxes=detections.boxes,
            scores=detections.scores,
            labels=detections.labels,
            classes=detections.classes,
            heatmaps=heatmaps,
            grid=self.head_grid,
            prompt=text_prompt,
            truncated=text.truncated[0],
            timings=GroundTimings(t_text, t_dggf, t_neck, t_head, t_decode),
        )

    def _ground_referent(
        self, features: SceneFeatures, prompt: str, score_threshold: float | None
    ) -> Predictions:
        objects, heat = features.objects, features.detection_heatmaps
        if objects is None or heat is None:
            raise ValueError(
                "scene features without candidates: encode the scene with this model "
                "(grounding='referent')"
            )
        threshold = self.cfg.referent.min_score if score_threshold is None else score_threshold
        clock = _Clock(self.device)
        with torch.no_grad():
            text = self.text_encoder([prompt])
            t_text = clock.lap()
            if len(objects):
                probs = torch.sigmoid(self.refer(objects, text)[0]).float().cpu().numpy()
            else:
                probs = np.zeros(0, dtype=np.float32)
            t_ref = clock.lap()
        probs = probs.astype(np.float64)
        if features.answerable is not None:  # labelled candidates; the proposals are context
            probs[features.answerable :] = 0.0
        order = np.argsort(-probs, kind="stable")
        order = order[probs[order] >= threshold]
        if features.answerable is not None:
            order = order[order < features.answerable]
        heatmaps = referent_heatmap(
            heat, objects.boxes, objects.labels, probs, self.head_grid, self.cfg.head.anchor
        )
        labels = objects.labels[order]
        return Predictions(
            boxes=objects.boxes[order],
            scores=probs[order],
            labels=labels,
            classes=tuple(CLASSES[i] for i in labels),
            heatmaps=heatmaps,
            grid=self.head_grid,
            prompt=prompt,
            truncated=text.truncated[0],
            timings=GroundTimings(t_text, 0.0, 0.0, 0.0, clock.lap(), referent=t_ref),
        )

    def forward(
        self,
        lidar: Sequence[PointsLike | None] | None,
        radar: Sequence[PointsLike | None] | None,
        prompts: Sequence[str],
    ) -> HeadOutput:
        """Batched training/evaluation pass of the paper's path (``grounding="tpcnet"``).

        Args:
            lidar: ``B`` LiDAR clouds ``(N_b, 4)`` (``None`` for a radar-only model).
            radar: ``B`` radar clouds ``(M_b, 7)`` in the LiDAR frame (``None`` for LiDAR-only).
            prompts: ``B`` prompts.

        Returns:
            :class:`model.head.HeadOutput` with ``heatmap (B, 3, H, W)`` logits and
            ``regression (B, 8, H, W)`` on :attr:`head_grid`; train it with
            :func:`model.losses.grounding_loss`. The referent path trains through
            :meth:`detect`, :meth:`candidates` and :meth:`refer` (:mod:`model.referent_train`).
        """
        if self.text_fusion is None:
            raise ValueError(
                "forward() is the paper's text-conditioned pass; a grounding='referent' model "
                "trains through detect() / candidates() / refer()"
            )
        batch = len(prompts)
        if batch == 0:
            raise ValueError("forward needs at least one sample")
        prompts = [validate_prompt(p) for p in prompts]  # fail before any network work
        lidar_t = self._clouds(lidar, batch, "lidar", LIDAR_FEATURES, self.cfg.uses_lidar)
        radar_t = self._clouds(radar, batch, "radar", RADAR_FEATURES, self.cfg.uses_radar)
        stages, _, _ = self._encode(lidar_t, radar_t)
        text = self.text_encoder(prompts)
        out, _ = self._ground(stages, text)
        return out
