"""The files of a Talk2Radar root as the annotation store sees them: split lists and sample files.

A sample's files are those :mod:`scenes.talk2radar.layout` names (:data:`scenes.talk2radar.layout.SAMPLE_FILES` in the
LiDAR tree and the radar tree, the sidecar ``meta/<id>.json``); it is visible once its id is in
``lidar/ImageSets/<split>.txt``. :class:`RootFiles` does the store's small file operations on
them: split-list edits (each list replaced atomically, :func:`scenes.utils.durable.atomic_write_text`),
removal of a sample's files and of the temporaries a killed write leaves (the one naming rule of
:func:`scenes.utils.durable.temp_path`, matched by :func:`scenes.utils.durable.remove_temporaries`), and the
highest id in use.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path

from annotate.errors import StoreError
from scenes.frame.kitti import ObjectLabel, read_label_file
from scenes.talk2radar.layout import (
    LABEL,
    PROMPT,
    SAMPLE_FILES,
    SAMPLE_FOLDERS,
    is_frame_id,
    meta_dir,
    meta_file,
    radar_folders_in,
    sample_dir,
    sample_file,
    split_dir,
    split_file,
)
from scenes.utils.durable import atomic_write_text, remove_temporaries
from scenes.utils.textfile import read_text_file


class RootFiles:
    """Paths and file operations of one root (see the module docstring).

    Args:
        path: The root.
        lidar_dir: Its LiDAR tree (``path / "lidar"``; the commit point's lists).
    """

    def __init__(self, path: Path, lidar_dir: Path) -> None:
        self.path = path
        self.lidar_dir = lidar_dir
        self.meta_dir = meta_dir(path)

    # ---------------------------------------------------------------- paths

    def radar_trees(self) -> list[Path]:
        """The radar trees the root has (normally one)."""
        return [self.path / n for n in radar_folders_in(self.path)]

    def all_trees(self) -> list[Path]:
        """The LiDAR tree, then the radar trees."""
        return [self.lidar_dir, *self.radar_trees()]

    # ---------------------------------------------------------------- reading

    @staticmethod
    def read_text(path: Path) -> str | None:
        """A text file's content (None when it does not exist; errors: :class:`StoreError`)."""
        if not path.is_file():
            return None
        return read_text_file(path, "file", StoreError)

    def read_prompt(self, sid: str) -> str | None:
        """The sample's prompt (stripped) from the LiDAR tree, None when it has none."""
        text = self.read_text(sample_file(self.lidar_dir, PROMPT, sid))
        return None if text is None else text.strip()

    def read_label_text(self, sid: str) -> str | None:
        """The sample's ``label_2`` text from the LiDAR tree, None when it has none."""
        return self.read_text(sample_file(self.lidar_dir, LABEL, sid))

    def read_labels(self, sid: str) -> list[ObjectLabel]:
        """The sample's labels from the LiDAR tree (none when it has no label file)."""
        path = sample_file(self.lidar_dir, LABEL, sid)
        if not path.is_file():
            return []
        return read_label_file(path)

    def splits_of(self, sid: str) -> tuple[str, ...]:
        """The LiDAR-tree splits whose list holds the sample (empty: not visible)."""
        out = []
        for path in sorted(split_dir(self.lidar_dir).glob("*.txt")):
            if any(int_or_none(line) == int(sid) for line in read_list(path)):
                out.append(path.stem)
        return tuple(out)

    def in_split(self, tree: Path, sid: str, split: str) -> bool:
        """Whether ``tree``'s list of ``split`` holds the sample."""
        path = split_file(tree, split)
        if not path.is_file():
            return False
        return any(int_or_none(line) == int(sid) for line in read_list(path))

    def max_id(self) -> int:
        """The highest id in any split list, sample folder or sidecar of the root (-1: none)."""
        best = -1
        for tree in self.all_trees():
            for path in split_dir(tree).glob("*.txt"):
                for line in read_list(path):
                    value = int_or_none(line)
                    if value is not None:
                        best = max(best, value)
            for folder in SAMPLE_FOLDERS:
                best = max(best, max_stem(sample_dir(tree, folder)))
        return max(best, max_stem(self.meta_dir))

    # ---------------------------------------------------------------- writing

    def add_to_split(self, sid: str, split: str) -> None:
        """Append the id to the split's list: radar tree(s) first, the LiDAR tree (commit) last."""
        for tree in (*self.radar_trees(), self.lidar_dir):
            path = split_file(tree, split)
            text = read_text_file(path, "split list", StoreError) if path.is_file() else ""
            if any(int_or_none(line) == int(sid) for line in text.splitlines()):
                continue
            if text and not text.endswith("\n"):
                text += "\n"
            atomic_write_text(path, text + sid + "\n")

    def remove_from_split(self, tree: Path, sid: str, split: str) -> None:
        """Remove the id from ``tree``'s list of ``split`` (no-op when it is not there)."""
        path = split_file(tree, split)
        if not path.is_file():
            return
        lines = read_text_file(path, "split list", StoreError).splitlines(keepends=True)
        kept = [line for line in lines if int_or_none(line) != int(sid)]
        if len(kept) != len(lines):
            atomic_write_text(path, "".join(kept))

    def remove_sample_files(self, sid: str) -> None:
        """Delete every file of a sample (and its temporaries) in every tree, and its sidecar."""
        for tree in self.all_trees():
            for folder, suffix in SAMPLE_FILES:
                sample_file(tree, folder, sid, suffix).unlink(missing_ok=True)
        meta_file(self.path, sid).unlink(missing_ok=True)
        self.remove_temporaries(sid)

    def remove_temporaries(self, sid: str) -> None:
        """Delete the temporaries a killed write of the sample's files left behind."""
        folders = [self.meta_dir]
        folders += [sample_dir(t, f) for t in self.all_trees() for f in SAMPLE_FOLDERS]
        for folder in folders:
            remove_temporaries(folder, f"{sid}.")

    def sweep_list_temporaries(self, folders: Sequence[Path] = ()) -> None:
        """Delete stale temporaries in the split-list folders (and ``folders``); best effort."""
        with contextlib.suppress(OSError):
            for folder in (*folders, *(split_dir(t) for t in self.all_trees())):
                remove_temporaries(folder)


def int_or_none(text: str) -> int | None:
    """The id on a line of a split list (None for anything but a frame id:
    :func:`scenes.talk2radar.layout.is_frame_id`, the one id rule)."""
    text = text.strip()
    return int(text) if is_frame_id(text) else None


def read_list(path: Path) -> list[str]:
    """The lines of an ImageSets list (errors: :class:`StoreError` naming the file)."""
    return read_text_file(path, "split list", StoreError).splitlines()


def max_stem(folder: Path) -> int:
    """The highest numeric file stem in ``folder`` (-1: none, or no folder)."""
    best = -1
    if folder.is_dir():
        with os.scandir(folder) as it:
            for entry in it:
                stem = entry.name.split(".", 1)[0]
                if is_frame_id(stem):
                    best = max(best, int(stem))
    return best


def holds(path: Path, text: str) -> bool:
    """Whether the file ``path`` exists and holds exactly ``text`` (False when unreadable)."""
    try:
        return path.is_file() and path.read_bytes() == text.encode("utf-8")
    except OSError:
        return False


__all__ = [
    "RootFiles",
    "holds",
    "int_or_none",
    "max_stem",
    "read_list",
]
