"""The files of a Talk2Radar root as the annotation store sees them: split lists and sample files.

A sample's files live in ``<tree>/training/<folder>/<id>.<ext>`` of the LiDAR tree and the radar
tree (:data:`SAMPLE_FOLDERS`), its sidecar in ``meta/<id>.json``; it is visible once its id is in
``lidar/ImageSets/<split>.txt``. :class:`RootFiles` names those paths in one place and does the
store's small file operations on them: split-list edits (each list replaced atomically, its
folder fsynced), removal of a sample's files and of the temporaries a killed write leaves
(``.<name>.tmp*``, the temporary names of :func:`scenes.kitti.atomic_write_text` and of
:func:`replace_all`), and the highest id in use.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path

from annotate.errors import StoreError
from scenes.kitti import ObjectLabel, atomic_write_text, read_label_file
from scenes.root import RADAR_FOLDERS
from scenes.textfile import read_text_file

SAMPLE_FOLDERS: tuple[tuple[str, str], ...] = (
    ("velodyne", "bin"),
    ("calib", "txt"),
    ("label_2", "txt"),
    ("prompt", "txt"),
)
"""``(folder, extension)`` of the files of a sample in each tree's ``training/``."""


class RootFiles:
    """Paths and file operations of one root (see the module docstring).

    Args:
        path: The root.
        lidar_dir: Its LiDAR tree (``path / "lidar"``; the commit point's lists).
    """

    def __init__(self, path: Path, lidar_dir: Path) -> None:
        self.path = path
        self.lidar_dir = lidar_dir
        self.meta_dir = path / "meta"

    # ---------------------------------------------------------------- paths

    def radar_trees(self) -> list[Path]:
        """The radar trees the root has (normally one)."""
        return [self.path / n for n in RADAR_FOLDERS if (self.path / n).is_dir()]

    def all_trees(self) -> list[Path]:
        """The LiDAR tree, then the radar trees."""
        return [self.lidar_dir, *self.radar_trees()]

    @staticmethod
    def sample_file(tree: Path, folder: str, sid: str, ext: str = "txt") -> Path:
        """``<tree>/training/<folder>/<sid>.<ext>``."""
        return tree / "training" / folder / f"{sid}.{ext}"

    def meta_file(self, sid: str) -> Path:
        """The sidecar ``meta/<sid>.json``."""
        return self.meta_dir / f"{sid}.json"

    @staticmethod
    def split_path(tree: Path, split: str) -> Path:
        """``<tree>/ImageSets/<split>.txt``."""
        return tree / "ImageSets" / f"{split}.txt"

    # ---------------------------------------------------------------- reading

    @staticmethod
    def read_text(path: Path) -> str | None:
        """A text file's content (None when it does not exist; errors: :class:`StoreError`)."""
        if not path.is_file():
            return None
        return read_text_file(path, "file", StoreError)

    def read_prompt(self, sid: str) -> str | None:
        """The sample's prompt (stripped) from the LiDAR tree, None when it has none."""
        text = self.read_text(self.sample_file(self.lidar_dir, "prompt", sid))
        return None if text is None else text.strip()

    def read_label_text(self, sid: str) -> str | None:
        """The sample's ``label_2`` text from the LiDAR tree, None when it has none."""
        return self.read_text(self.sample_file(self.lidar_dir, "label_2", sid))

    def read_labels(self, sid: str) -> list[ObjectLabel]:
        """The sample's labels from the LiDAR tree (none when it has no label file)."""
        path = self.sample_file(self.lidar_dir, "label_2", sid)
        if not path.is_file():
            return []
        return read_label_file(path)

    def splits_of(self, sid: str) -> tuple[str, ...]:
        """The LiDAR-tree splits whose list holds the sample (empty: not visible)."""
        out = []
        for path in sorted((self.lidar_dir / "ImageSets").glob("*.txt")):
            if any(int_or_none(line) == int(sid) for line in read_list(path)):
                out.append(path.stem)
        return tuple(out)

    def in_split(self, tree: Path, sid: str, split: str) -> bool:
        """Whether ``tree``'s list of ``split`` holds the sample."""
        path = self.split_path(tree, split)
        if not path.is_file():
            return False
        return any(int_or_none(line) == int(sid) for line in read_list(path))

    def max_id(self) -> int:
        """The highest id in any split list, sample folder or sidecar of the root (-1: none)."""
        best = -1
        for tree in self.all_trees():
            for path in (tree / "ImageSets").glob("*.txt"):
                for line in read_list(path):
                    value = int_or_none(line)
                    if value is not None:
                        best = max(best, value)
            for folder, _ in SAMPLE_FOLDERS:
                best = max(best, max_stem(tree / "training" / folder))
        return max(best, max_stem(self.meta_dir))

    # ---------------------------------------------------------------- writing

    def add_to_split(self, sid: str, split: str) -> None:
        """Append the id to the split's list: radar tree(s) first, the LiDAR tree (commit) last."""
        for tree in (*self.radar_trees(), self.lidar_dir):
            path = self.split_path(tree, split)
            text = read_text_file(path, "split list", StoreError) if path.is_file() else ""
            if any(int_or_none(line) == int(sid) for line in text.splitlines()):
                continue
            if text and not text.endswith("\n"):
                text += "\n"
            atomic_write_text(path, text + sid + "\n")
            fsync_dir(path.parent)

    def remove_from_split(self, tree: Path, sid: str, split: str) -> None:
        """Remove the id from ``tree``'s list of ``split`` (no-op when it is not there)."""
        path = self.split_path(tree, split)
        if not path.is_file():
            return
        lines = read_text_file(path, "split list", StoreError).splitlines(keepends=True)
        kept = [line for line in lines if int_or_none(line) != int(sid)]
        if len(kept) != len(lines):
            atomic_write_text(path, "".join(kept))
            fsync_dir(path.parent)

    def sync_sample_dirs(self, trees: Sequence[Path]) -> None:
        """Fsync the sample folders of ``trees`` and the sidecar folder."""
        for tree in trees:
            for folder, _ in SAMPLE_FOLDERS:
                fsync_dir(tree / "training" / folder)
        fsync_dir(self.meta_dir)

    def remove_sample_files(self, sid: str) -> None:
        """Delete every file of a sample (and its temporaries) in every tree, and its sidecar."""
        for tree in self.all_trees():
            for folder, ext in SAMPLE_FOLDERS:
                self.sample_file(tree, folder, sid, ext).unlink(missing_ok=True)
        self.meta_file(sid).unlink(missing_ok=True)
        self.remove_temporaries(sid)

    def remove_temporaries(self, sid: str) -> None:
        """Delete the temporaries a killed write of the sample's files left behind."""
        folders = [self.meta_dir]
        folders += [t / "training" / f for t in self.all_trees() for f, _ in SAMPLE_FOLDERS]
        for folder in folders:
            for tmp in folder.glob(f".{sid}.*.tmp*"):
                tmp.unlink(missing_ok=True)

    def sweep_list_temporaries(self, folders: Sequence[Path] = ()) -> None:
        """Delete stale temporaries in the split-list folders (and ``folders``); best effort."""
        with contextlib.suppress(OSError):
            for folder in (*folders, *(t / "ImageSets" for t in self.all_trees())):
                for tmp in folder.glob(".*.tmp*"):
                    tmp.unlink(missing_ok=True)


