"""nuScenes samples with their Talk2Car commands as training frames (the labels source).

A nuScenes root (``scenes.nuscenes.root.NuScenesRoot``) with the Talk2Car commands of one split
(``scenes.nuscenes.talk2car.read_commands``) trains the referent path as a View-of-Delft root
with scene labels does (:class:`scenes.datasets.frames.FrameDataset`'s labels source): one
:class:`scenes.datasets.frames.FrameItem` per nuScenes sample that a command of the split refers
to, in the root's sample order, with

- ``actors``: every annotation of the sample whose category maps into the model's class set
  (``scenes.nuscenes.classes.model_class`` with ``classes``: a ``nuscenes`` model's trucks and
  cones are actors, a ``vod`` model's are ignored), in the model frame, velocities zero (unknown); an
  actor's id is its annotation's index in the frame (``NuScenesFrame.boxes``), so a command's
  referent (``CommandSet.referent``: a ``Referent`` with box, cls and annotation index) is the actor of that id;
- ``ignore_boxes``: the annotations outside the class set (a truck, a bus, a barrier): no
  detection target, and no negative either (as View-of-Delft's non-metric labels are kept out of
  the metric);
- ``given``: the sample's commands, each with its one referent;
- ``region`` None and ``labels_complete`` True: nuScenes labels every object around the car, so
  label prompts are generated from the boxes (``--label-prompts``) and nothing is outside.

Augmentations are :func:`scenes.datasets.frames.augment_item`'s (the one home).

Only the names of the issue-40 contract are read from ``scenes.nuscenes`` (``NuScenesRoot``,
``NuScenesFrame``, ``read_commands`` and ``CommandSet``, ``model_class``); :func:`open_talk2car`
is the one place they are imported (tests give their own root and commands to
:class:`NuScenesFrames` directly).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache, partial
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from torch.utils.data import Dataset

from scenes.datasets import augment as aug
from scenes.datasets.augment import AugmentConfig
from scenes.datasets.frames import FrameItem, GivenPrompt, SensorAugment, augment_item
from scenes.geometry.actors import Actor
from scenes.geometry.classes import VOD, ClassSet

RADAR_SWEEPS = 5
"""Radar sweeps accumulated per radar when the model reads a nuScenes root (``time = -k`` for the
k-th older one): the model's radar channels are View-of-Delft's five accumulated scans with their
scan index, and nuScenes' single sweeps are sparse (docs/TALK2CAR.md, sections 3 and 4)."""


class ReferentLike(Protocol):
    """What is read of ``scenes.nuscenes.talk2car.Referent``: the referred annotation."""

    box: np.ndarray  # (7,) float64, model frame
    cls: str  # its model class
    index: int  # its index in the frame's annotations (NuScenesFrame.annotation_tokens)


class CommandSetLike(Protocol):
    """What is read of ``scenes.nuscenes.talk2car.CommandSet``."""

    commands: Sequence[Any]
    referent: dict[str, ReferentLike]
    split: str


class NuScenesRootLike(Protocol):
    """What is read of ``scenes.nuscenes.root.NuScenesRoot``."""

    samples: tuple[str, ...]

    def frame(self, sample_token: str) -> Any: ...


def open_talk2car(
    path: str | Path, commands: str | Path, split: str, classes: ClassSet = VOD
) -> tuple[NuScenesRootLike, CommandSetLike]:
    """The nuScenes root at ``path`` (:data:`RADAR_SWEEPS` radar sweeps a frame) and its Talk2Car
    commands of ``split`` (``commands``: the folder holding ``{split}_commands.json``) whose
    referents map onto ``classes`` (the model's set); the loader's skip reasons are printed by
    count.

    Raises:
        ValueError: a malformed root or command file (the loader's one-line message).
    """
    return _opened(str(path), str(commands), split, classes, _files_state(path, commands, split))


def _files_state(path: str | Path, commands: str | Path, split: str) -> tuple:
    """What the opened root and commands were read from: the size and change time of every table
    and of the command file (another state opens them again)."""
    from scenes.nuscenes.tables import version_folder
    from scenes.nuscenes.talk2car import commands_file

    try:
        files = sorted(version_folder(Path(path), None).glob("*.json"))
    except (OSError, ValueError):
        files = []
    files.append(commands_file(commands, split))
    state = []
    for f in files:
        try:
            st = f.stat()
            state.append((str(f), st.st_size, st.st_mtime_ns))
        except OSError:
            state.append((str(f), None, None))
    return tuple(state)


@lru_cache(maxsize=2)
def _opened(
    path: str, commands: str, split: str, classes: ClassSet, state: tuple
) -> tuple[NuScenesRootLike, CommandSetLike]:
    """:func:`open_talk2car`, once per root, split, class set and files' state: a training run
    opens its root for the training frames and for both views of the ``--freeze-scene`` cache
    (tables of a thousand samples take seconds to read and check)."""
    import sys

    from scenes.nuscenes.root import NuScenesRoot
    from scenes.nuscenes.talk2car import read_commands

    root = NuScenesRoot(path, radar_sweeps=RADAR_SWEEPS)
    found = read_commands(commands, split, root, classes)
    for reason, count in sorted(found.skipped.items()):
        print(f"{commands}: {split}: {count} command(s) skipped: {reason}", file=sys.stderr)
    return root, found


