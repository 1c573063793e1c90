"""Frames with every actor, for training the referent path (one item per distinct scene).

A Talk2Radar root holds one prompt per sample, and the samples of one synthetic world share their
sensor files. The referent path trains a text-agnostic detector on *all* actors of a frame and its
referent stage on prompts generated during training from those actors
(:func:`scenes.prompts.generate_prompts`), so it reads each distinct scene once: the samples of a
split are grouped by ``meta.world_id`` (samples without a sidecar world id are their own scene),
and the first sample of each group stands for it.

Augmentations keep every statement about the scene true, because the prompts are generated from
the augmented actors: the left-right flip mirrors points and actors (``y -> -y``, ``yaw -> -yaw``,
``vy -> -vy``; radar radial velocities unchanged, as :func:`scenes.dataset.flip_sample`). The
sensor augmentations of :class:`SensorAugment` (:mod:`scenes.augment`) make the model robust to what
still differs between the synthetic and the real sensors: intensity gain and offset, random and
beam-wise LiDAR dropout, radar point count, RCS offset, and single-scan radar (real roots often come
with the single-scan ``radar`` tree only). They change what the sensors report; the one exception,
a mounting-height offset, moves the whole scene in z (points and actors alike), which no prompt
speaks of. Nothing rescales distances.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from torch.utils.data import Dataset

from scenes import augment as aug
from scenes.actors import Actor
from scenes.boxes import wrap_yaw
from scenes.dataset import AugmentConfig
from scenes.root import Talk2RadarRoot


@dataclass(frozen=True)
class SensorAugment:
    """Probabilities and ranges of the sensor augmentations (each applied independently).

    Attributes:
        p_intensity: Probability of a random intensity gain/offset (:func:`jitter_intensity`).
        p_beams: Probability of beam-wise LiDAR dropout at a rate up to ``max_beam_rate``.
        max_beam_rate: Largest fraction of beams removed.
        p_radar_subsample: Probability of keeping only ``radar_keep`` of the radar points.
        radar_keep: Range of the kept fraction.
        p_rcs: Probability of a common RCS offset of up to 3 dB.
        p_single_scan: Probability of keeping only the newest radar scan (``time == 0``).
        p_mount: Probability of a mounting-height offset: the whole scene (both clouds and every
            actor box) moves by a uniform ``+-mount_shift`` metres in z, so that the detector does
            not rely on the generator's exact LiDAR height (1.70 m) when a real car's differs.
        mount_shift: Largest offset (m).
    """

    p_intensity: float = 0.5
    p_beams: float = 0.2
    max_beam_rate: float = 0.3
    p_radar_subsample: float = 0.3
    radar_keep: tuple[float, float] = (0.5, 1.0)
    p_rcs: float = 0.3
    p_single_scan: float = 0.25
    p_mount: float = 0.5
    mount_shift: float = 0.2

    def mount_offset(self, rng: np.random.Generator) -> float:
        """The z offset (m) of one item: 0, or uniform in ``+-mount_shift`` with ``p_mount``."""
        if rng.random() < self.p_mount:
            return float(rng.uniform(-self.mount_shift, self.mount_shift))
        return 0.0

    def apply(
        self, lidar: np.ndarray, radar: np.ndarray, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Augmented copies of ``lidar (N, 4)`` and ``radar (M, 7)``."""
        if rng.random() < self.p_intensity and len(lidar):
            lidar = aug.jitter_intensity(lidar, rng)
        if rng.random() < self.p_beams and len(lidar):
            lidar = aug.drop_beams(lidar, rng, float(rng.uniform(0.0, self.max_beam_rate)))
        if rng.random() < self.p_single_scan and len(radar):
            radar = aug.single_scan(radar)
        if rng.random() < self.p_radar_subsample and len(radar):
            radar = aug.subsample_radar(radar, rng, self.radar_keep)
        if rng.random() < self.p_rcs and len(radar):
            radar = aug.jitter_rcs(radar, rng)
        return np.asarray(lidar, np.float32), np.asarray(radar, np.float32)


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


def shift_actor(actor: Actor, dz: float) -> Actor:
    """The actor moved by ``dz`` metres in z (a mounting-height offset)."""
    box = actor.box.copy()
    box[2] += dz
    return Actor(actor.actor_id, actor.cls, box, actor.velocity)


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
        sensors: Sensor augmentations, applied when ``augment`` is given (None: none).
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
        sensors: SensorAugment | None = None,
        seed: int = 0,
    ) -> None:
        self.root = root if isinstance(root, Talk2RadarRoot) else Talk2RadarRoot(root)
        self.split = split
        self.sensors = sensors
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
            if self.sensors is not None:
                lidar, radar = self.sensors.apply(lidar, radar, rng)
                dz = self.sensors.mount_offset(rng)
                if dz:
                    lidar, radar = lidar.copy(), radar.copy()
                    lidar[:, 2] += dz
                    radar[:, 2] += dz
                    actors = tuple(shift_actor(a, dz) for a in actors)
            lidar, radar = self.augment.thin_and_shuffle(lidar, radar, rng)
        return FrameItem(sample.sample_id, lidar, radar, actors, flipped)


__all__ = ["FrameDataset", "FrameItem", "SensorAugment", "flip_actor", "scene_ids", "shift_actor"]
