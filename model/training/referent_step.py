"""One training step of the referent path: detection of every actor + referents of generated prompts.

Per batch of ``B`` scenes (:class:`scenes.datasets.frames.FrameItem`):

1. The text-agnostic detector (:meth:`model.grounding.scene_encoder.SceneEncoder.detect`) runs once per scene and is
   trained on *every* actor in the head grid (focal heatmap + smooth-L1, eq. 18).
2. Candidates per scene: every actor in the grid, its box slightly jittered (the detector's boxes
   are never exact) and its detection score read off the current heatmap at its anchor cell, plus
   the detector's own false detections (decoded boxes that match no actor: parked bicycles, poles,
   ghost objects), which are hard negatives the app will meet.
3. ``prompts_per_scene`` prompts per scene from :func:`scenes.language.prompts.generate_prompts` over the
   scene's actors (the same rules that resolve referents exactly), in the training phrasing stream.
   One encoded scene thus serves many prompts, and same-class actors are the hard negatives. A prompt
   whose referents are not all candidates (outside the head grid) is skipped.
4. The referent stage scores every candidate for every prompt: BCE + a listwise term
   (:func:`model.referent.stage.referent_loss`). The pooled BEV features carry gradients back into the
   backbones, so the scene features learn what the words need.

A second, cheaper stage (``python -m model.train ... --freeze-scene``) trains the referent stage
alone on cached scenes: every training scene is encoded once by the frozen detector
(:func:`cache_scenes`), its detections are matched to its actors (:func:`match_detections`), and
each step then scores many generated prompts per scene (:func:`cached_referent_step`) at a small
fraction of a joint step's cost. Its candidates are exactly what inference sees: the detector's own
boxes and scores, misses and false detections included.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import Tensor

from model.core.anchors import grid_cell_centres
from model.core.grid import BevGrid
from model.grounding.referent import referent_head
from model.head.detector import HeadOutput
from model.head.losses import LossTerms, grounding_loss
from model.head.targets import BatchTargets
from model.nets.text import (
    MiniLMTextEncoder,
    TextFeatures,
    encode_minilm_batched,
    pad_features,
    validate_prompt,
)
from model.tpcnet import TPCNet
from model.training.config import PromptDraw
from scenes.datasets.frames import AnnotatedRegion, FrameItem
from scenes.datasets.levelled import level_item
from scenes.geometry.actors import Actor
from scenes.geometry.boxes import points_in_footprints
from scenes.geometry.calib import Calibration
from scenes.language.prompts import Prompt, PromptConfig, generate_prompts
from scenes.language.prompts.noise import perturb


@dataclass(frozen=True)
class ReferentTrainConfig:
    """Settings of :func:`referent_step`.

    Attributes:
        prompts: The prompts generated per scene (:meth:`model.training.config.TrainConfig.
            prompt_draw`: the run's ``--prompts-per-scene``, ``--label-prompts``, ``--language``,
            ``--phrasing``, ``--text-noise`` and ``--family-rate``).
        jitter_xy: Std (m) of the noise added to an actor candidate's centre.
        jitter_size: Relative std of the noise on its size.
        jitter_yaw: Std (rad) of the noise on its heading.
        max_false: False detections kept per scene as negative candidates.
        referent_weight: Weight of the referent BCE in the total loss.
        listwise_weight: Weight of the listwise term.
    """

    prompts: PromptDraw
    jitter_xy: float = 0.15
    jitter_size: float = 0.05
    jitter_yaw: float = 0.05
    max_false: int = 12
    referent_weight: float = 1.0
    listwise_weight: float = 0.5


@dataclass(frozen=True)
class ReferentLoss:
    """Scalar loss tensors of one step."""

    total: Tensor
    detection: LossTerms
    bce: Tensor
    listwise: Tensor
    prompts: int


def model_frame(model: TPCNet, item: FrameItem) -> FrameItem:
    """``item`` as ``model`` sees it: with heights above the ground estimated from its LiDAR
    cloud when the model's ``PillarConfig.ground`` is ``estimated`` (as ``TPCNet.encode_scene``
    does at inference; :func:`scenes.datasets.levelled.level_item`), else as it is."""
    pillars = model.cfg.pillars
    if not pillars.levels_on_ground:
        return item
    return level_item(item, pillars.ground_height)


def in_grid_actors(actors: Sequence[Actor], model: TPCNet) -> list[Actor]:
    """Actors of the model's classes (``model.cfg.class_set``) whose anchor point lies in the
    head grid."""
    if not actors:
        return []
    inside = model.scene.anchors_in_grid(np.stack([a.box for a in actors]))
    classes = model.cfg.class_set
    return [a for a, ok in zip(actors, inside, strict=True) if ok and a.cls in classes]


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
    classes = model.cfg.class_set
    labels = np.array([classes.index(a.cls) for a in actors], dtype=np.int64)
    ids = np.array([a.actor_id for a in actors], dtype=np.int64)
    if len(boxes):
        boxes = boxes.copy()
        boxes[:, :2] += rng.normal(0.0, cfg.jitter_xy, (len(boxes), 2))
        boxes[:, 3:6] *= np.exp(rng.normal(0.0, cfg.jitter_size, (len(boxes), 3)))
        boxes[:, 6] += rng.normal(0.0, cfg.jitter_yaw, len(boxes))
    scores = model.scene.anchor_scores(heat, boxes, labels)
    false = []
    for i, (box, lab) in enumerate(zip(detections_boxes, detections_labels, strict=True)):
        same = [a for a in actors if classes.index(a.cls) == lab]
        limit = classes.classes[lab].match_distance
        if all(np.hypot(*(a.box[:2] - box[:2])) > limit for a in same):
            false.append(i)
    false = false[: cfg.max_false]
    if false:
        boxes = np.concatenate([boxes, detections_boxes[false]])
        labels = np.concatenate([labels, detections_labels[false]])
        scores = np.concatenate([scores, detections_scores[false]])
        ids = np.concatenate([ids, np.full(len(false), -1, dtype=np.int64)])
    return boxes, labels, scores, ids


def float32_output(out: HeadOutput) -> HeadOutput:
    """``out`` in float32 (a bfloat16 autocast forward's output; a no-op for float32)."""
    return HeadOutput(out.heatmap.float(), out.regression.float())


def _per_item(
    rng: np.random.Generator | Sequence[np.random.Generator], count: int
) -> list[np.random.Generator]:
    """One generator per item: ``rng`` itself for all (drawn in turn), or one given per item."""
    if isinstance(rng, np.random.Generator):
        return [rng] * count
    rngs = list(rng)
    if len(rngs) != count:
        raise ValueError(f"{len(rngs)} random generators for {count} items")
    return rngs


def step_text(model: TPCNet, texts: Sequence[str]) -> TextFeatures:
    """The step's prompts encoded by ``model``'s text encoder. The frozen MiniLM encodes the
    step's distinct prompts afresh in one padded batch, bypassing its cache: batched features equal
    one-at-a-time ones only to float rounding, so a cache filled by earlier steps would make a
    step's features depend on them, and a resumed run would not repeat an uninterrupted one."""
    encoder = model.text_encoder
    valid = [validate_prompt(t) for t in texts]
    if isinstance(encoder, MiniLMTextEncoder):
        distinct = list(dict.fromkeys(valid))
        entries = dict(
            zip(distinct, encode_minilm_batched(distinct, encoder.max_tokens), strict=True)
        )
        return pad_features([entries[t] for t in valid], model.device)
    return encoder(valid)


def referent_step(
    model: TPCNet,
    frames: Sequence[FrameItem],
    rng: np.random.Generator | Sequence[np.random.Generator],
    cfg: ReferentTrainConfig,
    prompt_config: PromptConfig | None = None,
) -> ReferentLoss:
    """Losses of one batch of scenes (module docstring); call ``.total.backward()``. ``rng`` is
    one generator drawn from scene after scene, or one per scene (then a scene's jitter and
    prompts do not depend on the others of the batch: :func:`model.training.steps.item_rngs`)."""
    device = model.device
    head = referent_head(model)
    rngs = _per_item(rng, len(frames))
    frames = [model_frame(model, f) for f in frames]
    lidar = model.scene.clouds([f.lidar for f in frames], len(frames), "lidar")
    radar = model.scene.clouds([f.radar for f in frames], len(frames), "radar")
    out, maps = model.detect(lidar, radar)
    actors = [in_grid_actors(f.actors, model) for f in frames]
    targets = detection_targets(model, frames, actors).to(device)
    out = float32_output(out)  # the losses and the decoding in float32 under autocast
    det = grounding_loss(out, targets)
    with torch.no_grad():
        dets = head.proposals(model.scene, out, limit=None)
        heat = torch.sigmoid(out.heatmap.detach()).cpu().numpy()
    pcfg = prompt_config or cfg.prompts.config
    scenes, texts, rows, target_rows = [], [], [], []
    for b, frame in enumerate(frames):
        if not actors[b]:
            continue
        d = dets[b]
        inside = slice(None) if frame.region is None else frame.region.contains(d.boxes[:, :2])
        boxes, labels, scores, ids = training_candidates(
            actors[b],
            d.boxes[inside],
            d.labels[inside],
            d.scores[inside],
            heat[b],
            model,
            rngs[b],
            cfg,
        )
        usable = [
            (text, refs)
            for text, refs in frame_prompts(
                frame, rngs[b], cfg.prompts.per_scene, pcfg, cfg.prompts.label_prompts
            )
            if set(refs) <= set(ids.tolist())
        ]
        if not usable:
            continue
        cands = head.describe(model.scene, boxes, labels, scores, maps[b], frame.lidar, frame.radar)
        scene_index = len(scenes)
        scenes.append(cands)
        for text, refs in usable:
            texts.append(text)
            rows.append(scene_index)
            target_rows.append(np.isin(ids, refs).astype(np.float32))
    if not texts:
        zero = det.total.new_zeros(())
        return ReferentLoss(det.total, det, zero, zero, 0)
    text = step_text(model, texts)
    bce, listwise = head.prompt_losses(scenes, rows, text, target_rows)
    total = det.total + cfg.referent_weight * (bce + cfg.listwise_weight * listwise)
    return ReferentLoss(total, det, bce, listwise, len(texts))


def frame_prompts(
    frame: FrameItem,
    rng: np.random.Generator,
    count: int,
    config: PromptConfig,
    label_prompts: int = 0,
    given_variants: int = 0,
) -> list[tuple[str, tuple[int, ...]]]:
    """``(text, referent actor ids)`` of a frame's training prompts: the prompts that come with
    it (labels source, all of them), or ``count`` generated from its actors (sidecar source).

    ``given_variants``: on a labels-source frame, each given prompt also comes back reworded that
    many times (:func:`scenes.language.prompts.noise.perturb`: meaning-free words dropped,
    synonyms, typos, casing; numbers, units, negators and sides kept), with its referents:
    a root of few given sentences (Talk2Car's commands) then teaches its wording less by heart.

    ``label_prompts``: on a labels-source frame with complete labels (scene labels, or a nuScenes
    sample: :attr:`scenes.datasets.frames.FrameItem.labels_complete`), that many
    more prompts generated from its labelled boxes, of the attributes a box alone decides
    (``PromptConfig.geometry_only``: class, depth, side; motion too where the frame's
    velocities are known, :attr:`FrameItem.unknown_motion`: a nuScenes sample). Given
    prompts are kept as written; generated ones are reworded as ``config.p_perturb`` says.
    Prompts are generated over the frame's class set (:attr:`FrameItem.prompt_classes`: the
    world's, so that a ``--classes nuscenes`` world's trucks and cones are talked about; a
    prompt whose referents the model's set lacks finds no candidate and is left out)."""
    if config.classes != frame.prompt_classes:
        config = replace(config, classes=frame.prompt_classes)
    if not frame.generates_prompts:
        given = [(g.text, g.referent_ids) for g in frame.given]
        given += reworded(given, rng, given_variants)
        if label_prompts <= 0 or not frame.labels_complete:
            return given
        unknown = frame.unknown_motion
        geometry = replace(config, geometry_only=unknown is None)
        extra: list[Prompt] = generate_prompts(
            frame.actors, rng, label_prompts, config=geometry, unknown_motion=unknown or ()
        )
        return given + [(p.text, tuple(p.referent_ids)) for p in extra]
    prompts: list[Prompt] = generate_prompts(frame.actors, rng, count, config=config)
    return [(p.text, tuple(p.referent_ids)) for p in prompts]


def reworded(
    prompts: Sequence[tuple[str, tuple[int, ...]]], rng: np.random.Generator, variants: int
) -> list[tuple[str, tuple[int, ...]]]:
    """Up to ``variants`` rewordings of each ``(text, referent ids)`` by
    :func:`scenes.language.prompts.noise.perturb` (its meaning kept), each with the same
    referents; a rewording equal to the text or to an earlier one is not repeated (a few tries
    each)."""
    out: list[tuple[str, tuple[int, ...]]] = []
    for text, refs in prompts:
        seen = {text}
        for _ in range(3 * variants):
            if len(seen) > variants:
                break
            new = perturb(text, rng)
            if new not in seen:
                seen.add(new)
                out.append((new, refs))
    return out


def detection_targets(
    model: TPCNet, frames: Sequence[FrameItem], actors: Sequence[Sequence[Actor]]
) -> BatchTargets:
    """Detector targets of a batch: every in-grid actor of each frame; where a frame's labels
    cover only the camera view (:attr:`FrameItem.region`), no negatives outside it; and no
    negatives on the footprint of a labelled object outside the class set
    (:attr:`FrameItem.ignore_boxes`, grown by :data:`IGNORE_MARGIN`)."""
    targets = model.scene.detection_targets(
        [np.stack([a.box for a in acts]) if acts else np.zeros((0, 7)) for acts in actors],
        [[a.cls for a in acts] for acts in actors],
    )
    has_ignore = [f.ignore_boxes is not None and len(f.ignore_boxes) > 0 for f in frames]
    if all(f.region is None for f in frames) and not any(has_ignore):
        return targets
    h, w = model.head_grid.shape
    ignore = np.zeros((len(frames), 1, h, w), dtype=bool)
    for b, frame in enumerate(frames):
        if has_ignore[b]:
            cells = grid_cell_centres(model.head_grid)
            inside = in_bev_footprint(cells, np.asarray(frame.ignore_boxes), IGNORE_MARGIN)
            ignore[b, 0] |= inside.reshape(h, w)
        if frame.region is not None:
            region = frame.region
            calib = tuple(
                (m.tobytes(), m.shape)
                for m in (region.calib.P2, region.calib.R0_rect, region.calib.Tr_velo_to_cam)
            )
            ignore[b, 0] |= _outside(model.head_grid, calib, region.image_size, region.mirrored)
    return replace(targets, ignore=torch.from_numpy(ignore))


IGNORE_MARGIN = 0.5
"""Metres by which an ignored object's footprint grows (the head's cells are 0.32-0.64 m: a cell
whose centre falls just outside the box still sees its points)."""


def in_bev_footprint(xy: np.ndarray, boxes: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """``(N,)`` bool: which ``(N, 2)`` ground positions lie inside the bird's-eye footprint of any
    of ``boxes`` ``(J, 7)`` (LiDAR frame), each grown by ``margin`` metres on every side."""
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return points_in_footprints(pts, boxes, margin).any(axis=1)


@functools.lru_cache(maxsize=64)
def _outside(
    grid: BevGrid, calib: tuple, image_size: tuple[int, int], mirrored: bool
) -> np.ndarray:
    """``(H, W)`` bool: head-grid cells outside the annotated region of a calibration (given as
    the bytes and shapes of ``P2``, ``R0_rect``, ``Tr_velo_to_cam``); a release's frames share a
    handful of calibrations, so this is computed once per calibration and flip."""
    p2, r0, tr = (np.frombuffer(data, dtype=np.float64).reshape(shape) for data, shape in calib)
    region = AnnotatedRegion(Calibration(p2, r0, tr), image_size, mirrored)
    h, w = grid.shape
    return ~region.contains(grid_cell_centres(grid)).reshape(h, w)


__all__ = [
    "IGNORE_MARGIN",
    "ReferentLoss",
    "ReferentTrainConfig",
    "float32_output",
    "in_bev_footprint",
    "in_grid_actors",
    "model_frame",
    "referent_step",
    "step_text",
    "training_candidates",
]
