"""Frames with every actor, for training the referent path (one item per distinct scene).

A Talk2Radar root holds one prompt per sample, and the samples of one synthetic world share their
sensor files. The referent path trains a text-agnostic detector on *all* actors of a frame and its
referent stage on prompts generated during training from those actors
(:func:`scenes.language.prompts.generate_prompts`), so it reads each distinct scene once: the samples of a
split are grouped by ``meta.world_id`` (samples without a sidecar world id are their own scene),
and the first sample of each group stands for it.

Augmentations keep every statement about the scene true, because the prompts are generated from
the augmented actors: the left-right flip mirrors points and actors (``y -> -y``, ``yaw -> -yaw``,
``vy -> -vy``; radar radial velocities unchanged: :func:`scenes.datasets.augment.flip_frame`, drawn by
:meth:`scenes.datasets.augment.AugmentConfig.draws_flip`: the flip's home). The
sensor augmentations of :class:`SensorAugment` (:mod:`scenes.datasets.augment`) make the model robust to what
still differs between the synthetic and the real sensors: intensity gain and offset, random and
beam-wise LiDAR dropout, radar point count, RCS offset, and single-scan radar (real roots often come
with the single-scan ``radar`` tree only). They change what the sensors report; the one exception,
a mounting-height offset, moves the whole scene in z (points and actors alike), which no prompt
speaks of. Nothing rescales distances.

Two sources of a frame's objects and prompts:

- **sidecar** (a synthetic root): the actors of ``meta/<id>.json`` (with ground velocities), and
  prompts generated during training from them;
- **labels** (a root as the real releases come, or any root given ``scene_labels``): the objects
  are the metric-class boxes of the View-of-Delft release's own ``label_2``
  (:class:`scenes.talk2radar.scene_labels.SceneLabels`), the region they cover is the camera's field of view
  (:class:`AnnotatedRegion`; outside it nothing is background), and the prompts are the ones that
  come with the root (:class:`GivenPrompt`: each sample's ``prompt/`` sentence, its referents
  its ``label_2`` boxes matched to the frame's objects). Without scene labels the objects are the
  union of the referents of the frame's samples (every other object then counts as background,
  which :class:`FrameDataset` warns about). Nothing under ``meta/`` is read in this mode; objects
  have no velocity (zeros: the prompts are given, and candidates' motion evidence comes from the
  radar points; a nuScenes sample's actors carry the velocities its data tells,
  :attr:`FrameItem.unknown_motion`).

A frame is :meth:`scenes.talk2radar.root.Talk2RadarRoot.frame_key`: samples sharing sensor files (one
synthetic world, or several prompts on one release frame) are one item.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from torch.utils.data import Dataset

from scenes.datasets import augment as aug
from scenes.datasets.augment import AugmentConfig
from scenes.geometry.actors import Actor
from scenes.geometry.boxes import match_by_centre
from scenes.geometry.calib import IMAGE_SIZE, Calibration
from scenes.geometry.classes import PRESETS, VOD, ClassSet
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels, fov_mask

REFERENT_MATCH_DISTANCE = 1.0
"""A referent box (a Talk2Radar ``label_2`` line) is the frame's labelled object of the same class
whose BEV centre is nearest, within this many metres (both are annotations of one object)."""


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
class GivenPrompt:
    """A prompt that comes with a frame (labels source).

    Attributes:
        sample_id: The sample it is the prompt of.
        text: The sentence (left/right swapped when the frame is flipped).
        referent_ids: Actor ids of its referents among the frame's objects (may be empty).
    """

    sample_id: str
    text: str
    referent_ids: tuple[int, ...]


@dataclass(frozen=True)
class AnnotatedRegion:
    """Where a frame's labels are complete: the camera's field of view (VoD labels only that).

    Attributes:
        calib: The frame's LiDAR calibration.
        image_size: ``(width, height)`` of its camera image.
        mirrored: The frame was flipped left-right (positions are mirrored back to test them).
    """

    calib: Calibration
    image_size: tuple[int, int]
    mirrored: bool = False

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """``(N,)`` bool for ``(N, 2)`` LiDAR-frame ground positions of the (augmented) frame."""
        pts = np.array(xy, dtype=np.float64, copy=True).reshape(-1, 2)
        if self.mirrored:
            pts[:, 1] *= -1
        return fov_mask(pts, self.calib, self.image_size)


@dataclass(frozen=True)
class FrameItem:
    """One scene with all its actors.

    Attributes:
        sample_id: The sample that stands for the scene.
        lidar: ``(N, 4)`` float32, LiDAR frame.
        radar: ``(M, 7)`` float32, LiDAR frame.
        actors: Every actor of the scene (LiDAR frame, ground velocities), augmented with the
            points; on the labels source, the frame's labelled objects (velocities zero, unknown).
        flipped: Whether the left-right flip was applied.
        given: Labels source: the prompts that come with the frame; empty on the sidecar source
            (prompts are generated from the actors, :attr:`generates_prompts`).
        region: Labels source with scene labels: where the labels are complete (None: everywhere).
        from_labels: The labels source (the prompts are given, :attr:`generates_prompts`).
        ignore_boxes: ``(J, 7)`` float64, LiDAR frame: labelled objects outside the class set
            (a nuScenes truck, bus, barrier, ...): no detection target and no negative either
            (:func:`model.training.referent_step.detection_targets`); None: none.
        labels_complete: Every object of the class set is among :attr:`actors` (scene labels,
            or a nuScenes sample: 360 degrees): label prompts may be generated from them.
        prompt_classes: The class set prompts are generated over for this frame
            (``PromptConfig.classes``, :func:`model.training.referent_step.frame_prompts`): on
            the sidecar source the world's (its sidecar's ``extra["classes"]``, ``vod`` when
            absent: a ``--classes nuscenes`` world is talked about by its trucks and cones), on
            the labels source the model's (the actors were read into it).
    """

    sample_id: str
    lidar: np.ndarray
    radar: np.ndarray
    actors: tuple[Actor, ...]
    flipped: bool = False
    given: tuple[GivenPrompt, ...] = ()
    region: AnnotatedRegion | None = None
    from_labels: bool = False
    ignore_boxes: np.ndarray | None = None
    labels_complete: bool = False
    prompt_classes: str = "vod"
    unknown_motion: tuple[int, ...] | None = None

    @property
    def generates_prompts(self) -> bool:
        """Whether prompts are generated from the actors (sidecar source) rather than given."""
        return not self.from_labels


def shift_actor(actor: Actor, dz: float) -> Actor:
    """The actor moved by ``dz`` metres in z (a mounting-height offset)."""
    box = actor.box.copy()
    box[2] += dz
    return Actor(actor.actor_id, actor.cls, box, actor.velocity)


def frame_groups(root: Talk2RadarRoot, split: str) -> list[list[str]]:
    """The sample ids of ``split`` grouped by frame (:meth:`Talk2RadarRoot.frame_key`), groups in
    the order of their first sample."""
    groups: dict[tuple[object, ...], list[str]] = {}
    for sid in root.ids(split):
        groups.setdefault(root.frame_key(sid), []).append(sid)
    return list(groups.values())


def scene_ids(root: Talk2RadarRoot, split: str) -> list[str]:
    """One sample id per distinct frame of ``split`` (the first of each group), in order."""
    return [group[0] for group in frame_groups(root, split)]


def _objects_from_referents(
    boxes: list[np.ndarray], labels: list[np.ndarray], num_classes: int
) -> tuple[np.ndarray, np.ndarray]:
    """The union of several samples' referent boxes of one frame (duplicates merged); labels
    index a set of ``num_classes`` classes."""
    out_boxes: list[np.ndarray] = []
    out_labels: list[int] = []
    limits = np.full(num_classes, REFERENT_MATCH_DISTANCE)
    for b, lab in zip(boxes, labels, strict=True):
        known = np.array(out_boxes).reshape(-1, 7)
        match = match_by_centre(b, lab, known, np.array(out_labels, dtype=np.int64), limits)
        for box, label, m in zip(b, lab, match, strict=True):
            if m < 0:
                out_boxes.append(box)
                out_labels.append(int(label))
    return np.array(out_boxes).reshape(-1, 7), np.array(out_labels, dtype=np.int64)


class FrameDataset(Dataset):
    """The distinct scenes of a split, with their actors (module docstring).

    Args:
        root: A :class:`Talk2RadarRoot` or its path.
        split: ImageSets name.
        augment: Augmentations (None for evaluation).
        sensors: Sensor augmentations, applied when ``augment`` is given (None: none).
        seed: Seed of the augmentation stream (item ``i`` at epoch ``e`` draws from
            ``(seed, e, i)``; call :meth:`set_epoch`).

        scene_labels: A View-of-Delft root with the frames' full labels: the labels source with
            the camera's field of view as the annotated region.
        source: ``"sidecar"``, ``"labels"`` or ``"auto"`` (labels when ``scene_labels`` is given
            or the root has no ``meta/`` folder, as a release; else the sidecar).
        classes: The model's class set: the labels source reads labels of these classes (a
            sidecar's actors are every actor, whatever its class; the model keeps its own).

    Raises:
        ValueError: The split has no scene, or (sidecar source) a scene has no sidecar listing
            its actors.
    """

    def __init__(
        self,
        root: Talk2RadarRoot | str,
        split: str,
        augment: AugmentConfig | None = None,
        sensors: SensorAugment | None = None,
        seed: int = 0,
        scene_labels: SceneLabels | None = None,
        source: str = "auto",
        classes: ClassSet = VOD,
    ) -> None:
        root = root if isinstance(root, Talk2RadarRoot) else Talk2RadarRoot(root, classes=classes)
        if root.classes != classes:
            raise ValueError(
                f"{root.path}: a root read into the {root.classes.name!r} class set given to a "
                f"{classes.name!r} dataset"
            )
        if scene_labels is not None and scene_labels.classes != classes:
            raise ValueError(
                f"{scene_labels.root}: scene labels read into the {scene_labels.classes.name!r} "
                f"class set given to a {classes.name!r} dataset"
            )
        self.classes = classes
        if source not in ("auto", "sidecar", "labels"):
            raise ValueError(f"source must be auto, sidecar or labels, got {source!r}")
        if source == "auto":
            has_meta = (root.path / "meta").is_dir() and root.sidecar
            source = "labels" if scene_labels is not None or not has_meta else "sidecar"
        if source == "sidecar" and scene_labels is not None:
            raise ValueError("scene labels are for the labels source")
        self.source = source
        if source == "labels":
            root = Talk2RadarRoot(
                root.path, radar=root.radar_folder, sidecar=False, classes=classes
            )
        self.root = root
        self.split = split
        self.sensors = sensors
        self.scene_labels = scene_labels
        self.groups = frame_groups(self.root, split)
        self.ids = [group[0] for group in self.groups]
        if not self.ids:
            raise ValueError(f"{self.root.path}: split {split!r} has no samples")
        if source == "labels" and scene_labels is None:
            print(
                f"{self.root.path}: no scene labels given: a frame's objects are the referents of "
                "its prompts, and every other object counts as background (give the View-of-Delft "
                "release with --scene-labels)",
                file=sys.stderr,
            )
        self.augment = augment
        self.seed = seed
        self.epoch = 0

    def limit(self, count: int) -> None:
        """Keep only the first ``count`` frames."""
        self.groups = self.groups[:count]
        self.ids = self.ids[:count]

    def _labelled(
        self, index: int
    ) -> tuple[object, tuple[Actor, ...], tuple[GivenPrompt, ...], AnnotatedRegion | None]:
        """The first sample, objects, given prompts and annotated region of frame ``index``."""
        group = self.groups[index]
        first = self.root.load(group[0])
        referents = [(first.boxes, first.classes, first.prompt)]
        for sid in group[1:]:
            boxes, classes = self.root.load_referents(sid)
            referents.append((boxes, classes, self.root.load_prompt(sid)))
        names = self.classes.names
        ref_labels = [np.array([names.index(c) for c in r[1]], dtype=np.int64) for r in referents]
        region = None
        if self.scene_labels is not None:
            objects = self.scene_labels.load(group[0])
            boxes, labels = objects.metric()
            size = first.image_size if first.image_path is not None else IMAGE_SIZE
            region = AnnotatedRegion(objects.calib, size)
            boxes, labels = list(boxes), list(labels)
        else:
            union = _objects_from_referents([r[0] for r in referents], ref_labels, len(names))
            boxes, labels = list(union[0]), list(union[1])
        limits = np.full(len(names), REFERENT_MATCH_DISTANCE)
        given = []
        for sid, (ref_boxes, _, prompt), ref_lab in zip(group, referents, ref_labels, strict=True):
            match = match_by_centre(
                ref_boxes, ref_lab, np.array(boxes).reshape(-1, 7), np.array(labels), limits
            )
            ids = []
            for box, lab, m in zip(ref_boxes, ref_lab, match, strict=True):
                if m < 0:  # a referent the scene labels lack: it is an object all the same
                    boxes.append(box)
                    labels.append(int(lab))
                    m = len(boxes) - 1
                ids.append(int(m))
            if prompt is not None:
                given.append(GivenPrompt(sid, prompt, tuple(ids)))
        actors = tuple(
            Actor(i, names[int(lab)], box, np.zeros(2))
            for i, (box, lab) in enumerate(zip(boxes, labels, strict=True))
        )
        return first, actors, tuple(given), region

    def set_epoch(self, epoch: int) -> None:
        """Select the augmentation stream of ``epoch``."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.ids)

    def __getitem__(self, index: int) -> FrameItem:
        given: tuple[GivenPrompt, ...] = ()
        region = None
        if self.source == "labels":
            sample, actors, given, region = self._labelled(index)
        else:
            sample = self.root.load(self.ids[index])
            if sample.meta is None or not sample.meta.actors:
                raise ValueError(
                    f"{self.root.path}: sample {sample.sample_id} has no "
                    f"meta/{sample.sample_id}.json listing the scene's actors; a root as the "
                    "releases come trains on its labels: give --scene-labels VOD_ROOT"
                )
            actors = tuple(sample.meta.actors)
        return augment_item(
            FrameItem(
                sample.sample_id,
                np.asarray(sample.lidar, dtype=np.float32),
                np.asarray(sample.radar, dtype=np.float32),
                actors,
                given=given,
                region=region,
                from_labels=self.source == "labels",
                labels_complete=self.scene_labels is not None,
                prompt_classes=self.classes.name
                if sample.meta is None
                else world_classes(sample.meta.extra, self.root.path, sample.sample_id),
            ),
            self.augment,
            self.sensors,
            aug.item_rng(self.seed, self.epoch, index),
        )