def frame_actors(
    frame: Any, model_class: Any, classes: ClassSet = VOD
) -> tuple[tuple[Actor, ...], np.ndarray, tuple[int, ...] | None]:
    """The actors of a ``NuScenesFrame`` (annotations whose category ``model_class`` maps into
    ``classes``, id = annotation index, velocity the frame's where known, else zero), the
    ``(J, 7)`` boxes of the others (:attr:`FrameItem.ignore_boxes`) and the ids of the actors
    whose velocity is unknown (:attr:`FrameItem.unknown_motion`; None: a frame without
    velocities)."""
    boxes = np.asarray(frame.boxes, dtype=np.float64).reshape(-1, 7)
    given = getattr(frame, "velocities", None)
    velocities = np.full((len(boxes), 2), np.nan) if given is None else given
    velocities = np.asarray(velocities, dtype=np.float64).reshape(len(boxes), 2)
    actors, ignored, unknown = [], [], []
    for i, (box, category, attributes) in enumerate(
        zip(boxes, frame.categories, frame.attributes, strict=True)
    ):
        cls = model_class(category, attributes)
        if cls is None:
            ignored.append(box)
        elif cls not in classes:
            raise ValueError(
                f"model_class({category!r}) gave {cls!r}, not one of the {classes.name!r} class "
                f"set ({', '.join(classes.names)})"
            )
        else:
            known = np.isfinite(velocities[i]).all()
            actors.append(Actor(i, cls, box.copy(), velocities[i].copy() if known else np.zeros(2)))
            if not known:
                unknown.append(i)
    ignored_boxes = np.array(ignored, dtype=np.float64).reshape(-1, 7)
    return tuple(actors), ignored_boxes, None if given is None else tuple(unknown)


def _model_class(classes: ClassSet) -> Any:
    from scenes.nuscenes.classes import model_class

    return partial(model_class, classes=classes)


class NuScenesFrames(Dataset):
    """The nuScenes samples of a split's Talk2Car commands as training frames (module docstring).

    Args:
        root: The nuScenes root (``NuScenesRoot``).
        commands: Its commands of one split (``CommandSet``); only kept commands with a referent.
        augment, sensors, seed: As :class:`scenes.datasets.frames.FrameDataset`'s.
        model_class: ``(category, attributes) -> class name or None`` (default
            ``scenes.nuscenes.classes.model_class`` into ``classes``, the mapping's one home).
        classes: The model's class set: the annotations whose category maps onto it are the
            actors (a ``nuscenes`` model trains on trucks, cones, ...), the others are ignored;
            prompts are generated over it (:attr:`FrameItem.prompt_classes`).

    Raises:
        ValueError: no command of the split has a referent.
    """

    source = "labels"

    def __init__(
        self,
        root: NuScenesRootLike,
        commands: CommandSetLike,
        augment: AugmentConfig | None = None,
        sensors: SensorAugment | None = None,
        seed: int = 0,
        model_class: Any = None,
        classes: ClassSet = VOD,
    ) -> None:
        self.root = root
        self.commands = commands
        self.split = commands.split
        self.augment = augment
        self.sensors = sensors
        self.seed = seed
        self.epoch = 0
        self.classes = classes
        self.model_class = model_class or _model_class(classes)
        by_sample: dict[str, list[Any]] = {}
        for command in commands.commands:
            if command.command_token in commands.referent:
                by_sample.setdefault(command.sample_token, []).append(command)
        order = {token: i for i, token in enumerate(root.samples)}
        self.ids = sorted(by_sample, key=lambda t: order.get(t, len(order)))
        self.by_sample = by_sample
        if not self.ids:
            raise ValueError(
                f"Talk2Car split {commands.split!r}: no command with a referent in the class set "
                f"({', '.join(classes.names)}): nothing to train on"
            )

    @property
    def command_count(self) -> int:
        """Commands of the frames kept."""
        return sum(len(self.by_sample[t]) for t in self.ids)

    def limit(self, count: int) -> None:
        """Keep only the first ``count`` frames."""
        self.ids = self.ids[:count]

    def set_epoch(self, epoch: int) -> None:
        """Select the augmentation stream of ``epoch``."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.ids)

    def item(self, index: int) -> FrameItem:
        """Frame ``index`` as read (not augmented)."""
        token = self.ids[index]
        frame = self.root.frame(token)
        actors, ignored, unknown_motion = frame_actors(frame, self.model_class, self.classes)
        known = {a.actor_id for a in actors}
        given = []
        for command in self.by_sample[token]:
            annotation = self.commands.referent[command.command_token].index
            if int(annotation) not in known:
                raise ValueError(
                    f"Talk2Car command {command.command_token}: its referent, annotation "
                    f"{annotation} of sample {token}, is not in the class set of the frame"
                )
            given.append(GivenPrompt(command.command_token, command.text, (int(annotation),)))
        return FrameItem(
            token,
            np.asarray(frame.lidar, dtype=np.float32).reshape(-1, 4),
            np.asarray(frame.radar, dtype=np.float32).reshape(-1, 7),
            actors,
            given=tuple(given),
            region=None,
            from_labels=True,
            ignore_boxes=ignored,
            labels_complete=True,
            prompt_classes=self.classes.name,
            unknown_motion=unknown_motion,
        )

    def __getitem__(self, index: int) -> FrameItem:
        item = self.item(index)
        rng = aug.item_rng(self.seed, self.epoch, index)
        return augment_item(item, self.augment, self.sensors, rng)


__all__ = [
    "RADAR_SWEEPS",
    "NuScenesFrames",
    "frame_actors",
    "open_talk2car",
]
