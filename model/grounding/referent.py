"""The referent grounding head (``grounding="referent"``, the shipped checkpoint): the shared
detector proposes every object of a scene once (:meth:`ReferentGrounding.encode`: decoding at the
candidate threshold, :func:`model.referent.scene_candidates.describe_candidates`); per prompt only the text encoder
and the referent stage (:class:`model.referent.stage.ReferentStage`) run, and the answer is the
candidates whose referent probability reaches the threshold, with
:class:`model.referent.heatmap.ReferentCanvas` (kept per scene) drawing its heatmap. Training: :meth:`proposals`,
:meth:`describe` and :meth:`prompt_losses` (:mod:`model.training.referent_step`)."""

from __future__ import annotations

import weakref
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor, nn

from model.config import ModelConfig
from model.core.candidates import SceneCandidates, SceneMaps
from model.core.features import (
    Clock,
    GroundTimings,
    PointsLike,
    Predictions,
    SceneFeatures,
)
from model.core.labelled import LabelledBoxes, with_context
from model.grounding.interface import GroundingHead
from model.grounding.scene_encoder import SceneEncoder
from model.head.decode import Detections, decode
from model.head.detector import HeadOutput
from model.nets.text import TextFeatures
from model.referent.heatmap import ReferentCanvas
from model.referent.scene_candidates import describe_candidates, stack_candidates
from model.referent.stage import CandidateBatch, ReferentStage, SceneEmbeddings, referent_loss

UNCALIBRATED_REFERENT = 0.5
"""Operating threshold of a referent-path checkpoint that was never calibrated: a referent
probability, the decision boundary its BCE training draws."""


