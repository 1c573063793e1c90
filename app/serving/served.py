"""The kind of root the app serves, chosen once: :func:`serve_root` -> a :class:`ServedRoot`.

Three kinds of root are served: a Talk2Radar root (prompts and their referents), a View-of-Delft
release as it comes (every object labelled, no prompts), both read by
:class:`scenes.talk2radar.root.Talk2RadarRoot` (:class:`Talk2RadarServed`), and a nuScenes root
with its Talk2Car commands (:class:`app.serving.served_nuscenes.NuScenesServed`). What differs between
them lives in the one object :class:`Talk2PCApp <app.server.Talk2PCApp>` chooses at start, never
in branches elsewhere:

- ``root``: the frames (``ids(split)``, ``load(id) -> Sample``, ``splits()``, ``path``) that
  :class:`app.serving.navigation.FrameStore` reads;
- ``labelled``: the frames' labelled boxes ("Candidates: Labelled boxes", the Annotate tab's
  ready-made boxes);
- ``frame_notes(sample)``: lines under the frame summary (a nuScenes sample's scene and commands);
- where pairs go (``pairs_path``, ``named``: nothing is written where the person did not say) and
  the store that writes them (``open_store``: an :class:`annotate.AnnotationStore` of Talk2Radar
  pairs, or an :class:`annotate.talk2car.Talk2CarStore` of Talk2Car commands), the frame a new
  pair is made on (``source_frame``), what a pair must be beyond :func:`annotate.validate`
  (``draft_issues``: a Talk2Car command refers to exactly one labelled annotation), the split a
  pair must go into (``pair_split``: a Talk2Car command, its sample's);
- ``frame_commands(sample)``: the commands listed under the frame summary, a click on one runs
  it (:mod:`app.serving.frame_commands`; None on a Talk2Radar root);
- ``drives(ids)``: the drives the Annotate tab's *Sequence* folder plays.

The families' readers come from the dataset layer (:mod:`scenes.datasets.source`); the drives of
a split are the Talk2Radar family's (:mod:`scenes.talk2radar.drives`: found from View-of-Delft's
ego poses; a nuScenes root's scenes are given as the same :class:`Drives`), imported from its
room for that.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

from annotate import AnnotationStore, Draft, SourceFrame
from annotate.validation import Issue, ValidationConfig
from app.serving.frame_commands import FrameCommand
from app.serving.labelled import LabelledFrames
from app.text import md_text
from scenes.datasets.source import NuScenesSource, Talk2RadarRoot, open_source, root_family
from scenes.frame import FrameSource, RootError, Sample
from scenes.frame.kitti import outside_class_counts, outside_class_phrase
from scenes.geometry.classes import VOD, ClassSet
from scenes.talk2radar.drives import Drives, find_drives

__all__ = [
    "PAIRS_SUFFIX",
    "ServedRoot",
    "Talk2RadarServed",
    "default_pairs_root",
    "has_prompts",
    "serve_root",
]

PAIRS_SUFFIX = "-talk2radar"
"""Name suffix of the folder beside a root without prompts where its pairs are saved."""


class ServedRoot(Protocol):
    """What differs between the kinds of root served (module docstring)."""

    root: FrameSource
    labelled: LabelledFrames
    pairs_path: Path
    named: bool

    def unnamed_message(self) -> str:
        """Why pairs are not saved when the person named no folder (``named`` False)."""

    def open_store(self) -> Any:
        """The store pairs are saved into (at ``pairs_path``; opening writes nothing)."""

    def pairs_described(self) -> str:
        """What ``pairs_path`` holds, said after the folder in the Annotate tab's status when it
        is not the served root ("a Talk2Radar root beside the served one, ...")."""

    def source_frame(self, sample: Sample) -> SourceFrame:
        """The frame a new pair on ``sample`` (a frame of ``root``) is made on."""

    def draft_issues(self, draft: Draft, sample: Sample) -> tuple[Issue, ...]:
        """Errors that block saving ``draft`` on ``sample`` beyond :func:`annotate.validate`."""

    def pair_split(self, sample: Sample) -> str | None:
        """The split a new pair on ``sample`` must go into (None: the person chooses)."""

    def frame_commands(self, sample: Sample) -> tuple[FrameCommand, ...] | None:
        """The commands of ``sample`` the app lists and runs with a click (None: the root kind
        has no commands, :mod:`app.serving.frame_commands`)."""

    def frame_notes(self, sample: Sample) -> str:
        """Markdown lines shown under the frame summary ("" for none)."""

    def drives(self, ids: Sequence[str]) -> Drives:
        """The drives of a split list of ``root``."""


def has_prompts(root: Talk2RadarRoot) -> bool:
    """Whether ``root`` is a Talk2Radar root with prompts (``lidar/training/prompt/``); a
    View-of-Delft root as released has none."""
    return root.has_prompts


def default_pairs_root(root: Talk2RadarRoot) -> Path:
    """Where pairs annotated on ``root`` go without ``--pairs``: into ``root`` itself when it is
    a Talk2Radar root with prompts (the pairs join its splits); for a root without prompts (a
    release as it comes, whose own files are never touched) the sibling folder
    ``<root>-talk2radar``, only *suggested*: nothing is written beside a release unless the
    person names the pairs folder (:class:`app.annotate_tab.AnnotationHub`, ``named``)."""
    if has_prompts(root):
        return root.path
    path = root.path.resolve() if root.path.name in ("", ".", "..") else root.path
    return path.with_name(path.name + PAIRS_SUFFIX)


class Talk2RadarServed:
    """A Talk2Radar root or a View-of-Delft release (:class:`Talk2RadarRoot`).

    Args:
        root: The served root.
        pairs: ``--pairs`` (None: the root itself when it has prompts, else no saving).
        scene_labels: ``--scene-labels`` (:class:`app.serving.labelled.LabelledFrames`).
        classes: The served model's class set: labels are read into it, the labelled boxes and
            the pairs saved are of its classes.
    """

    def __init__(
        self,
        root: Talk2RadarRoot,
        pairs: Path | None = None,
        scene_labels: Path | None = None,
        classes: ClassSet = VOD,
    ) -> None:
        if root.classes != classes:  # the labels read into the served model's classes
            root = Talk2RadarRoot(root.path, root.radar_folder, root.sidecar, classes)
        self.root = root
        self.classes = classes
        self.labelled = LabelledFrames(root, scene_labels, classes)
        self.pairs_path = Path(pairs) if pairs is not None else default_pairs_root(root)
        self.named = pairs is not None or has_prompts(root)

    def unnamed_message(self) -> str:
        return (
            "the served root has no prompts (a release as it comes), and pairs are never "
            "written beside it unless you say where: restart with --pairs DIR "
            f"(e.g. --pairs {self.pairs_path})"
        )

    def pairs_described(self) -> str:
        return "a Talk2Radar root beside the served one, whose files are not touched"

    def open_store(self) -> AnnotationStore:
        return AnnotationStore(
            self.pairs_path,
            radar_folder=self.root.radar_folder,
            validation=ValidationConfig(classes=self.classes.names),
            classes=self.classes,
        )

    def source_frame(self, sample: Sample) -> SourceFrame:
        return SourceFrame.from_root(self.root, sample.sample_id, sample=sample)

    def draft_issues(self, draft: Draft, sample: Sample) -> tuple[Issue, ...]:
        return ()

    def pair_split(self, sample: Sample) -> str | None:
        return None

    def frame_commands(self, sample: Sample) -> tuple[FrameCommand, ...] | None:
        """None: a Talk2Radar prompt is the frame's prompt, not a list of commands."""
        return None

    def frame_notes(self, sample: Sample) -> str:
        """The line of a sample whose referents (its ``label_2`` on a root with prompts) fall
        outside the served model's class set: how many, of which classes, and that the model
        cannot answer them (``""`` when none do, and on a release without prompts, whose labels
        are every object and no referents)."""
        counts = outside_class_counts(sample.labels, self.classes)
        if not counts or not has_prompts(self.root):
            return ""
        phrase = outside_class_phrase(counts)
        return (
            f"**Note:** {md_text(phrase)}: the checkpoint's classes are "
            f"{md_text(', '.join(self.classes.names))}; it cannot answer them, and the GT above "
            "leaves them out"
        )

    def drives(self, ids: Sequence[str]) -> Drives:
        """:func:`scenes.talk2radar.drives.find_drives` (errors: ``RootError``, ``OSError``)."""
        return find_drives(self.root, ids)


