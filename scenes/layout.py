"""The layout of a Talk2Radar root (spec §1.2): where every file of a sample lives, in one place.

::

    <root>/lidar/ImageSets/<split>.txt            split lists (readers use the LiDAR tree's)
    <root>/lidar/training/velodyne/<id>.bin       LiDAR points
    <root>/lidar/training/calib/<id>.txt          LiDAR calibration
    <root>/lidar/training/label_2/<id>.txt        the referred objects
    <root>/lidar/training/prompt/<id>.txt         the prompt
    <root>/lidar/training/image_2/<id>.jpg        camera image (or .png), optional
    <root>/lidar/training/pose/<id>.json          the ego pose, optional (View-of-Delft's three
                                                  JSON lines, :mod:`scenes.poses`)
    <root>/radar_5frames/...                      the same folders, radar points and calibration
                                                  (or radar_3frames/, radar/: one radar tree)
    <root>/meta/<id>.json                         Talk2PC sidecar, optional
    <root>/annotations/manifest.jsonl             Talk2PC: the annotation store's log of every
                                                  save, edit, deletion and review (annotate/)
    <root>/sources/<frame>/lidar.bin, radar.bin, lidar_calib.txt, radar_calib.txt, image.jpg
                                                  Talk2PC: a frame's sensor files, hard-linked
                                                  into the samples made from it

Ids are 5-digit, zero padded (:func:`format_id`). The reader (:class:`scenes.root.Talk2RadarRoot`),
the writer (:class:`scenes.writer.Talk2RadarWriter`), the synthetic generator and the annotation
store take every path from here. Nothing here touches the disk but :func:`radar_folders_in`.
"""

from __future__ import annotations

from pathlib import Path

LIDAR_FOLDER = "lidar"
"""The LiDAR tree."""
RADAR_FOLDERS = ("radar_5frames", "radar_3frames", "radar")
"""The radar trees a root may have, in the order readers look for them."""
RADAR_FOLDER_OF_SCANS = {1: "radar", 3: "radar_3frames", 5: "radar_5frames"}
"""Radar tree per number of accumulated radar scans (as VoD)."""
SCANS_OF_RADAR_FOLDER = {folder: scans for scans, folder in RADAR_FOLDER_OF_SCANS.items()}
"""Number of accumulated radar scans of each radar tree."""

SAMPLES = "training"
IMAGE_SETS = "ImageSets"
TRAIN_VAL = "train_val"
"""The View-of-Delft release's split list of its ``train`` and ``val`` frames together."""
META = "meta"
ANNOTATIONS = "annotations"
MANIFEST = "manifest.jsonl"
SOURCES = "sources"

VELODYNE = "velodyne"
CALIB = "calib"
LABEL = "label_2"
PROMPT = "prompt"
IMAGE = "image_2"
POSE = "pose"

FOLDER_SUFFIX = {
    VELODYNE: ".bin",
    CALIB: ".txt",
    LABEL: ".txt",
    PROMPT: ".txt",
    IMAGE: ".jpg",
    POSE: ".json",
}
"""The file suffix of each sample folder (images may also be ``.png``: :data:`IMAGE_SUFFIXES`)."""
IMAGE_SUFFIXES = (".jpg", ".png")
"""Image suffixes a root may use, in the order readers look for them (VoD uses ``.jpg``)."""
SAMPLE_FILES: tuple[tuple[str, str], ...] = (
    (VELODYNE, ".bin"),
    (CALIB, ".txt"),
    (LABEL, ".txt"),
    (PROMPT, ".txt"),
    *((IMAGE, suffix) for suffix in IMAGE_SUFFIXES),
    (POSE, ".json"),
)
"""``(folder, suffix)`` of every file a sample may have in a tree."""
SAMPLE_FOLDERS = tuple(dict.fromkeys(folder for folder, _ in SAMPLE_FILES))
"""The sample folders of a tree (each once)."""

SOURCE_LIDAR = "lidar.bin"
SOURCE_RADAR = "radar.bin"
SOURCE_LIDAR_CALIB = "lidar_calib.txt"
SOURCE_RADAR_CALIB = "radar_calib.txt"
SOURCE_IMAGE = "image.jpg"
SOURCE_SENSORS = (SOURCE_LIDAR, SOURCE_RADAR, SOURCE_LIDAR_CALIB, SOURCE_RADAR_CALIB)
"""The four sensor files every ``sources/<frame>/`` folder has (the image is optional)."""


class RootError(ValueError):
    """A Talk2Radar root is incomplete or malformed; the message names the file."""


def format_id(sample_id: str | int) -> str:
    """The 5-digit, zero-padded form of a frame id (``7`` -> ``"00007"``)."""
    try:
        return f"{int(sample_id):05d}"
    except ValueError as exc:
        raise RootError(f"invalid sample id {sample_id!r}: expected an integer") from exc


def sample_dir(tree: Path, folder: str) -> Path:
    """``<tree>/training/<folder>``."""
    return tree / SAMPLES / folder


def sample_file(tree: Path, folder: str, sample_id: str, suffix: str | None = None) -> Path:
    """``<tree>/training/<folder>/<sample_id><suffix>`` (the folder's suffix by default)."""
    return (
        sample_dir(tree, folder)
        / f"{sample_id}{FOLDER_SUFFIX[folder] if suffix is None else suffix}"
    )


def split_dir(tree: Path) -> Path:
    """``<tree>/ImageSets``."""
    return tree / IMAGE_SETS


def split_file(tree: Path, split: str) -> Path:
    """``<tree>/ImageSets/<split>.txt``."""
    return split_dir(tree) / f"{split}.txt"


def meta_dir(root: Path) -> Path:
    """``<root>/meta``."""
    return root / META


def meta_file(root: Path, sample_id: str) -> Path:
    """The sidecar ``<root>/meta/<sample_id>.json``."""
    return meta_dir(root) / f"{sample_id}.json"


def manifest_file(root: Path) -> Path:
    """The annotation manifest ``<root>/annotations/manifest.jsonl``."""
    return root / ANNOTATIONS / MANIFEST


def source_dir(root: Path, frame_key: str) -> Path:
    """``<root>/sources/<frame_key>``: one frame's shared sensor files."""
    return root / SOURCES / frame_key


def radar_folders_in(root: Path) -> list[str]:
    """The radar trees present in ``root``, in :data:`RADAR_FOLDERS` order."""
    return [name for name in RADAR_FOLDERS if (root / name).is_dir()]


__all__ = [
    "ANNOTATIONS",
    "CALIB",
    "FOLDER_SUFFIX",
    "IMAGE",
    "IMAGE_SETS",
    "IMAGE_SUFFIXES",
    "LABEL",
    "LIDAR_FOLDER",
    "MANIFEST",
    "META",
    "POSE",
    "PROMPT",
    "RADAR_FOLDERS",
    "RADAR_FOLDER_OF_SCANS",
    "SAMPLES",
    "SAMPLE_FILES",
    "SAMPLE_FOLDERS",
    "SCANS_OF_RADAR_FOLDER",
    "SOURCES",
    "SOURCE_IMAGE",
    "SOURCE_LIDAR",
    "SOURCE_LIDAR_CALIB",
    "SOURCE_RADAR",
    "SOURCE_RADAR_CALIB",
    "SOURCE_SENSORS",
    "TRAIN_VAL",
    "VELODYNE",
    "RootError",
    "format_id",
    "manifest_file",
    "meta_dir",
    "meta_file",
    "radar_folders_in",
    "sample_dir",
    "sample_file",
    "source_dir",
    "split_dir",
    "split_file",
]
