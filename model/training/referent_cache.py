"""The second stage of the referent path (``--freeze-scene``): scenes encoded once, prompts banked.

Every training scene is encoded once by the frozen detector (:func:`cache_scenes`), its detections
are matched to its actors (:func:`match_detections`), its prompts (generated, or given with a real
root) are encoded once by the frozen text encoder (:class:`TextBank`), and each step then scores
some of them per scene (:func:`cached_referent_step`) at a small fraction of a joint step's cost.
Its candidates are exactly what inference sees: the detector's own boxes and scores, misses and
false detections included.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch

from model.head.losses import LossTerms
from model.nets.text import encode_minilm_batched, pad_features
from model.referent.head import referent_head
from model.referent.scene_candidates import SceneCandidates
from model.tpcnet import TPCNet
from model.training.referent_step import (
    ReferentLoss,
    ReferentTrainConfig,
    _per_item,
    frame_prompts,
)
from scenes.actors import CLASSES, Actor
from scenes.boxes import CENTRE_MATCH_DISTANCE, match_by_centre
from scenes.frame_dataset import FrameDataset
from scenes.prompts import PromptConfig


@dataclass(frozen=True)
class CachedScene:
    """A training scene encoded once by the frozen detector, with its bank of prompts.

    Attributes:
        candidates: The detector's candidates (tensors detached, on the CPU).
        actor_ids: ``(K,)`` the actor each candidate detects, -1 for a false detection.
        prompts: Generated prompts with at least one detected referent.
        targets: Per prompt, ``(K,)`` float32: 1 where the candidate is a referent.
    """

    candidates: SceneCandidates
    actor_ids: np.ndarray
    prompts: tuple[str, ...]
    targets: tuple[np.ndarray, ...]


def match_detections(boxes: np.ndarray, labels: np.ndarray, actors: Sequence[Actor]) -> np.ndarray:
    """Actor id ``(K,)`` of each detection (-1: none): detections in the given (score) order take
    the nearest free actor of their class within :data:`scenes.boxes.CENTRE_MATCH_DISTANCE` of
    the BEV centre (:func:`scenes.boxes.match_by_centre`)."""
    if not actors:
        return np.full(len(boxes), -1, dtype=np.int64)
    targets = np.stack([a.box for a in actors])
    target_labels = np.array([CLASSES.index(a.cls) for a in actors], dtype=np.int64)
    limits = np.array([CENTRE_MATCH_DISTANCE[c] for c in CLASSES])
    index = match_by_centre(boxes, labels, targets, target_labels, limits)
    ids = np.array([a.actor_id for a in actors], dtype=np.int64)
    return np.where(index >= 0, ids[np.maximum(index, 0)], -1)


@dataclass
class TextBank:
    """Frozen-encoder token features of every banked prompt: ``text -> (tokens, numbers,
    truncated)`` (tokens kept as float16 to halve the memory)."""

    entries: dict

    def features(self, texts: Sequence[str], device: torch.device):
        """:class:`model.nets.text.TextFeatures` of ``texts`` (all in the bank)."""
        return pad_features([self.entries[t] for t in texts], device)


def cache_scenes(
    model: TPCNet,
    dataset: FrameDataset,
    prompts_per_scene: int,
    seed: int = 0,
    progress: bool = True,
    label_prompts: int = 0,
    known: TextBank | None = None,
    prompt_config: PromptConfig | None = None,
) -> tuple[list[CachedScene], TextBank]:
    """Encode every scene of ``dataset`` with the frozen model, generate ``prompts_per_scene``
    prompts per scene (labels source: take its given prompts, plus ``label_prompts`` from its
    labelled boxes, :func:`frame_prompts`) and encode them with the frozen text encoder (module
    docstring). A ``dataset`` that flips every frame gives the mirrored views of the scenes.
    Prompts already in ``known`` (e.g. the other view's bank) are not encoded again; the bank
    returned holds only the new ones. ``prompt_config``: the generator's settings
    (:attr:`model.training.config.PromptDraw.config`; default: the base
    prompts in the training phrasings)."""
    from tqdm import tqdm

    model.eval()
    pcfg = prompt_config or PromptConfig()
    scenes = []
    with torch.no_grad():
        for i in tqdm(range(len(dataset)), desc="cache scenes", disable=not progress):
            item = dataset[i]
            objects = model.encode_scene(item.lidar, item.radar).objects
            assert objects is not None
            cpu = replace(
                objects,
                geometry=objects.geometry.cpu(),
                fused=objects.fused.cpu(),
                lidar=None if objects.lidar is None else objects.lidar.cpu(),
                radar=None if objects.radar is None else objects.radar.cpu(),
            )
            ids = match_detections(objects.boxes, objects.labels, item.actors)
            rng = np.random.default_rng((seed, 11, i))
            prompts = frame_prompts(item, rng, prompts_per_scene, pcfg, label_prompts)
            # A prompt is kept when it refers to nothing (the empty answer is an answer: things
            # outside the classes, attributes nothing here has) or to a detected object.
            usable = [
                (text, refs) for text, refs in prompts if not refs or np.isin(ids, refs).any()
            ]
            scenes.append(
                CachedScene(
                    cpu,
                    ids,
                    tuple(text for text, _ in usable),
                    tuple(np.isin(ids, refs).astype(np.float32) for _, refs in usable),
                )
            )
    done = {} if known is None else known.entries
    texts = [t for t in dict.fromkeys(t for s in scenes for t in s.prompts) if t not in done]
    entries = {}
    max_tokens = model.cfg.text.max_tokens
    chunk = 256
    for start in tqdm(
        range(0, len(texts), chunk), desc="encode prompts", disable=not progress, unit="chunk"
    ):
        part = texts[start : start + chunk]
        for text, (tok, num, trunc) in zip(
            part, encode_minilm_batched(part, max_tokens, 64), strict=True
        ):
            entries[text] = (tok.half(), num, trunc)
    return scenes, TextBank(entries)


def cached_referent_step(
    model: TPCNet,
    scenes: Sequence[CachedScene],
    bank: TextBank,
    rng: np.random.Generator | Sequence[np.random.Generator],
    cfg: ReferentTrainConfig,
) -> ReferentLoss:
    """Referent loss on cached scenes, ``cfg.prompts.per_scene`` banked prompts drawn per scene
    (only the referent stage learns; ``rng`` as in :func:`referent_step`). Undetected referents
    cannot be answered and are not in a prompt's target."""
    device = model.device
    chosen, texts, rows, targets = [], [], [], []
    for scene, scene_rng in zip(scenes, _per_item(rng, len(scenes)), strict=True):
        if not len(scene.candidates) or not scene.prompts:
            continue
        k = min(cfg.prompts.per_scene, len(scene.prompts))
        picks = scene_rng.choice(len(scene.prompts), size=k, replace=False)
        index = len(chosen)
        chosen.append(scene.candidates)
        for j in picks:
            texts.append(scene.prompts[j])
            rows.append(index)
            targets.append(scene.targets[j])
    zero = torch.zeros((), device=device)
    if not texts:
        return ReferentLoss(zero, LossTerms(zero, zero, zero), zero, zero, 0)
    text = bank.features(texts, device)
    bce, listwise = referent_head(model).prompt_losses(chosen, rows, text, targets)
    total = cfg.referent_weight * (bce + cfg.listwise_weight * listwise)
    return ReferentLoss(total, LossTerms(zero, zero, zero), bce, listwise, len(texts))


__all__ = [
    "CachedScene",
    "TextBank",
    "cache_scenes",
    "cached_referent_step",
    "match_detections",
]
