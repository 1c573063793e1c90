"""One training step of the referent path: detection of every actor + referents of generated prompts.

Per batch of ``B`` scenes (:class:`scenes.frame_dataset.FrameItem`):

1. The text-agnostic detector (:meth:`model.tpcnet.TPCNet.detect`) runs once per scene and is
   trained on *every* actor in the head grid (focal heatmap + smooth-L1, eq. 18).
2. Candidates per scene: every actor in the grid, its box slightly jittered (the detector's boxes
   are never exact) and its detection score read off the current heatmap at its anchor cell, plus
   the detector's own false detections (decoded boxes that match no actor: parked bicycles, poles,
   ghost objects), which are hard negatives the app will meet.
3. ``prompts_per_scene`` prompts per scene from :func:`scenes.prompts.generate_prompts` over the
   scene's actors (the same rules that resolve referents exactly), in the training phrasing stream.
   One encoded scene thus serves many prompts, and same-class actors are the hard negatives. A prompt
   whose referents are not all candidates (outside the head grid) is skipped.
4. The referent stage scores every candidate for every prompt: BCE + a listwise term
   (:func:`model.referent.referent_loss`). The pooled BEV features carry gradients back into the
   backbones, so the scene features learn what the words need.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from model.decode import decode
from model.grounder import stack_candidates
from model.losses import LossTerms, grounding_loss
from model.referent import referent_loss
from model.targets import anchor_points, collate_targets, draw_targets
from model.tpcnet import TPCNet, as_points
from scenes.actors import CLASSES, Actor
from scenes.frame_dataset import FrameItem
from scenes.prompts import Prompt, PromptConfig, generate_prompts

MATCH_DISTANCE = {"Car": 2.0, "Pedestrian": 1.0, "Cyclist": 1.2}
"""A detection within this BEV centre distance (m) of a same-class actor is that actor."""


@dataclass(frozen=True)
class ReferentTrainConfig:
    """Settings of :func:`referent_step`.

    Attributes:
        prompts_per_scene: Prompts generated per scene and step.
        jitter_xy: Std (m) of the noise added to an actor candidate's centre.
        jitter_size: Relative std of the noise on its size.
        jitter_yaw: Std (rad) of the noise on its heading.
        max_false: False detections kept per scene as negative candidates.
        referent_weight: Weight of the referent BCE in the total loss.
        listwise_weight: Weight of the listwise term.
        phrasing: Phrasing stream of the generated prompts (``PromptConfig.phrasing``).
    """

    prompts_per_scene: int = 8
    jitter_xy: float = 0.15
    jitter_size: float = 0.05
    jitter_yaw: float = 0.05
    max_false: int = 12
    referent_weight: float = 1.0
    listwise_weight: float = 0.5
    phrasing: str = "train"


@dataclass(frozen=True)
class ReferentLoss:
    """Scalar loss tensors of one step."""

    total: Tensor
    detection: LossTerms
    bce: Tensor
    listwise: Tensor
    prompts: int


def in_grid_actors(actors: Sequence[Actor], model: TPCNet) -> list[Actor]:
    """Actors of the metric classes whose anchor point lies in the head grid."""
    if not actors:
        return []
    boxes = np.stack([a.box for a in actors])
    inside = model.head_grid.contains(anchor_points(boxes, model.cfg.head.anchor))
    return [a for a, ok in zip(actors, inside, strict=True) if ok and a.cls in CLASSES]


def _anchor_scores(heat: np.ndarray, boxes: np.ndarray, labels: np.ndarray, model: TPCNet):
    """Detector score of each box: the 3x3 max of its class heatmap around its anchor cell."""
    if len(boxes) == 0:
        return np.zeros(0)
    _, h, w = heat.shape
    cells = np.floor(model.head_grid.xy_to_cell(anchor_points(boxes, model.cfg.head.anchor)))
    out = np.zeros(len(boxes))
    for i, ((c, r), lab) in enumerate(zip(cells.astype(int), labels, strict=True)):
        r0, r1, c0, c1 = max(r - 1, 0), min(r + 2, h), max(c - 1, 0), min(c + 2, w)
        if r0 < r1 and c0 < c1:
            out[i] = float(heat[lab, r0:r1, c0:c1].max())
    return out


def training_candidates(
    actors: Sequence[Actor],
    detections_boxes: np.ndarray,
    detections_labels: np.ndarray,
    detections_scores: np.ndarray,
    heat: np.ndarray,
    model: TPCNet,
    rng: np.random.Generator,
    cfg: ReferentTrainConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Candidates of one training scene (module docstring, step 2).

    Returns:
        ``boxes (K, 7)``, ``labels (K,)``, ``scores (K,)`` and ``actor_ids (K,)`` (-1 for a false
        detection).
    """
    boxes = np.stack([a.box for a in actors]) if actors else np.zeros((0, 7))
    labels = np.array([CLASSES.index(a.cls) for a in actors], dtype=np.int64)
    ids = np.array([a.actor_id for a in actors], dtype=np.int64)
    if len(boxes):
        boxes = boxes.copy()
        boxes[:, :2] += rng.normal(0.0, cfg.jitter_xy, (len(boxes), 2))
        boxes[:, 3:6] *= np.exp(rng.normal(0.0, cfg.jitter_size, (len(boxes), 3)))
        boxes[:, 6] += rng.normal(0.0, cfg.jitter_yaw, len(boxes))
    scores = _anchor_scores(heat, boxes, labels, model)
    false = []
    for i, (box, lab) in enumerate(zip(detections_boxes, detections_labels, strict=True)):
        same = [a for a in actors if CLASSES.index(a.cls) == lab]
        limit = MATCH_DISTANCE[CLASSES[lab]]
        if all(np.hypot(*(a.box[:2] - box[:2])) > limit for a in same):
            false.append(i)
    false = false[: cfg.max_false]
    if false:
        boxes = np.concatenate([boxes, detections_boxes[false]])
        labels = np.concatenate([labels, detections_labels[false]])
        scores = np.concatenate([scores, detections_scores[false]])
        ids = np.concatenate([ids, np.full(len(false), -1, dtype=np.int64)])
    return boxes, labels, scores, ids