class ReferentGrounding(GroundingHead):
    """The referent stage (``stage``) over the detector's candidates."""

    takes_labelled_candidates = True
    takes_alternatives = True

    def __init__(self, cfg: ModelConfig, text_dim: int, neck_channels: int) -> None:
        super().__init__()
        self.cfg = cfg
        first = cfg.backbone.channels[0]
        # Candidate maps are pooled at two points (centre, anchor): see model.referent.scene_candidates.
        self.stage = ReferentStage(
            cfg.referent,
            text_dim,
            2 * neck_channels,
            2 * first if cfg.uses_lidar else None,
            2 * first if cfg.uses_radar else None,
            len(cfg.class_set),
        )
        self._kept_scene: (
            tuple[weakref.ref[SceneCandidates], tuple, CandidateBatch, SceneEmbeddings] | None
        ) = None
        self._kept_canvas: tuple[weakref.ref, weakref.ref, ReferentCanvas] | None = None

    @classmethod
    def build(cls, cfg: ModelConfig, text_dim: int, neck_channels: int) -> ReferentGrounding:
        return cls(cfg, text_dim, neck_channels)

    @property
    def min_score(self) -> float:
        return float(self.cfg.referent.min_score)

    @property
    def uncalibrated_threshold(self) -> float:
        return UNCALIBRATED_REFERENT

    def proposals(
        self, scene: SceneEncoder, out: HeadOutput, limit: int | None
    ) -> list[Detections]:
        """The detector's boxes of a batch at the candidate threshold (at most ``limit``)."""
        threshold = self.cfg.referent.candidate_threshold
        return decode(out, scene.head_grid, self.cfg.head, threshold, limit=limit)

    def describe(
        self,
        scene: SceneEncoder,
        boxes: np.ndarray,
        labels: np.ndarray,
        scores: np.ndarray,
        maps: SceneMaps,
        lidar: np.ndarray | None,
        radar: np.ndarray | None,
    ) -> SceneCandidates:
        """:func:`model.referent.scene_candidates.describe_candidates` with this model's grid and anchor."""
        return describe_candidates(
            boxes,
            labels,
            scores,
            maps,
            scene.head_grid,
            self.cfg.head.anchor,
            lidar if self.cfg.uses_lidar else None,
            radar if self.cfg.uses_radar else None,
            context=self.cfg.referent.context,
            subsets=self.cfg.referent.subset_ranks,
            num_classes=len(self.cfg.class_set),
        )

    def refer(self, cands: SceneCandidates | list[SceneCandidates], text: TextFeatures) -> Tensor:
        """Referent logits ``(N, K)`` of ``N`` prompts; ``cands`` is one scene shared by all the
        prompts, or one scene per prompt.

        At inference (eval mode, no gradient) on one scene, the scene's batch and its
        :meth:`ReferentStage.scene_embeddings` are kept for the next prompt on the same scene
        (:meth:`_scene_batch`): per prompt only what depends on the text runs."""
        scenes = [cands] if isinstance(cands, SceneCandidates) else list(cands)
        n = text.tokens.shape[0]
        embedded = None
        if len(scenes) == 1 and n == 1 and not self.training and not torch.is_grad_enabled():
            batch, embedded = self._scene_batch(scenes[0])
        else:
            batch = stack_candidates(scenes)
        if len(scenes) == 1 and n > 1:
            batch = batch.index(torch.zeros(n, dtype=torch.long, device=batch.padding.device))
        return self.stage(batch, text.tokens, text.numbers, text.padding_mask, embedded)

    def _scene_batch(self, cands: SceneCandidates) -> tuple[CandidateBatch, SceneEmbeddings]:
        """One scene's batch and its text-free embeddings, from a one-scene memory when the
        scene is the one asked last and the embeddings' weights are the ones they were computed
        with (checked by each parameter's storage and version counter, which every in-place
        update, an optimiser step or ``load_state_dict``, advances)."""
        stage = self.stage
        weights = tuple(
            (p.data_ptr(), p._version)
            for module in (stage.fused, stage.lidar, stage.radar)
            if module is not None
            for p in module.parameters()
        )
        kept = self._kept_scene
        if kept is not None and kept[0]() is cands and kept[1] == weights:
            return kept[2], kept[3]
        batch = stack_candidates([cands])
        embedded = self.stage.scene_embeddings(batch)
        self._kept_scene = (weakref.ref(cands), weights, batch, embedded)
        return batch, embedded

    def _canvas(
        self, scene: SceneEncoder, objects: SceneCandidates, heat: np.ndarray
    ) -> ReferentCanvas:
        """The scene's :class:`ReferentCanvas` (the text-free part of the answer's heatmap),
        from a one-scene memory when ``objects`` and ``heat`` are the ones asked last."""
        kept = self._kept_canvas
        if kept is not None and kept[0]() is objects and kept[1]() is heat:
            return kept[2]
        canvas = ReferentCanvas.of(
            heat, objects.boxes, objects.labels, scene.head_grid, self.cfg.head.anchor
        )
        self._kept_canvas = (weakref.ref(objects), weakref.ref(heat), canvas)
        return canvas

    def prompt_losses(
        self,
        scenes: Sequence[SceneCandidates],
        rows: Sequence[int],
        text: TextFeatures,
        targets: Sequence[np.ndarray],
    ) -> tuple[Tensor, Tensor]:
        """The referent losses of ``N`` prompts (training): prompt ``i`` asks about
        ``scenes[rows[i]]``, its encoded text is row ``i`` of ``text`` and ``targets[i]`` marks its
        referents among that scene's candidates (``(K_scene,)`` float32, 1 for a referent).
        Returns :func:`model.referent.stage.referent_loss`'s BCE and listwise term."""
        device = next(self.stage.parameters()).device
        batch = stack_candidates(scenes).index(torch.tensor(list(rows)))
        batch = CandidateBatch(
            batch.geometry.to(device),
            batch.fused.to(device),
            None if batch.lidar is None else batch.lidar.to(device),
            None if batch.radar is None else batch.radar.to(device),
            batch.padding.to(device),
        )
        logits = self.stage(batch, text.tokens, text.numbers, text.padding_mask)
        target = torch.zeros_like(logits)
        for i, t in enumerate(targets):
            target[i, : len(t)] = torch.from_numpy(t).to(device)
        return referent_loss(logits, target, batch.padding)

    def encode(
        self,
        scene: SceneEncoder,
        lidar: list[Tensor] | None,
        radar: list[Tensor] | None,
        candidates: LabelledBoxes | None,
    ) -> SceneFeatures:
        return self.encode_views(scene, lidar, radar, (candidates,))[0]

    def encode_views(
        self,
        scene: SceneEncoder,
        lidar: list[Tensor] | None,
        radar: list[Tensor] | None,
        views: Sequence[LabelledBoxes | None],
    ) -> list[SceneFeatures]:
        """:meth:`encode` of one scene for each of ``views`` (None: the detector's proposals;
        labelled boxes: those, with the proposals that overlap none of them as context), from one
        pass of the sensors and the detector (the ``--freeze-scene`` cache describes a scene both
        ways)."""
        stages = scene.sensors(lidar, radar, timed=True)
        clock = Clock(scene.device)
        limit = self.cfg.referent.max_candidates
        neck, out = scene.detector(stages.fused)
        heat = torch.sigmoid(out.heatmap[0]).float().cpu().numpy()
        dets = self.proposals(scene, out, limit)[0]
        keep = slice(0, limit)
        maps = stages.maps(neck, 0)
        lidar_np = None if lidar is None else lidar[0].cpu().numpy()
        radar_np = None if radar is None else radar[0].cpu().numpy()
        result = []
        for candidates in views:
            boxes, labels, scores = dets.boxes[keep], dets.labels[keep], dets.scores[keep]
            answerable = None
            if candidates is not None:
                answerable = len(candidates)
                boxes, labels, scores = with_context(candidates, boxes, labels, scores, limit)
            objects = self.describe(scene, boxes, labels, scores, maps, lidar_np, radar_np)
            result.append(
                stages.features(
                    lidar,
                    radar,
                    clock.lap(),
                    objects=objects,
                    detection_heatmaps=heat,
                    answerable=answerable,
                )
            )
        return result

    def check(self, scene: SceneEncoder, features: SceneFeatures) -> None:
        if features.objects is None or features.detection_heatmaps is None:
            raise ValueError(
                "scene features without candidates: encode the scene with this model "
                "(grounding='referent')"
            )

    def answer(
        self,
        scene: SceneEncoder,
        features: SceneFeatures,
        text: TextFeatures,
        prompt: str,
        score_threshold: float | None,
    ) -> Predictions:
        objects, heat = features.objects, features.detection_heatmaps
        assert objects is not None and heat is not None  # check()
        threshold = self.min_score if score_threshold is None else score_threshold
        clock = Clock(scene.device)
        if len(objects):
            with torch.inference_mode():  # (numbers out: nothing of it is kept for autograd)
                # one row per text of the sentence's reading: a candidate's probability is
                # its best over them ("the vehicle": the car, the truck, ...)
                logits = self.refer(objects, text)
                probs = torch.sigmoid(logits).amax(dim=0).float().cpu().numpy()
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
        heatmaps = self._canvas(scene, objects, heat).draw(probs)
        labels = objects.labels[order]
        return Predictions(
            boxes=objects.boxes[order],
            scores=probs[order],
            labels=labels,
            classes=tuple(self.cfg.class_set.names[i] for i in labels),
            heatmaps=heatmaps,
            grid=scene.head_grid,
            prompt=prompt,
            truncated=text.truncated[0],
            timings=GroundTimings(0.0, 0.0, 0.0, 0.0, clock.lap(), referent=t_ref),
        )

    def forward_batch(
        self,
        scene: SceneEncoder,
        text_encoder: nn.Module,
        lidar: Sequence[PointsLike | None] | None,
        radar: Sequence[PointsLike | None] | None,
        prompts: Sequence[str],
    ) -> HeadOutput:
        raise ValueError(
            "forward() is the paper's text-conditioned pass; a grounding='referent' model "
            "trains through detect() and its referent head (model.training.referent_step)"
        )


def referent_head(model: nn.Module) -> ReferentGrounding:
    """``model``'s referent head (``model.grounding``).

    Raises:
        ValueError: ``model`` is not a referent-path model (``grounding="referent"``).
    """
    head = getattr(model, "grounding", None)
    if not isinstance(head, ReferentGrounding):
        raise ValueError("this needs a referent-path model (grounding='referent')")
    return head
