"""The training data of the referent path: one or several roots, each with its source and weight.

``python -m model.train --data ROOT [--data ROOT2 ...] [--data-weight W ...] [--scene-labels VOD
...]``: each ``--data`` root is one :class:`RootSpec`. ``--data-weight`` and ``--scene-labels`` pair
with the ``--data`` roots in order (give ``none`` for a root without scene labels; fewer values
than roots leave the rest at weight 1, a nuScenes root at :func:`talk2car_weight` of its
training commands and samples, and without scene labels). A root given scene labels, or one
without a ``meta/`` folder (a release as it comes), trains on its labels and given prompts and
never reads a sidecar; a synthetic root with its sidecar trains on generated prompts
(:class:`scenes.datasets.frames.FrameDataset`). So one command can pre-train on our world and
fine-tune on a user's: ``--data data/synth --data T2R --scene-labels none --scene-labels VOD``.

A ``--data`` root holding a ``v1.0-*`` folder is a nuScenes root (found automatically,
:func:`scenes.datasets.source.root_family`); it trains on the Talk2Car commands of
the matching ``--talk2car`` folder (paired with the ``--data`` roots in order, ``none`` for a
Talk2Radar root), every annotation of a commanded sample a detection target
(:class:`scenes.datasets.nuscenes_frames.NuScenesFrames`).

:class:`MixedFrames` is the epoch over several roots: the items of a root of weight ``w`` are seen
``w`` times per epoch on average (``floor(w)`` times each, plus a random ``w - floor(w)`` share of
them, drawn per epoch from ``(seed, epoch)``), so an epoch's length is fixed and a resumed run
draws the same epoch again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from torch.utils.data import Dataset

from scenes.datasets.family_files import SceneLabels, command_counts
from scenes.datasets.frames import FrameDataset, FrameItem
from scenes.datasets.nuscenes_frames import NuScenesFrames, open_talk2car
from scenes.datasets.source import NUSCENES, root_family
from scenes.frame import RootError
from scenes.geometry.classes import VOD, ClassSet

NO_SCENE_LABELS = "none"
"""The ``--scene-labels`` value of a root that has none."""

TALK2CAR_VISITS = 510
"""The fewest sample visits an epoch that a nuScenes root gets when ``--data-weight`` is not given
(:func:`talk2car_weight`; never more than 3 a sample): a root of few samples holding several
commands each under-trains a referent stage at one pass an epoch (``--freeze-scene --init-detector``: 30 epochs of one pass over 170 samples of 7 commands each
reached 63.7 % top-1 on 2,125 val commands of another seed, of two passes 66.7 %, of three
70.1 % with :data:`model.training.config.TALK2CAR_LABEL_PROMPTS` label prompts;
docs/RESULTS_HISTORY.md, "Talk2Car on synthetic nuScenes roots")."""

TALK2CAR_COMMANDS_PER_VISIT = 2.4
"""Beyond :data:`TALK2CAR_VISITS`, a nuScenes root's epoch visits one sample per this many training
commands (that root's 1,220 commands over 510 visits): an epoch's length, and so a run's,
follows what the referent stage learns from (the commands), not how many samples hold them. The
release's 8,349 training commands on about 6,500 samples (its test split holds 1.28 commands a
sample): 3,479 visits an epoch, each sample about half an epoch; a root of 1,000 commands of one
sample each: 510 (docs/TALK2CAR.md, "What a run costs")."""

TALK2CAR_MAX_WEIGHT = 3.0
"""The largest default weight of a nuScenes root (:func:`talk2car_weight`)."""


def talk2car_weight(commands: int, samples: int) -> float:
    """A nuScenes root's default ``--data-weight`` for ``commands`` training commands on
    ``samples`` samples: ``commands / TALK2CAR_COMMANDS_PER_VISIT`` visits an epoch, at least
    :data:`TALK2CAR_VISITS`, over its samples, within ``(0, TALK2CAR_MAX_WEIGHT]`` (170 samples of
    7 commands: 3; 1,000 samples of one command: 0.51; the release's 8,349 on 6,500: 0.54)."""
    if samples <= 0:
        return TALK2CAR_MAX_WEIGHT
    visits = max(float(TALK2CAR_VISITS), commands / TALK2CAR_COMMANDS_PER_VISIT)
    return float(min(TALK2CAR_MAX_WEIGHT, visits / samples))


def mirrored_cache(spec: RootSpec) -> bool:
    """Whether a ``--freeze-scene`` run caches this root's scenes mirrored as well (with
    ``--flip-probability`` above 0): a Talk2Radar root always; a nuScenes root while it has at
    most :data:`TALK2CAR_VISITS` commanded samples. A root of more is visited less than once a
    sample an epoch, so its own samples are variety enough, and a mirrored view would double the
    caching that grows with its samples (the issue-48 root of 1,224 samples: about half of a
    run's time)."""
    return spec.talk2car is None or (spec.samples or 0) <= TALK2CAR_VISITS


class DataSpecError(ValueError):
    """The ``--data`` / ``--data-weight`` / ``--scene-labels`` values do not fit together."""


@dataclass(frozen=True)
class RootSpec:
    """One training root.

    Attributes:
        path: The Talk2Radar root.
        weight: Times each of its frames is seen per epoch, on average (> 0).
        scene_labels: A View-of-Delft root with the frames' full labels, or None.
        talk2car: A nuScenes root's Talk2Car command folder (``{split}_commands.json``), or None
            (a Talk2Radar root).
        samples: A nuScenes root's commanded training samples
            (:func:`scenes.nuscenes.talk2car.command_counts`), or None.
        commands: A nuScenes root's training commands (the same count), or None.
    """

    path: str
    weight: float = 1.0
    scene_labels: str | None = None
    talk2car: str | None = None
    samples: int | None = None
    commands: int | None = None

    @property
    def labelled(self) -> bool:
        """Whether the root's frames list every object of the class set (scene labels, or a
        nuScenes root): label prompts are generated from them."""
        return self.scene_labels is not None or self.talk2car is not None


def root_specs(
    data: Sequence[str],
    weights: Sequence[float] = (),
    scene_labels: Sequence[str] = (),
    talk2car: Sequence[str] = (),
) -> tuple[RootSpec, ...]:
    """Pair the ``--data``, ``--data-weight``, ``--scene-labels`` and ``--talk2car`` values
    (module docstring).

    Raises:
        DataSpecError: no root, more weights, scene-label roots or command folders than
            ``--data`` roots, a weight that is not a positive finite number, a nuScenes root
            without its ``--talk2car`` folder (or given scene labels), or a command folder for a
            root that is not a nuScenes root.
    """
    if not data:
        raise DataSpecError("--data: give at least one root")
    for flag, values in (
        ("--data-weight", weights),
        ("--scene-labels", scene_labels),
        ("--talk2car", talk2car),
    ):
        if len(values) > len(data):
            raise DataSpecError(
                f"{flag} given {len(values)} times for {len(data)} --data roots; they pair in order"
            )
    out = []
    for i, path in enumerate(data):
        labels = scene_labels[i] if i < len(scene_labels) else None
        labels = None if labels in (None, NO_SCENE_LABELS) else labels
        commands = talk2car[i] if i < len(talk2car) else None
        commands = None if commands in (None, NO_SCENE_LABELS) else commands
        try:
            nuscenes = root_family(path, commands, commands_required=True) == NUSCENES
        except RootError as exc:
            raise DataSpecError(str(exc)) from exc
        count = samples = None
        if nuscenes and commands is not None:
            try:
                count, samples = command_counts(commands, "train")
            except RootError as exc:
                raise DataSpecError(str(exc)) from exc
        if i < len(weights):
            weight = float(weights[i])
        elif count is not None and samples is not None:
            weight = talk2car_weight(count, samples)
        else:
            weight = 1.0
        if not math.isfinite(weight) or weight <= 0:
            raise DataSpecError(f"--data-weight {weights[i]!r} of {path}: must be a number > 0")
        if nuscenes and labels is not None:
            raise DataSpecError(
                f"--scene-labels {labels} pairs with the nuScenes root {path}, whose own "
                "annotations are its scene labels; give 'none'"
            )
        out.append(RootSpec(path, weight, labels, commands, samples, count))
    return tuple(out)


TrainingFrames = FrameDataset | NuScenesFrames
"""One root's training frames: a Talk2Radar root's, or a nuScenes root's commanded samples."""


def frame_dataset(
    spec: RootSpec, split: str, classes: ClassSet = VOD, **kwargs: object
) -> TrainingFrames:
    """The frames of one root's ``split`` (its source chosen as the module says); a Talk2Radar
    root's labels read into ``classes`` (the model's class set)."""
    if spec.talk2car is not None:
        root, commands = open_talk2car(spec.path, spec.talk2car, split, classes)
        return NuScenesFrames(root, commands, classes=classes, **kwargs)  # type: ignore[arg-type]
    labels = None if spec.scene_labels is None else SceneLabels(spec.scene_labels, classes)
    return FrameDataset(spec.path, split, scene_labels=labels, classes=classes, **kwargs)  # type: ignore[arg-type]


class MixedFrames(Dataset):
    """Several :class:`FrameDataset`\\ s as one epoch, each root at its weight (module docstring).

    Item ``j`` of an epoch is frame :meth:`resolve` ``(j)`` of the concatenation of the roots.
    """

    def __init__(self, datasets: Sequence[TrainingFrames], weights: Sequence[float], seed: int = 0):
        if len(datasets) != len(weights) or not datasets:
            raise DataSpecError("MixedFrames needs one weight per dataset")
        self.datasets = list(datasets)
        self.weights = [float(w) for w in weights]
        self.seed = seed
        self.offsets = np.cumsum([0] + [len(d) for d in self.datasets])
        self.epoch = -1
        self.set_epoch(0)

    def _table(self, epoch: int) -> np.ndarray:
        parts = []
        for r, (d, w) in enumerate(zip(self.datasets, self.weights, strict=True)):
            n = len(d)
            whole, frac = int(math.floor(w)), w - math.floor(w)
            items = np.tile(np.arange(n), whole)
            extra = int(round(frac * n))
            if extra:
                rng = np.random.default_rng((self.seed, epoch, 3, r))
                items = np.concatenate([items, rng.choice(n, size=extra, replace=False)])
            parts.append(items + self.offsets[r])
        return np.concatenate(parts).astype(np.int64)

    def set_epoch(self, epoch: int) -> None:
        """Draw ``epoch``'s items and select its augmentation streams."""
        if epoch != self.epoch:
            self.table = self._table(epoch)
            self.epoch = epoch
        for d in self.datasets:
            d.set_epoch(epoch)

    def __len__(self) -> int:
        return len(self.table)

    def resolve(self, index: int) -> int:
        """The frame of item ``index``, as an index into the roots' concatenation."""
        return int(self.table[index])

    def locate(self, flat: int) -> tuple[int, int]:
        """``(root, frame)`` of an index into the concatenation."""
        r = int(np.searchsorted(self.offsets, flat, side="right") - 1)
        return r, flat - int(self.offsets[r])

    def __getitem__(self, index: int) -> FrameItem:
        r, i = self.locate(self.resolve(index))
        return self.datasets[r][i]


__all__ = [
    "NO_SCENE_LABELS",
    "TALK2CAR_COMMANDS_PER_VISIT",
    "TALK2CAR_MAX_WEIGHT",
    "TALK2CAR_VISITS",
    "DataSpecError",
    "MixedFrames",
    "RootSpec",
    "TrainingFrames",
    "frame_dataset",
    "mirrored_cache",
    "root_specs",
    "talk2car_weight",
]
