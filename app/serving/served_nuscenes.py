"""A nuScenes root with its Talk2Car commands, served: :class:`NuScenesServed` (the root kind,
:mod:`app.serving.served`) over the frames of :class:`scenes.nuscenes.source.NuScenesSource`.

Frames. Every sample of the root is a frame (the source's module docstring): its labelled
boxes are the annotations of the served class set (the labelled boxes of "Candidates: Labelled
boxes" and the Annotate tab's ready-made boxes, as a View-of-Delft release's), its prompt the
sample's first command (the Query tab's prompt box). Under the frame summary
(:func:`frame_notes`): the scene (its position among the scenes, its description) and
every command of the sample with its referred box, numbered as the *Commands* folder's buttons
that run them (:mod:`app.serving.frame_commands`; a sample without commands says so, and why).

Pairs. Annotated pairs are Talk2Car commands (:class:`annotate.talk2car.Talk2CarStore`) saved
only into the folder named with ``--pairs DIR`` (``DIR/commands/{split}_commands.json``, the split
of the sample annotated: :meth:`scenes.nuscenes.source.NuScenesSource.sample_split`, by the scene lists of the command
files; the Annotate tab's *Split* shows it and cannot be changed there); without
it nothing is written and the tab suggests ``<root>-talk2car``. A ``DIR`` whose ``commands/`` lies
inside the served root or is (or lies inside) the ``--talk2car`` folder is refused when the app
starts (:func:`annotate.talk2car.check_pairs_folder`): the release is never written.

Family specifics: this is the nuScenes family's served kind, so it imports what only that
family has (:mod:`scenes.nuscenes.source`: a sample's commands, the ``ALL`` split), and gives
its scenes as the drives of :mod:`scenes.talk2radar.drives` (the one drive type the Annotate
tab's *Sequence* folder plays).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from annotate import DEFAULT_SPLITS, Draft, SourceFrame, StoreError
from annotate.talk2car import Talk2CarStore, check_pairs_folder, referred_annotation
from annotate.validation import Issue
from app.serving.frame_commands import FrameCommand
from app.serving.labelled import LabelledFrames
from app.text import md_text
from scenes.datasets.source import NuScenesSource
from scenes.frame import RootError, Sample
from scenes.nuscenes.source import ALL, SampleCommand
from scenes.talk2radar.drives import Drive, DriveFrame, Drives

__all__ = ["PAIRS_SUFFIX", "NuScenesServed", "frame_notes"]

PAIRS_SUFFIX = "-talk2car"
"""Name suffix of the folder suggested for the commands annotated on a nuScenes root."""
SPLIT_ORDER = ("train", "val", "test")
COMMANDS_SUFFIX = "_commands.json"


def _none_why(source: NuScenesSource, token: str) -> str:
    """The summary's line for a sample without commands (markdown)."""
    if source.talk2car is None:
        return "none: the app was started without --talk2car (the command files' folder)"
    split = source.sample_split(token)
    commanded = sum(1 for s in source.ids(ALL) if source.commands(s))
    return (
        f"none for this sample (its scene is in split {md_text(split)})"
        if split is not None
        else "none for this sample"
    ) + f"; {commanded} sample(s) of the root have commands"


def frame_notes(source: NuScenesSource, sample: Sample) -> str:
    """The lines under a sample's frame summary: its scene and its commands with their referred
    boxes, numbered as the *Commands* folder's buttons (markdown, escaped)."""
    tables = source.nuscenes.tables
    token = sample.sample_id
    scene_token = tables.records["sample"][token]["scene_token"]
    scenes = list(tables.records["scene"])
    scene = tables.records["scene"][scene_token]
    in_scene = [
        s
        for s in source.nuscenes.samples
        if tables.records["sample"][s]["scene_token"] == scene_token
    ]
    lines = [
        f"*Scene* {scenes.index(scene_token) + 1} / {len(scenes)} "
        f"({md_text(str(scene.get('name', '')))}: {md_text(str(scene.get('description', '')))}) "
        f"· sample {in_scene.index(token) + 1} / {len(in_scene)} of the scene"
    ]
    commands = source.commands(token)
    if not commands:
        lines.append(f"*Commands:* {_none_why(source, token)}")
    else:
        lines.append(f"*Commands ({len(commands)}):*")
        for i, c in enumerate(commands):
            x, y = float(c.box[0]), float(c.box[1])
            lines.append(
                f"{i + 1}. {md_text(c.command.text)} → **{c.cls}** "
                f"({md_text(c.command.category)}) at {x:.1f} m ahead, {y:+.1f} m left · "
                f"{md_text(c.split)}"
            )
    return "  \n".join(lines[:2]) + ("\n" + "\n".join(lines[2:]) if len(lines) > 2 else "")


def _about(c: SampleCommand) -> str:
    """What a command refers to, plain text: ``"(vehicle.car) at 12.3 m ahead, +1.0 m left ·
    train"``."""
    x, y = float(c.box[0]), float(c.box[1])
    return f"({c.command.category}) at {x:.1f} m ahead, {y:+.1f} m left · {c.split}"


class NuScenesServed:
    """The root kind of a nuScenes root (:class:`app.serving.served.ServedRoot`).

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

    def pairs_described(self) -> str:
        return (
            "Talk2Car command files, commands/{split}_commands.json, beside the served root, "
            "whose files are not touched"
        )

    def unnamed_message(self) -> str:
        return (
            "pairs on a nuScenes root are saved as Talk2Car commands only where you say: restart "
            f"with --pairs DIR (e.g. --pairs {self.pairs_path}; commands go into "
            "DIR/commands/{split}_commands.json)"
        )

    def open_store(self) -> Talk2CarStore:
        """The store of the commands annotated here: each saved into its sample's split
        (:meth:`scenes.nuscenes.source.NuScenesSource.sample_split`)."""
        splits = tuple(dict.fromkeys((*DEFAULT_SPLITS, *self.root.splits()[1:])))
        return Talk2CarStore(
            self.pairs_path,
            self.root.nuscenes,
            splits=splits,
            classes=self.root.classes,
            protected=self.protected,
            split_of=self.root.sample_split,
        )

    def pair_split(self, sample: Sample) -> str | None:
        """The split of ``sample`` (a new command goes there; None: the person chooses)."""
        return self.root.sample_split(sample.sample_id)

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
        return frame_notes(self.root, sample)

    def frame_commands(self, sample: Sample) -> tuple[FrameCommand, ...]:
        """The sample's commands as the app lists and runs them (:mod:`app.serving.frame_commands`)."""
        return tuple(
            FrameCommand(c.command.text, c.box, c.cls, _about(c))
            for c in self.root.commands(sample.sample_id)
        )

    def drives(self, ids: Sequence[str]) -> Drives:
        """Every sample a drive of its own: nuScenes' key frames come at 2 Hz, not the 10 Hz
        the *Sequence* folder plays and carries boxes at."""
        return Drives(tuple(Drive((DriveFrame((i,), None),)) for i in range(len(ids))))
