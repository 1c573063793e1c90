"""The samples of a nuScenes root with its Talk2Car commands as a frame source:
:class:`NuScenesSource` (a :class:`scenes.frame.FrameSource`).

Every sample of the root is a frame, by scene then time (split ``all``); a split of the
``--talk2car`` folder (``train``, ``val``, ``test``: its ``{split}_commands.json``) serves the
samples its commands refer to. A frame is the :class:`scenes.nuscenes.root.NuScenesFrame` as a
:class:`scenes.frame.Sample`: the LiDAR and all five radars in the model frame (radar channels
as View-of-Delft's), the CAM_FRONT image with the calibration whose P2 / Tr_velo_to_cam the
projection code uses, ``boxes`` / ``classes`` = the annotations whose category is in the class
set (:func:`scenes.nuscenes.classes.model_class`), and ``prompt`` = the sample's first command.
A sample's split is the command file whose ``scene_tokens`` lists its scene
(:meth:`NuScenesSource.sample_split`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes.frame import Sample
from scenes.geometry.classes import VOD, ClassSet
from scenes.nuscenes.classes import model_class
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import CommandFileError, Talk2CarCommand, read_commands
from scenes.utils.errors import RootError

__all__ = ["ALL", "COMMANDS_SUFFIX", "NuScenesSource", "SampleCommand"]

log = logging.getLogger(__name__)

ALL = "all"
"""The split of every sample of the root."""
SPLIT_ORDER = ("train", "val", "test")
COMMANDS_SUFFIX = "_commands.json"


@dataclass(frozen=True)
class SampleCommand:
    """A command of a sample: its split, the command, its referred box (``(7,)`` model frame)
    and class."""

    split: str
    command: Talk2CarCommand
    box: np.ndarray
    cls: str


class NuScenesSource:
    """The samples of a nuScenes root as frames (module docstring).

    Args:
        path: The nuScenes root (holding ``v1.0-*/``).
        talk2car: The folder holding ``{split}_commands.json`` (None: no commands).

    Raises:
        scenes.nuscenes.tables.NuScenesError: a malformed root; a missing ``talk2car`` folder, one
            without command files, or a malformed command file (one line naming it).
    """

    has_prompts = False
    """No Talk2Radar prompt folder: the annotations are the labelled boxes."""
    radar_folder = None

    def frame_key(self, sample_id: str) -> tuple[object, ...]:
        """The identity of a sample's frame: its token (each sample its own sensors)."""
        return (self.path, sample_id)

    def __init__(
        self, path: str | Path, talk2car: str | Path | None = None, classes: ClassSet = VOD
    ) -> None:
        self.nuscenes = NuScenesRoot(path)
        self.classes = classes
        """The served model's class set: an annotation is a sample's box when its category maps
        onto one of these classes (:func:`scenes.nuscenes.classes.model_class`)."""
        self.path = self.nuscenes.path
        self.talk2car = Path(talk2car) if talk2car is not None else None
        self._split_ids: dict[str, list[str]] = {ALL: list(self.nuscenes.samples)}
        self._commands: dict[str, list[SampleCommand]] = {}
        self._scene_split: dict[str, str] = {}
        """scene token -> the split whose command file lists the scene (the first, in order)."""
        self.skipped: dict[str, dict[str, int]] = {}
        """split -> skip reason -> count (the loader's, also logged)."""
        if self.talk2car is not None:
            self._read_commands(self.talk2car)

    def __repr__(self) -> str:
        return f"NuScenesSource({str(self.path)!r}, talk2car={self.talk2car!r})"

    def _read_commands(self, folder: Path) -> None:
        if not folder.is_dir():
            raise CommandFileError(f"--talk2car {folder}: no such folder")
        names = sorted(p.name[: -len(COMMANDS_SUFFIX)] for p in folder.glob("*" + COMMANDS_SUFFIX))
        if not names:
            raise CommandFileError(f"--talk2car {folder}: no {{split}}{COMMANDS_SUFFIX} file")
        order = {s: i for i, s in enumerate(SPLIT_ORDER)}
        position = {s: i for i, s in enumerate(self.nuscenes.samples)}
        for split in sorted(names, key=lambda s: (order.get(s, len(order)), s)):
            found = read_commands(folder, split, self.nuscenes, self.classes)
            self.skipped[split] = dict(found.skipped)
            for scene in found.scene_tokens:
                self._scene_split.setdefault(scene, split)
            for reason, count in sorted(found.skipped.items()):
                log.warning("%s: %s: %d command(s) skipped: %s", folder, split, count, reason)
            samples = set()
            for c in found.commands:
                ref = found.referent[c.command_token]
                self._commands.setdefault(c.sample_token, []).append(
                    SampleCommand(split, c, ref.box, ref.cls)
                )
                samples.add(c.sample_token)
            self._split_ids[split] = sorted(samples, key=position.__getitem__)

    # ------------------------------------------------------------------ FrameSource

    def splits(self) -> list[str]:
        """``all``, then the command files' splits (train, val, test first)."""
        return list(self._split_ids)

    def ids(self, split: str) -> list[str]:
        """The sample tokens of ``split`` in the root's order.

        Raises:
            RootError: an unknown split (the message lists the others).
        """
        if split not in self._split_ids:
            raise RootError(
                f"{self.path}: no split {split!r} (splits: {', '.join(self.splits())}; a split is "
                "a --talk2car command file)"
            )
        return list(self._split_ids[split])

    def choose_split(self, split: str | None) -> str:
        """``split`` when given (checked), else ``all``."""
        if split is None:
            return ALL
        self.ids(split)
        return split

    def commands(self, sample_token: str) -> tuple[SampleCommand, ...]:
        """The commands of a sample, every split, in file order."""
        return tuple(self._commands.get(sample_token, ()))

    def sample_split(self, sample_token: str) -> str | None:
        """The split a sample belongs to: the one whose command file lists its scene in
        ``scene_tokens`` (Talk2Car splits by scene), else the split of its first command; None
        when no command file says (no ``--talk2car``, a scene none lists)."""
        record = self.nuscenes.tables.records["sample"].get(sample_token)
        split = self._scene_split.get(record["scene_token"]) if record is not None else None
        if split is None and self._commands.get(sample_token):
            split = self._commands[sample_token][0].split
        return split

    def load(self, sample_id: str) -> Sample:
        """The sample as a :class:`Sample` (module docstring).

        Raises:
            scenes.nuscenes.tables.NuScenesError,
            scenes.nuscenes.sensorfiles.SensorFileError: a dangling token, a bad sensor file.
        """
        frame = self.nuscenes.frame(sample_id)
        keep, classes = [], []
        for i, (category, attributes) in enumerate(
            zip(frame.categories, frame.attributes, strict=True)
        ):
            cls = model_class(category, attributes, self.classes)
            if cls is not None:
                keep.append(i)
                classes.append(cls)
        commands = self.commands(sample_id)
        return Sample(
            sample_id=sample_id,
            lidar=frame.lidar,
            radar=frame.radar,
            boxes=frame.boxes[keep].reshape(-1, 7),
            classes=tuple(classes),
            prompt=commands[0].command.text if commands else None,
            calib=frame.calib,
            image_path=frame.image_path,
        )
