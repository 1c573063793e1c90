"""How each grounding kind trains: one strategy per grounding head, chosen once per run.

What differs between the paper's path (``--grounding tpcnet``, :class:`model.grounding.paper.PaperGrounding`)
and the referent path (``--grounding referent``, :class:`model.grounding.referent.ReferentGrounding`)
when training, and nowhere else in the train command:

- the settings it takes (:meth:`TrainingKind.check`: several ``--data`` roots and
  ``--scene-labels`` are the referent path's);
- the dataset: the root's prompt and referent pairs (:class:`scenes.datasets.grounding.GroundingDataset`)
  for the paper's path, the frames of every root with prompts generated per step
  (:class:`model.training.data.MixedFrames` of :class:`scenes.datasets.frames.FrameDataset`) for
  the referent path;
- the scenes encoded once by a frozen detector (``--freeze-scene``, referent path only);
- the step (:mod:`model.training.steps`: :class:`PaperStep`, :class:`JointReferentStep`,
  :class:`FrozenSceneStep`);
- whether a finished run is calibrated (``--calibrate``: the referent path's answer set).

:func:`training_kind` takes the kind's head class from :func:`model.tpcnet.head_class` (the one
place the two kinds are told apart) and returns the strategy kept for it. The step functions are
looked up in this module when a step is made, so that tests can wrap them.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import torch

from model.grounding.interface import GroundingHead
from model.grounding.paper import PaperGrounding
from model.grounding.referent import ReferentGrounding
from model.tpcnet import TPCNet, head_class
from model.training import distributed
from model.training.config import TrainConfig, TrainingError
from model.training.data import (
    MixedFrames,
    RootSpec,
    TrainingFrames,
    frame_dataset,
    mirrored_cache,
)
from model.training.referent_cache import cached_referent_step
from model.training.referent_step import ReferentTrainConfig, referent_step
from model.training.steps import (
    FrozenScenes,
    FrozenSceneStep,
    JointReferentStep,
    PaperStep,
    TrainStep,
    freeze_scene,
)
from scenes.datasets.augment import AugmentConfig
from scenes.datasets.frames import SensorAugment
from scenes.datasets.grounding import GroundingDataset
from scenes.frame import FrameSource
from scenes.geometry.classes import class_set

TrainingData = GroundingDataset | MixedFrames
"""A run's training items: indexed by :func:`model.training.loop.epoch_batches`, ``set_epoch``."""


class TrainingKind(Protocol):
    """How one grounding kind trains (see the module docstring)."""

    calibrates: bool
    """Whether ``--calibrate`` chooses the finished run's operating threshold."""

    def check(self, cfg: TrainConfig) -> None:
        """Raise :class:`TrainingError` for a setting this kind does not take."""

    def dataset(
        self, cfg: TrainConfig, specs: Sequence[RootSpec], root: FrameSource | None
    ) -> TrainingData:
        """The training items of ``cfg.train_split`` (``root``: the first of ``specs``, read)."""

    def frozen(
        self,
        model: TPCNet,
        cfg: TrainConfig,
        specs: Sequence[RootSpec],
        referent_cfg: ReferentTrainConfig,
        progress: bool,
    ) -> FrozenScenes | None:
        """The scenes encoded once by the frozen detector (``--freeze-scene``), else None."""

    def step(
        self,
        model: TPCNet,
        cfg: TrainConfig,
        dataset: TrainingData,
        referent_cfg: ReferentTrainConfig,
        frozen: FrozenScenes | None,
        device: torch.device,
    ) -> TrainStep:
        """The run's step, its step function bound to ``model`` (``distributed.wrap_step``)."""


def _forward_step(model: torch.nn.Module, lidar: list, radar: list, prompts: list):
    return model(lidar, radar, prompts)


def _augment(cfg: TrainConfig) -> AugmentConfig:
    return AugmentConfig(flip_probability=cfg.flip_probability)


def training_frames(cfg: TrainConfig, spec: RootSpec, **kwargs: object) -> TrainingFrames:
    """One root's training frames (``kwargs``: :func:`model.training.data.frame_dataset`'s),
    the first ``--scene-limit`` only with ``--freeze-scene`` (the scenes cached)."""
    frames = frame_dataset(spec, cfg.train_split, class_set(cfg.classes), **kwargs)
    if cfg.freeze_scene and cfg.scene_limit:
        frames.limit(cfg.scene_limit)
    return frames


