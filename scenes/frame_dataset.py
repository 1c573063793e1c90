"""Frames with every actor, for training the referent path (one item per distinct scene).

A Talk2Radar root holds one prompt per sample, and the samples of one synthetic world share their
sensor files. The referent path trains a text-agnostic detector on *all* actors of a frame and its
referent stage on prompts generated during training from those actors
(:func:`scenes.prompts.generate_prompts`), so it reads each distinct scene once: the samples of a
split are grouped by ``meta.world_id`` (samples without a sidecar world id are their own scene),
and the first sample of each group stands for it.

Augmentations keep every statement about the scene true, because the prompts are generated from
the augmented actors: the left-right flip mirrors points and actors (``y -> -y``, ``yaw -> -yaw``,
``vy -> -vy``; radar radial velocities unchanged, as :func:`scenes.dataset.flip_sample`); LiDAR
point dropout changes density only. Nothing rescales distances.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from torch.utils.data import Dataset

from scenes.actors import Actor
from scenes.boxes import wrap_yaw
from scenes.dataset import AugmentConfig
from scenes.root import Talk2RadarRoot


@dataclass(frozen=True)
class FrameItem:
    """One scene with all its actors.

    Attributes:
        sample_id: The sample that stands for the scene.
        lidar: ``(N, 4)`` float32, LiDAR frame.
        radar: ``(M, 7)`` float32, LiDAR frame.
        actors: Every actor of the scene (LiDAR frame, ground velocities), augmented with the
            points.
        flipped: Whether the left-right flip was applied.
    """

    sample_id: str
    lidar: np.ndarray
    radar: np.ndarray
    actors: tuple[Actor, ...]
    flipped: bool = False


def flip_actor(actor: Actor) -> Actor:
    """The actor mirrored about the LiDAR's x-z plane."""
    box = actor.box.copy()
    box[1] *= -1
    box[6] = wrap_yaw(-box[6])
    vel = actor.velocity * np.array([1.0, -1.0])
    return Actor(actor.actor_id, actor.cls, box, vel)


def scene_ids(root: Talk2RadarRoot, split: str) -> list[str]:
    """One sample id per distinct scene of ``split`` (first sample of each world), in order."""
    seen: set[int] = set()
    out = []
    for sid in root.ids(split):
        meta = root.load_meta(sid)
        world = -1 if meta is None else meta.world_id
        if world >= 0:
            if world in seen:
                continue
            seen.add(world)
        out.append(sid)
    return out


class FrameDataset(Dataset):
    """The distinct scenes of a split, with their actors (module docstring).

    Args:
        root: A :class:`Talk2RadarRoot` or its path.
        split: ImageSets name.
        augment: Augmentations (None for evaluation).
        seed: Seed of the augmentation stream (item ``i`` at epoch ``e`` draws from
            ``(seed, e, i)``; call :meth:`set_epoch`).

    Raises:
        ValueError: The split has no scene, or a scene has no sidecar listing its actors.
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
        self.ids = scene_ids(self.root, split)
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

    def __getitem__(self, index: int) -> FrameItem:
        sample = self.root.load(self.ids[index])
        if sample.meta is None or not sample.meta.actors:
            raise ValueError(
                f"{self.root.path}: sample {sample.sample_id} has no meta/{sample.sample_id}.json "
                "listing the scene's actors; the referent path trains on every actor of a frame"
            )
        lidar = np.asarray(sample.lidar, dtype=np.float32)
        radar = np.asarray(sample.radar, dtype=np.float32)
        actors = tuple(sample.meta.actors)
        flipped = False
        if self.augment is not None:
            rng = np.random.default_rng((self.seed, self.epoch, index))
            if rng.random() < self.augment.flip_probability:
                lidar, radar = lidar.copy(), radar.copy()
                lidar[:, 1] *= -1
                radar[:, 1] *= -1
                actors = tuple(flip_actor(a) for a in actors)
                flipped = True
            if self.augment.lidar_keep_min < 1.0 and len(lidar):
                keep = rng.uniform(self.augment.lidar_keep_min, 1.0)
                lidar = lidar[rng.random(len(lidar)) < keep]
            if self.augment.shuffle_points:
                lidar = lidar[rng.permutation(len(lidar))]
                radar = radar[rng.permutation(len(radar))]
        return FrameItem(sample.sample_id, lidar, radar, actors, flipped)


__all__ = ["FrameDataset", "FrameItem", "flip_actor", "scene_ids"]