def int_or_none(text: str) -> int | None:
    """The id on a line of a split list (None for anything but digits)."""
    text = text.strip()
    return int(text) if text.isdigit() else None


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
                if stem.isdigit():
                    best = max(best, int(stem))
    return best


def fsync_dir(path: Path) -> None:
    """Fsync a folder (its entries: a rename or a new file in it is durable); best effort."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def holds(path: Path, text: str) -> bool:
    """Whether the file ``path`` exists and holds exactly ``text`` (False when unreadable)."""
    try:
        return path.is_file() and path.read_bytes() == text.encode("utf-8")
    except OSError:
        return False


def replace_all(targets: Sequence[tuple[Path, str]], op: str) -> None:
    """Write every ``(path, text)`` to a temporary file (fsynced) first, then rename each over its
    target: a full disk stops the first phase, before any target changed."""
    staged: list[tuple[Path, Path]] = []
    try:
        for path, text in targets:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.tmp-{op[:12]}")
            staged.append((tmp, path))
            with open(tmp, "w", encoding="utf-8") as handle:
                handle.write(text)
                handle.flush()
                os.fsync(handle.fileno())
        for tmp, path in staged:
            os.replace(tmp, path)
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)


__all__ = [
    "SAMPLE_FOLDERS",
    "RootFiles",
    "fsync_dir",
    "holds",
    "int_or_none",
    "max_stem",
    "read_list",
    "replace_all",
]