@dataclass(frozen=True)
class PaperTraining:
    """The paper's path: text-conditioned forward on the root's prompt pairs."""

    calibrates: bool = False

    def check(self, cfg: TrainConfig) -> None:
        if len(cfg.data) > 1 or cfg.scene_labels:
            raise TrainingError(
                "several --data roots and --scene-labels are the referent path's; the paper's "
                "path trains on one root's label_2 boxes"
            )
        if any(spec.talk2car is not None for spec in cfg.roots()):
            raise TrainingError(
                "a nuScenes root with --talk2car trains the referent path (--grounding "
                "referent); the paper's path trains on a Talk2Radar root's label_2 boxes"
            )

    def dataset(
        self, cfg: TrainConfig, specs: Sequence[RootSpec], root: FrameSource | None
    ) -> TrainingData:
        return GroundingDataset(root, cfg.train_split, augment=_augment(cfg), seed=cfg.seed)

    def frozen(
        self,
        model: TPCNet,
        cfg: TrainConfig,
        specs: Sequence[RootSpec],
        referent_cfg: ReferentTrainConfig,
        progress: bool,
    ) -> FrozenScenes | None:
        return None

    def step(
        self,
        model: TPCNet,
        cfg: TrainConfig,
        dataset: TrainingData,
        referent_cfg: ReferentTrainConfig,
        frozen: FrozenScenes | None,
        device: torch.device,
    ) -> TrainStep:
        if not isinstance(dataset, GroundingDataset):
            raise TypeError(f"the paper's step trains on a GroundingDataset, got {type(dataset)}")
        forward = distributed.wrap_step(model, _forward_step, find_unused=False)
        return PaperStep(forward, model, dataset, device, cfg.amp == "bf16")


@dataclass(frozen=True)
class ReferentTraining:
    """The referent path: its joint stage, or ``--freeze-scene`` on cached scenes."""

    calibrates: bool = True

    def check(self, cfg: TrainConfig) -> None:
        return None

    def dataset(
        self, cfg: TrainConfig, specs: Sequence[RootSpec], root: FrameSource | None
    ) -> TrainingData:
        sensors = SensorAugment() if cfg.sensor_augment else None
        augment = _augment(cfg)
        return MixedFrames(
            [
                training_frames(cfg, spec, augment=augment, sensors=sensors, seed=cfg.seed)
                for spec in specs
            ],
            [spec.weight for spec in specs],
            seed=cfg.seed,
        )

    def frozen(
        self,
        model: TPCNet,
        cfg: TrainConfig,
        specs: Sequence[RootSpec],
        referent_cfg: ReferentTrainConfig,
        progress: bool,
    ) -> FrozenScenes | None:
        if not cfg.freeze_scene:
            return None
        # Only the referent stage learns; every scene is encoded once by the frozen detector.
        roots = [
            (functools.partial(training_frames, cfg, spec), mirrored_cache(spec)) for spec in specs
        ]
        return freeze_scene(model, cfg, roots, referent_cfg, progress=progress)

    def step(
        self,
        model: TPCNet,
        cfg: TrainConfig,
        dataset: TrainingData,
        referent_cfg: ReferentTrainConfig,
        frozen: FrozenScenes | None,
        device: torch.device,
    ) -> TrainStep:
        amp = cfg.amp == "bf16"
        if frozen is not None:
            step = distributed.wrap_step(model, cached_referent_step)
            return FrozenSceneStep(step, dataset, frozen, referent_cfg, cfg, device, amp)
        step = distributed.wrap_step(model, referent_step)
        return JointReferentStep(step, dataset, referent_cfg, cfg.seed, device, amp)


KINDS: dict[type[GroundingHead], TrainingKind] = {
    PaperGrounding: PaperTraining(),
    ReferentGrounding: ReferentTraining(),
}
"""The training strategy of each grounding head."""


def training_kind(cfg: TrainConfig) -> TrainingKind:
    """The training strategy of ``cfg.grounding``'s head (:func:`model.tpcnet.head_class`)."""
    return KINDS[head_class(cfg.grounding)]


__all__ = [
    "KINDS",
    "PaperTraining",
    "ReferentTraining",
    "TrainingData",
    "TrainingKind",
    "training_frames",
    "training_kind",
]