def _prompt_config(phrasing: str) -> PromptConfig:
    if "phrasing" in PromptConfig.__dataclass_fields__:
        return PromptConfig(phrasing=phrasing)
    return PromptConfig()


def referent_step(
    model: TPCNet,
    frames: Sequence[FrameItem],
    rng: np.random.Generator,
    cfg: ReferentTrainConfig,
    prompt_config: PromptConfig | None = None,
) -> ReferentLoss:
    """Losses of one batch of scenes (module docstring); call ``.total.backward()``."""
    device = model.device
    lidar = [as_points(f.lidar, 4, "LiDAR").to(device) for f in frames]
    radar = [as_points(f.radar, 7, "radar").to(device) for f in frames]
    out, maps = model.detect(
        lidar if model.cfg.uses_lidar else None, radar if model.cfg.uses_radar else None
    )
    actors = [in_grid_actors(f.actors, model) for f in frames]
    targets = collate_targets(
        [
            draw_targets(
                np.stack([a.box for a in acts]) if acts else np.zeros((0, 7)),
                [a.cls for a in acts],
                model.head_grid,
                model.cfg.head,
            )
            for acts in actors
        ]
    ).to(device)
    det = grounding_loss(out, targets)
    with torch.no_grad():
        dets = decode(out, model.head_grid, model.cfg.head, model.cfg.referent.candidate_threshold)
        heat = torch.sigmoid(out.heatmap.detach()).float().cpu().numpy()
    pcfg = prompt_config or _prompt_config(cfg.phrasing)
    scenes, texts, rows, target_rows = [], [], [], []
    for b, frame in enumerate(frames):
        if not actors[b]:
            continue
        boxes, labels, scores, ids = training_candidates(
            actors[b], dets[b].boxes, dets[b].labels, dets[b].scores, heat[b], model, rng, cfg
        )
        prompts: list[Prompt] = generate_prompts(
            frame.actors, rng, cfg.prompts_per_scene, config=pcfg
        )
        usable = [p for p in prompts if set(p.referent_ids) <= set(ids.tolist())]
        if not usable:
            continue
        cands = model.candidates(boxes, labels, scores, maps[b], frame.lidar, frame.radar)
        scene_index = len(scenes)
        scenes.append(cands)
        for p in usable:
            texts.append(p.text)
            rows.append(scene_index)
            target_rows.append(np.isin(ids, p.referent_ids).astype(np.float32))
    if not texts:
        zero = det.total.new_zeros(())
        return ReferentLoss(det.total, det, zero, zero, 0)
    prefetch = getattr(model.text_encoder, "prefetch", None)
    if prefetch is not None:
        prefetch(texts)
    text = model.text_encoder(texts)
    batch = stack_candidates(scenes).index(torch.tensor(rows, device=device))
    assert model.referent is not None
    logits = model.referent(batch, text.tokens, text.numbers, text.padding_mask)
    target = torch.zeros_like(logits)
    for i, t in enumerate(target_rows):
        target[i, : len(t)] = torch.from_numpy(t).to(device)
    bce, listwise = referent_loss(logits, target, batch.padding)
    total = det.total + cfg.referent_weight * (bce + cfg.listwise_weight * listwise)
    return ReferentLoss(total, det, bce, listwise, len(texts))


__all__ = [
    "MATCH_DISTANCE",
    "ReferentLoss",
    "ReferentTrainConfig",
    "in_grid_actors",
    "referent_step",
    "training_candidates",
]