def serve_root(
    root: Any,
    *,
    pairs: Path | None = None,
    scene_labels: Path | None = None,
    talk2car: Path | None = None,
    classes: ClassSet = VOD,
) -> ServedRoot:
    """The :class:`ServedRoot` of ``root``: a :class:`Talk2RadarRoot`, an
    :class:`scenes.nuscenes.source.NuScenesSource`, or a path to either (a folder holding a
    ``v1.0-*`` table folder is a nuScenes root, read with its ``talk2car`` commands).

    Raises:
        RootError: not a root; ``talk2car`` or a split problem on the wrong kind of root.
        scenes.nuscenes.tables.NuScenesError: a malformed nuScenes root or command file.
    """
    from app.serving.served_nuscenes import NuScenesServed

    if isinstance(root, str | Path):  # the family decided once (RootError: --talk2car misplaced)
        root = open_source(root, talk2car, classes)
    elif isinstance(root, Talk2RadarRoot):
        root_family(root.path, talk2car)
    if isinstance(root, NuScenesSource):
        if root.classes != classes:  # its boxes: the served model's classes
            root = NuScenesSource(root.path, root.talk2car, classes)
        if scene_labels is not None:
            raise RootError(
                f"--scene-labels is for a Talk2Radar root; {root.path} is a nuScenes root "
                "(its own annotations are its labelled boxes)"
            )
        return NuScenesServed(root, pairs)
    return Talk2RadarServed(root, pairs, scene_labels, classes)
