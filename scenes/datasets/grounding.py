"""A torch ``Dataset`` over any Talk2Radar root, with augmentations that keep the prompt true.

Each item is one sample: the frame's LiDAR and radar points (LiDAR frame), its prompt and the boxes
that prompt refers to. Train-time augmentations (all optional, see
:class:`scenes.datasets.augment.AugmentConfig`, re-exported here):

- left-right flip (``y -> -y``, ``yaw -> -yaw``) with the words "left" and "right" swapped in the
  prompt (:func:`scenes.datasets.augment.flip_sample`, where the flip lives);
- random LiDAR point dropout (a density change only);
- point shuffling.

Nothing rescales distances or rotates the scene: "about 20 metres ahead" and "on the left" stay true.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch.utils.data import Dataset

from scenes.datasets.augment import AugmentConfig, flip_sample, item_rng
from scenes.talk2radar.root import Talk2RadarRoot


@dataclass(frozen=True)
class GroundingItem:
    """One training / evaluation item.

    Attributes:
        sample_id: 5-digit id.
        lidar: ``(N, 4)`` float32 tensor, LiDAR frame.
        radar: ``(M, 7)`` float32 tensor, LiDAR frame.
        boxes: ``(K, 7)`` float64 array of the referred boxes.
        classes: ``K`` class names.
        prompt: The sentence (flipped with the scene when the flip was applied).
        flipped: Whether the left-right flip was applied.
    """

    sample_id: str
    lidar: torch.Tensor
    radar: torch.Tensor
    boxes: np.ndarray
    classes: tuple[str, ...]
    prompt: str
    flipped: bool = False


@dataclass(frozen=True)
class GroundingBatch:
    """A collated batch: per-sample point tensors of varying sizes, boxes and prompts."""

    sample_ids: tuple[str, ...]
    lidar: tuple[torch.Tensor, ...]
    radar: tuple[torch.Tensor, ...]
    boxes: tuple[np.ndarray, ...]
    classes: tuple[tuple[str, ...], ...]
    prompts: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.sample_ids)


class GroundingDataset(Dataset):
    """Samples of one split of a Talk2Radar root.

    Args:
        root: A :class:`Talk2RadarRoot` or its path.
        split: ImageSets name (``train``, ``val``, ``test``).
        augment: Augmentations to apply (None for evaluation).
        seed: Seed of the augmentation random stream (item ``i`` at epoch ``e`` draws from
            ``(seed, e, i)``, so runs and resumed runs repeat exactly; call :meth:`set_epoch`).
    """

    def __init__(
        self,
        root: Talk2RadarRoot | str,
        split: str,
        augment: AugmentConfig | None = None,
        seed: int = 0,
    ) -> None:
        self.root = root if isinstance(root, Talk2RadarRoot) else Talk2RadarRoot(root)
        self.split = split
        self.ids = self.root.ids(split)
        if not self.ids:
            raise ValueError(f"{self.root.path}: split {split!r} has no samples")
        self.augment = augment
        self.seed = seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the augmentation stream of ``epoch``."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.ids)

    def __getitem__(self, index: int) -> GroundingItem:
        sample = self.root.load(self.ids[index])
        if sample.prompt is None:
            raise ValueError(f"{self.root.path}: sample {sample.sample_id} has no prompt")
        lidar, radar, boxes, prompt = sample.lidar, sample.radar, sample.boxes, sample.prompt
        flipped = False
        if self.augment is not None:
            rng = item_rng(self.seed, self.epoch, index)
            if self.augment.draws_flip(rng):
                lidar, radar, boxes, prompt = flip_sample(lidar, radar, boxes, prompt)
                flipped = True
            lidar, radar = self.augment.thin_and_shuffle(lidar, radar, rng)
        return GroundingItem(
            sample_id=sample.sample_id,
            lidar=torch.from_numpy(np.ascontiguousarray(lidar, dtype=np.float32)),
            radar=torch.from_numpy(np.ascontiguousarray(radar, dtype=np.float32)),
            boxes=np.asarray(boxes, dtype=np.float64).reshape(-1, 7),
            classes=tuple(sample.classes),
            prompt=prompt,
            flipped=flipped,
        )


def collate(items: Sequence[GroundingItem]) -> GroundingBatch:
    """Collate items into a :class:`GroundingBatch` (point clouds stay a tuple of tensors)."""
    return GroundingBatch(
        sample_ids=tuple(it.sample_id for it in items),
        lidar=tuple(it.lidar for it in items),
        radar=tuple(it.radar for it in items),
        boxes=tuple(it.boxes for it in items),
        classes=tuple(it.classes for it in items),
        prompts=tuple(it.prompt for it in items),
    )


__all__ = ["AugmentConfig", "GroundingBatch", "GroundingDataset", "GroundingItem", "collate"]
