"""One training step of each trainable stage, chosen once per run by :func:`model.training.loop.train`.

A step takes the dataset indices of this rank's batch and the epoch, and returns its losses
(:class:`StepLoss`); the loop around it (learning rate, backward, clipping, logging, checkpoints)
is the same for every stage:

- :class:`PaperStep`: the paper's path (``--grounding tpcnet``): a collated batch, the detector's
  targets of its referents, the text-conditioned forward, :func:`model.head.losses.grounding_loss`.
- :class:`JointReferentStep`: the referent path's joint stage:
  :func:`model.training.referent_step.referent_step` on the batch's frames.
- :class:`FrozenSceneStep`: ``--freeze-scene``:
  :func:`model.training.referent_cache.cached_referent_step` on the cached scenes
  (:func:`freeze_scene`), each as is or mirrored (:func:`pick_view`).

Each holds its step function already bound to the model (``distributed.wrap_step``: a plain call,
or a DistributedDataParallel forward under ``torchrun``), and runs it under bfloat16 autocast with
``--amp bf16``. The random draws of the referent stages are seeded per item
(:func:`item_rngs`), so that a resumed or a distributed run draws what one uninterrupted process
does.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import torch
from torch import Tensor

from model.head.losses import LossTerms, grounding_loss
from model.tpcnet import TPCNet
from model.training.config import TrainConfig, TrainingError
from model.training.referent_cache import CachedScene, TextBank, cache_scenes, shift_evidence
from model.training.referent_step import ReferentTrainConfig, float32_output
from model.training.scene_store import open_store
from scenes.datasets.augment import AugmentConfig, draw_flip
from scenes.datasets.frames import FrameDataset
from scenes.datasets.grounding import GroundingDataset, collate
from scenes.utils.owned import FolderError


@dataclass(frozen=True)
class StepLoss:
    """The losses of one step.

    Attributes:
        total: The scalar loss to back-propagate.
        detection: The detector's terms (heatmap, regression; zeros on cached scenes).
        extra: Further terms logged beside them (the referent stage's ``bce``, ``listwise``).
    """

    total: Tensor
    detection: LossTerms
    extra: dict[str, float]


class TrainStep(Protocol):
    """One step of a stage: the losses of this rank's batch ``indices`` of ``epoch``."""

    def __call__(self, indices: list[int], epoch: int) -> StepLoss: ...


def item_rngs(seed: int, epoch: int, indices: list[int]) -> list[np.random.Generator]:
    """The generator of each training item of a step (referent path: box jitter, generated and
    drawn prompts), seeded by ``(seed, epoch, item)``: the same whichever rank or step draws the
    item, so a resumed or a distributed run draws what one uninterrupted process does."""
    return [np.random.default_rng((seed, 7, epoch, i)) for i in indices]


def _autocast(device: torch.device, amp: bool) -> torch.autocast:
    return torch.autocast(device.type, torch.bfloat16, enabled=amp)


@dataclass(frozen=True)
class PaperStep:
    """The paper's path: ``forward`` is the step function bound to the model
    (``(lidar, radar, prompts) -> HeadOutput``)."""

    forward: Callable[..., Any]
    model: TPCNet
    dataset: GroundingDataset
    device: torch.device
    amp: bool

    def __call__(self, indices: list[int], epoch: int) -> StepLoss:
        batch = collate([self.dataset[i] for i in indices])
        targets = self.model.scene.detection_targets(batch.boxes, batch.classes).to(self.device)
        lidar = [t.to(self.device) for t in batch.lidar]
        radar = [t.to(self.device) for t in batch.radar]
        with _autocast(self.device, self.amp):
            output = self.forward(lidar, radar, list(batch.prompts))
        terms = grounding_loss(float32_output(output), targets)
        return StepLoss(terms.total, terms, {})


@dataclass(frozen=True)
class JointReferentStep:
    """The referent path's joint stage: ``step`` is
    :func:`model.training.referent_step.referent_step` bound to the model."""

    step: Callable[..., Any]
    dataset: Any
    """The frames (:class:`model.training.data.MixedFrames`)."""
    config: ReferentTrainConfig
    seed: int
    device: torch.device
    amp: bool

    def __call__(self, indices: list[int], epoch: int) -> StepLoss:
        rngs = item_rngs(self.seed, epoch, indices)
        with _autocast(self.device, self.amp):
            ref = self.step([self.dataset[i] for i in indices], rngs, self.config)
        return StepLoss(
            ref.total, ref.detection, {"bce": ref.bce.item(), "listwise": ref.listwise.item()}
        )


@dataclass(frozen=True)
class FrozenScenes:
    """The scenes of a ``--freeze-scene`` run, encoded once by the frozen detector.

    Attributes:
        cached: One per training frame, in the dataset's order.
        mirrored: The same scenes mirrored (prompts with left and right swapped), None for a
            scene of a root cached without (:func:`model.training.data.mirrored_cache`); empty
            without flips.
        bank: The frozen MiniLM features of every banked prompt of both.
    """

    cached: list[CachedScene]
    mirrored: list[CachedScene | None]
    bank: TextBank


def pick_view(
    cached: list, mirrored: list, index: int, cfg: TrainConfig, epoch: int
) -> CachedScene:
    """``--freeze-scene``: the cached scene ``index`` as is, or its mirrored view (prompts with
    left and right swapped) with ``cfg.flip_probability``; then, where it has one, its labelled
    view (:attr:`CachedScene.labelled`) with ``cfg.labelled_views``, some of its labelled boxes
    reading another candidate's pooled features with ``cfg.evidence_shift``
    (:func:`model.training.referent_cache.shift_evidence`); all drawn from ``(seed, epoch,
    index)``."""
    rng = np.random.default_rng((cfg.seed, 13, epoch, index))
    flip = draw_flip(rng, cfg.flip_probability)
    mirror = mirrored[index] if mirrored and flip else None
    scene = cached[index] if mirror is None else mirror
    if scene.labelled is None:
        return scene
    pick = np.random.default_rng((cfg.seed, 17, epoch, index))
    if pick.random() >= cfg.labelled_views:
        return scene
    return shift_evidence(scene.labelled, pick, cfg.evidence_shift)


@dataclass(frozen=True)
class FrozenSceneStep:
    """``--freeze-scene``: ``step`` is
    :func:`model.training.referent_cache.cached_referent_step` bound to the model."""

    step: Callable[..., Any]
    dataset: Any
    """The frames (:class:`model.training.data.MixedFrames`: ``resolve`` maps an index to its
    cached scene)."""
    scenes: FrozenScenes
    config: ReferentTrainConfig
    train: TrainConfig
    device: torch.device
    amp: bool

    def __call__(self, indices: list[int], epoch: int) -> StepLoss:
        rngs = item_rngs(self.train.seed, epoch, indices)
        s = self.scenes
        with _autocast(self.device, self.amp):
            picked = [
                pick_view(s.cached, s.mirrored, self.dataset.resolve(i), self.train, epoch)
                for i in indices
            ]
            ref = self.step(picked, s.bank, rngs, self.config)
        return StepLoss(
            ref.total, ref.detection, {"bce": ref.bce.item(), "listwise": ref.listwise.item()}
        )


def freeze_scene(
    model: TPCNet,
    cfg: TrainConfig,
    frames: Sequence[tuple[Callable[..., FrameDataset], bool]],
    referent_cfg: ReferentTrainConfig,
    progress: bool,
) -> FrozenScenes:
    """Freeze everything but the referent stage and encode every scene once (``--freeze-scene``):
    ``frames`` gives each root's training frames (called with no argument, or with
    ``augment=`` the flip that mirrors every frame) and whether its scenes are cached mirrored
    too (:func:`model.training.data.mirrored_cache`). Scenes and prompt features kept by earlier
    runs are read back from ``--cache`` (:mod:`model.training.scene_store`)."""
    for p in model.parameters():
        p.requires_grad_(False)
    for p in model.grounding.parameters():
        p.requires_grad_(True)
    if cfg.text_encoder not in (None, "minilm"):
        raise TrainingError("--freeze-scene banks frozen MiniLM prompt features: use minilm")
    cached: list[CachedScene] = []
    mirrored: list[CachedScene | None] = []
    bank = TextBank({})
    specs = list(enumerate(cfg.roots(), start=1))
    roots: dict[str, str] = {f"--data root {i}": s.path for i, s in specs}
    roots.update({f"--talk2car folder {i}": s.talk2car for i, s in specs if s.talk2car})
    try:
        store = open_store(cfg.cache, model, model.cfg.text.max_tokens, apart=roots)
    except FolderError as exc:
        raise TrainingError(f"--cache {exc}") from None
    flip = AugmentConfig(flip_probability=1.0, lidar_keep_min=1.0, shuffle_points=False)
    flips = cfg.flip_probability > 0
    for frames_of, mirror in frames:
        views: list[tuple[FrameDataset, list]] = [(frames_of(), cached)]
        if flips and mirror:  # every scene also encoded mirrored, prompts swapped
            views.append((frames_of(augment=flip), mirrored))
        for dataset, into in views:
            part, part_bank = cache_scenes(
                model,
                dataset,
                cfg.bank_prompts,
                seed=cfg.seed,
                progress=progress,
                label_prompts=cfg.label_prompts,
                known=bank,
                prompt_config=referent_cfg.prompts.config,
                labelled=cfg.labelled_views > 0,
                given_variants=cfg.given_variants,
                store=store,
            )
            into += part
            bank.entries.update(part_bank.entries)
        if flips and not mirror:
            mirrored += [None] * (len(cached) - len(mirrored))
    return FrozenScenes(cached, mirrored, bank)


__all__ = [
    "FrozenSceneStep",
    "FrozenScenes",
    "JointReferentStep",
    "PaperStep",
    "StepLoss",
    "TrainStep",
    "freeze_scene",
    "item_rngs",
    "pick_view",
]
