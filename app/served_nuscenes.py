"""A nuScenes root with its Talk2Car commands, served: :class:`NuScenesSource` (the frames) and
:class:`NuScenesServed` (the root kind, :mod:`app.served`).

Frames. Every sample of the root is a frame, by scene then time (split ``all``); a split of the
``--talk2car`` folder (``train``, ``val``, ``test``: its ``{split}_commands.json``) serves the
samples its commands refer to. A frame is the :class:`scenes.nuscenes.root.NuScenesFrame` as the
app's :class:`scenes.talk2radar.root.Sample`: the LiDAR and all five radars in the model frame
(radar channels as View-of-Delft's, so they are coloured by velocity as on Talk2Radar), the
CAM_FRONT image with the calibration whose P2 / Tr_velo_to_cam the projection code uses,
``boxes`` / ``classes`` = the annotations whose category is in the class set
(:func:`scenes.nuscenes.classes.model_class`; the labelled boxes of "Candidates: Labelled boxes"
and the Annotate tab's ready-made boxes, as a View-of-Delft release's), and ``prompt`` = the
sample's first command (the Query tab's prompt box). Under the frame summary
(:meth:`NuScenesSource.notes`): the scene (its position among the scenes, its description) and
every command of the sample with its referred box.

Pairs. Annotated pairs are Talk2Car commands (:class:`annotate.talk2car.Talk2CarStore`) saved
only into the folder named with ``--pairs DIR`` (``DIR/commands/{split}_commands.json``); without
it nothing is written and the tab suggests ``<root>-talk2car``. A ``DIR`` whose ``commands/`` lies
inside the served root or is (or lies inside) the ``--talk2car`` folder is refused when the app
starts (:func:`annotate.talk2car.check_pairs_folder`): the release is never written.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from annotate import Draft, SourceFrame, StoreError
from annotate.talk2car import Talk2CarStore, check_pairs_folder, referred_annotation
from annotate.validation import Issue
from app.labelled import LabelledFrames
from app.text import md_text
from scenes.geometry.classes import VOD, ClassSet
from scenes.nuscenes.classes import model_class
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import CommandFileError, Talk2CarCommand, read_commands
from scenes.talk2radar.drives import Drive, DriveFrame, Drives
from scenes.talk2radar.layout import RootError
from scenes.talk2radar.root import Sample

__all__ = ["ALL", "PAIRS_SUFFIX", "NuScenesServed", "NuScenesSource", "SampleCommand"]

log = logging.getLogger(__name__)

ALL = "all"
"""The split of every sample of the root."""
PAIRS_SUFFIX = "-talk2car"
"""Name suffix of the folder suggested for the commands annotated on a nuScenes root."""
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
    """The samples of a nuScenes root as the app's frames (module docstring).

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

    # ------------------------------------------------------------------ FrameLoader

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

    def load(self, sample_id: str) -> Sample:
        """The sample as the app's :class:`Sample` (module docstring).

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

    def notes(self, sample: Sample) -> str:
        """The sample's scene and its commands with their referred boxes (markdown, escaped)."""
        tables = self.nuscenes.tables
        token = sample.sample_id
        scene_token = tables.records["sample"][token]["scene_token"]
        scenes = list(tables.records["scene"])
        scene = tables.records["scene"][scene_token]
        in_scene = [
            s
            for s in self.nuscenes.samples
            if tables.records["sample"][s]["scene_token"] == scene_token
        ]
        lines = [
            f"*Scene* {scenes.index(scene_token) + 1} / {len(scenes)} "
            f"({md_text(str(scene.get('name', '')))}: {md_text(str(scene.get('description', '')))}) "
            f"· sample {in_scene.index(token) + 1} / {len(in_scene)} of the scene"
        ]
        commands = self.commands(token)
        if not commands:
            lines.append("*Commands:* none for this sample")
        else:
            lines.append(f"*Commands ({len(commands)}):*")
            for c in commands:
                x, y = float(c.box[0]), float(c.box[1])
                lines.append(
                    f"- {md_text(c.command.text)} → **{c.cls}** ({md_text(c.command.category)}) "
                    f"at {x:.1f} m ahead, {y:+.1f} m left · {c.split}"
                )
        return "  \n".join(lines[:2]) + ("\n" + "\n".join(lines[2:]) if len(lines) > 2 else "")


class NuScenesServed:
    """The root kind of a nuScenes root (:class:`app.served.ServedRoot`).

    Args:
        source: The frames.
        pairs: ``--pairs DIR``: where annotated commands go (``DIR/commands/``); None: nowhere
            (the tab suggests ``<root>-talk2car``).

    Raises:
        RootError: ``pairs`` would write into the served root or the ``--talk2car`` folder (one
            line, :func:`annotate.talk2car.check_pairs_folder`).
    """

    def __init__(self, source: NuScenesSource, pairs: Path | None = None) -> None:
        self.root = source
        self.labelled = LabelledFrames(source, classes=source.classes)  # type: ignore[arg-type]
        path = source.path.resolve() if source.path.name in ("", ".", "..") else source.path
        self.pairs_path = (
            Path(pairs) if pairs is not None else path.with_name(path.name + PAIRS_SUFFIX)
        )
        self.named = pairs is not None
        self.protected = (source.talk2car,) if source.talk2car is not None else ()
        """Folders the pairs never go into (the ``--talk2car`` folder; the root is checked too)."""
        if pairs is not None:
            try:
                check_pairs_folder(self.pairs_path, source.path, self.protected)
            except StoreError as exc:
                raise RootError(f"--pairs: {exc}") from None

    def unnamed_message(self) -> str:
        return (
            "pairs on a nuScenes root are saved as Talk2Car commands only where you say: restart "
            f"with --pairs DIR (e.g. --pairs {self.pairs_path}; commands go into "
            "DIR/commands/{split}_commands.json)"
        )

    def open_store(self) -> Talk2CarStore:
        return Talk2CarStore(
            self.pairs_path, self.root.nuscenes, classes=self.root.classes, protected=self.protected
        )

    def source_frame(self, sample: Sample) -> SourceFrame:
        return SourceFrame(
            f"{self.root.path.name}/{sample.sample_id}",
            sample,
            None,
            str(self.root.path.resolve()),
            sample.sample_id,
        )

    def draft_issues(self, draft: Draft, sample: Sample) -> tuple[Issue, ...]:
        """A command refers to exactly one labelled annotation
        (:func:`annotate.talk2car.referred_annotation`)."""
        found = self.root.nuscenes.annotation_boxes(sample.sample_id)
        return referred_annotation(draft, *found, self.root.classes)[1]

    def frame_notes(self, sample: Sample) -> str:
        return self.root.notes(sample)

    def drives(self, ids: Sequence[str]) -> Drives:
        """Every sample a drive of its own: nuScenes' key frames come at 2 Hz, not the 10 Hz
        the *Sequence* folder plays and carries boxes at."""
        return Drives(tuple(Drive((DriveFrame((i,), None),)) for i in range(len(ids))))
