"""Which splits of a Talk2Radar or View-of-Delft root can be served, and why not.

A split can be served when its list names at least one frame and every frame has the files the
reader needs (LiDAR points and calib, ``label_2``, the radar tree's points and calib):
:func:`split_problem` says why not, naming the first missing file; :func:`no_split_lists` says
what an ``ImageSets`` folder without lists lacks; :func:`first_servable_split` picks a split when
none is given. The app's launcher (``launch.py``) asks these, the reader's knowledge of its
layout kept here with the reader.
"""

from __future__ import annotations

from collections.abc import Sequence

from scenes.talk2radar.layout import (
    CALIB,
    LABEL,
    VELODYNE,
    format_id,
    sample_dir,
    sample_file,
    split_dir,
    split_file,
)
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.errors import RootError

__all__ = [
    "SPLIT_PREFERENCE",
    "first_servable_split",
    "missing_files",
    "no_split_lists",
    "split_problem",
]

SPLIT_PREFERENCE = ("test", "val", "train")
"""Splits tried, in order, when no split is given (then the others, sorted)."""


def missing_files(root: Talk2RadarRoot, split: str) -> list[str]:
    """One message per frame of ``split`` that lacks a file the reader needs (LiDAR points and
    calib, label_2, the radar tree's points and calib), naming the first missing file."""
    trees = [(root.lidar_dir, (VELODYNE, CALIB, LABEL))]
    if root.radar_dir is not None:
        trees.append((root.radar_dir, (VELODYNE, CALIB)))
    out = []
    for sid in root.ids(split):
        sid = format_id(sid)
        for tree, folders in trees:
            gone = [sample_file(tree, folder, sid) for folder in folders]
            gone = [f for f in gone if not (f.exists() or f.is_symlink())]
            if gone:
                out.append(f"{gone[0]}: missing {gone[0].parent.name} file for sample {sid}")
                break
    return out


def split_problem(root: Talk2RadarRoot, split: str) -> str | None:
    """Why ``split`` cannot be served (None: it can): a split list the reader refuses, one that
    lists no frame, or frames missing files (the first named, with their count)."""
    try:
        ids = root.ids(split)
        missing = missing_files(root, split)
    except RootError as exc:
        return str(exc)
    if not ids:
        return f"{root.path}: split {split!r} lists no frame (splits: {root.splits()})"
    if missing:
        if split_dir(root.lidar_dir).is_dir():
            where = f"listed in {split_file(root.lidar_dir, split)}"
        else:
            where = f"of {sample_dir(root.lidar_dir, VELODYNE)}"
        return f"{missing[0]} ({len(missing)} of the {len(ids)} frames {where} miss files)"
    return None


def no_split_lists(root: Talk2RadarRoot) -> str | None:
    """Why the root has no split to serve: an ``ImageSets`` folder without lists (None: it has
    a list, or no ``ImageSets`` folder and so every frame as split ``all``)."""
    if root.splits():
        return None
    return (
        f"{split_dir(root.lidar_dir)}: no split list (<split>.txt with one frame id a "
        "line); write one, e.g. all.txt listing the ids of lidar/training/velodyne, and pass "
        "--split all, or remove the empty folder to serve every frame"
    )


def first_servable_split(
    root: Talk2RadarRoot, preference: Sequence[str] = SPLIT_PREFERENCE
) -> tuple[str | None, list[str]]:
    """The first of ``preference`` (then the root's other lists, sorted) that can be served
    (None: none can), and the problems of those tried before it (``'split': problem`` each)."""
    present = root.splits()
    candidates = [s for s in preference if s in present]
    candidates += [s for s in present if s not in preference]
    problems = []
    for candidate in candidates:
        problem = split_problem(root, candidate)
        if problem is None:
            return candidate, problems
        problems.append(f"{candidate!r}: {problem}")
    return None, problems
