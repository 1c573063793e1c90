"""What training and evaluation need of a family's own files beyond a :class:`FrameSource`.

A :class:`~scenes.frame.FrameSource` offers what every family has (splits, ids, samples, frame
keys). A few commands also name or read a family's own files: where a split is listed (for a
message), which frames of a Talk2Radar / View-of-Delft root have labels, the label files of a
training split (its own ``label_2`` or a VoD root's full scene labels), how many samples a
Talk2Car command file holds and refers to, and nuScenes' category -> class mapping. Each is one
named function here, or the family's own name re-exported where nothing needs adding to it
(``SceneLabels``, ``command_counts``, the tree names), so that ``model/`` reaches a family's
format through the dataset layer (as it
opens roots through :func:`scenes.datasets.source.open_source`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from scenes.frame import FrameSource
from scenes.geometry.classes import ClassSet
from scenes.nuscenes.classes import model_class
from scenes.nuscenes.source import NuScenesSource
from scenes.nuscenes.talk2car import command_counts, commands_file
from scenes.talk2radar.layout import (
    ID_WIDTH,
    LABEL,
    LIDAR_FOLDER,
    RADAR_FOLDERS,
    VELODYNE,
    is_frame_id,
    sample_dir,
    sample_file,
    split_file,
)
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels
from scenes.utils.errors import RootError

__all__ = [
    "LIDAR_FOLDER",
    "RADAR_FOLDERS",
    "SceneLabels",
    "SplitLabels",
    "command_counts",
    "labelled_frame_ids",
    "nuscenes_class_mapping",
    "point_folder",
    "split_label_files",
    "split_list_file",
]


def split_list_file(source: FrameSource, split: str) -> Path | None:
    """The file that lists ``split``'s samples: a Talk2Radar root's ``lidar/ImageSets/<split>.txt``,
    a nuScenes root's ``{split}_commands.json`` (None: a nuScenes root without commands, or a
    family without split files)."""
    if isinstance(source, Talk2RadarRoot):
        return split_file(source.lidar_dir, split)
    if isinstance(source, NuScenesSource) and source.talk2car is not None:
        return commands_file(source.talk2car, split)
    return None


def point_folder(root: Talk2RadarRoot) -> Path:
    """The folder of a Talk2Radar root's LiDAR point files (``lidar/training/velodyne``)."""
    return sample_dir(root.lidar_dir, VELODYNE)


def labelled_frame_ids(root: Talk2RadarRoot, split: str) -> list[str]:
    """The frames of a Talk2Radar / View-of-Delft root with labels: ``all`` = every ``label_2``
    file of the LiDAR tree (VoD withholds its test labels), else the ids of
    ``ImageSets/<split>.txt``.

    Raises:
        RootError: no label folder, no label file, or a split list problem (names the file).
    """
    if split != "all":
        return root.ids(split)
    label_dir = sample_dir(root.lidar_dir, LABEL)
    if not label_dir.is_dir():
        raise RootError(f"{label_dir}: no label folder (a root with full labels has one)")
    ids = sorted(path.stem for path in label_dir.glob("*.txt"))
    for sid in ids:
        if not is_frame_id(sid):
            raise RootError(
                f"{label_dir / (sid + '.txt')}: not named by a {ID_WIDTH}-digit frame id "
                "(ASCII digits)"
            )
    if not ids:
        raise RootError(f"{label_dir}: no label files")
    return ids


@dataclass(frozen=True)
class SplitLabels:
    """The label files of a Talk2Radar root's split (:func:`split_label_files`).

    Attributes:
        ids: The split's sample ids, in order.
        files: The label file of each id (its ``label_2``, or the scene labels' of its frame).
        folder: The label folder they lie in (for a message).
        split_list: The split's list file (for a message).
    """

    ids: tuple[str, ...]
    files: tuple[Path, ...]
    folder: Path
    split_list: Path


def split_label_files(
    path: str | Path, split: str, scene_labels_root: str | Path | None = None
) -> SplitLabels:
    """The label files of ``split`` of the Talk2Radar root at ``path``: its own ``label_2``, or
    with ``scene_labels_root`` (a View-of-Delft root) that root's full labels of each frame.

    Raises:
        RootError: not a root, a split list the reader refuses (names the file), or scene labels
            that are not a View-of-Delft root with labels.
    """
    root = Talk2RadarRoot(path, radar=None)
    ids = tuple(root.ids(split))
    if scene_labels_root is None or not ids:  # no frame: the scene labels are not opened
        files = tuple(sample_file(root.lidar_dir, LABEL, sid) for sid in ids)
        folder = sample_dir(root.lidar_dir, LABEL)
    else:
        scene = SceneLabels(scene_labels_root)
        files = tuple(scene.label_path(sid) for sid in ids)
        folder = sample_dir(scene.tree, LABEL)
    return SplitLabels(ids, files, folder, split_file(root.lidar_dir, split))


def nuscenes_class_mapping(classes: ClassSet) -> Callable[[str, Sequence[str]], str | None]:
    """nuScenes' category (and attributes) -> the class of ``classes`` (None: outside the set):
    :func:`scenes.nuscenes.classes.model_class`, the one mapping."""
    return partial(model_class, classes=classes)