def augment_item(
    item: FrameItem,
    augment: AugmentConfig | None,
    sensors: SensorAugment | None,
    rng: np.random.Generator,
) -> FrameItem:
    """``item`` augmented as the module docstring says (the one home of a training frame's
    augmentation, whichever dataset read it): the left-right flip drawn by ``augment`` (points,
    actors, given sentences, annotated region and ignored boxes mirrored), then ``sensors``
    (with their mounting-height offset), then the thinning and shuffling; ``augment`` None: the
    item as it is."""
    if augment is None:
        return item
    lidar, radar, actors, given = item.lidar, item.radar, item.actors, item.given
    region, ignore, flipped = item.region, item.ignore_boxes, item.flipped
    if augment.draws_flip(rng):
        texts = tuple(g.text for g in given)
        lidar, radar, actors, texts = aug.flip_frame(lidar, radar, actors, texts)
        given = tuple(
            GivenPrompt(g.sample_id, text, g.referent_ids)
            for g, text in zip(given, texts, strict=True)
        )
        if region is not None:
            region = AnnotatedRegion(region.calib, region.image_size, mirrored=True)
        if ignore is not None:
            ignore = aug.mirror_boxes(ignore)
        flipped = True
    if sensors is not None:
        lidar, radar = sensors.apply(lidar, radar, rng)
        dz = sensors.mount_offset(rng)
        if dz:
            lidar, radar = lidar.copy(), radar.copy()
            lidar[:, 2] += dz
            radar[:, 2] += dz
            actors = tuple(shift_actor(a, dz) for a in actors)
            if ignore is not None:
                ignore = ignore.copy()
                ignore[:, 2] += dz
    lidar, radar = augment.thin_and_shuffle(lidar, radar, rng)
    return FrameItem(
        item.sample_id,
        lidar,
        radar,
        actors,
        flipped,
        given=given,
        region=region,
        from_labels=item.from_labels,
        ignore_boxes=ignore,
        labels_complete=item.labels_complete,
        prompt_classes=item.prompt_classes,
    )


def world_classes(extra: Mapping[str, object], root: Path, sample_id: str) -> str:
    """The class set a synthetic world was generated with: its sidecar's ``extra["classes"]``
    (``python -m scenes.synth --classes``), ``vod`` when absent (the default world writes none).

    Raises:
        ValueError: the field names no preset (one line naming the sidecar and the field).
    """
    name = extra.get("classes", "vod")
    if name not in PRESETS:
        raise ValueError(
            f"{root / 'meta' / (sample_id + '.json')}: field 'extra.classes': {name!r} is not "
            f"one of {tuple(PRESETS)}"
        )
    return str(name)


__all__ = [
    "REFERENT_MATCH_DISTANCE",
    "AnnotatedRegion",
    "FrameDataset",
    "FrameItem",
    "GivenPrompt",
    "SensorAugment",
    "augment_item",
    "frame_groups",
    "scene_ids",
    "shift_actor",
    "world_classes",
]
