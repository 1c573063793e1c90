"""The layout of a Talk2Radar root (spec §1.2): where every file of a sample lives, in one place.

::

    <root>/lidar/ImageSets/<split>.txt            split lists (readers use the LiDAR tree's)
    <root>/lidar/training/velodyne/<id>.bin       LiDAR points
    <root>/lidar/training/calib/<id>.txt          LiDAR calibration
    <root>/lidar/training/label_2/<id>.txt        the referred objects
    <root>/lidar/training/prompt/<id>.txt         the prompt
    <root>/lidar/training/image_2/<id>.jpg        camera image (or .png), optional
    <root>/lidar/training/pose/<id>.json          the ego pose, optional (View-of-Delft's three
                                                  JSON lines, :mod:`scenes.talk2radar.poses`)
    <root>/radar_5frames/...                      the same folders, radar points and calibration
                                                  (or radar_3frames/, radar/: one radar tree)
    <root>/meta/<id>.json                         Talk2PC sidecar, optional
    <root>/annotations/manifest.jsonl             Talk2PC: the annotation store's log of every
                                                  save, edit, deletion and review (annotate/)
    <root>/sources/<frame>/lidar.bin, radar.bin, lidar_calib.txt, radar_calib.txt, image.jpg
                                                  Talk2PC: a frame's sensor files, hard-linked
                                                  into the samples made from it

Ids follow one rule (:func:`is_frame_id`): exactly :data:`ID_WIDTH` (5) ASCII digits, as
Talk2Radar and View-of-Delft write them (``00042``). Split lists and file names must spell them so
(:func:`parse_id`, :func:`parse_split_list`: ``42``, ``0_0010``, ``+4``, ``-6``, other scripts'
digits, whitespace and 6-digit ids are refused, naming the file and line); code that holds a number
formats it with :func:`format_id`. The reader (:class:`scenes.talk2radar.root.Talk2RadarRoot`),
the writer (:class:`scenes.talk2radar.writer.Talk2RadarWriter`, through which the synthetic
generator writes) and the annotation store take every path from here. Nothing here touches the disk but :func:`radar_folders_in`.
"""

from __future__ import annotations

import operator
from pathlib import Path

from scenes.utils.errors import RootError

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


ID_WIDTH = 5
"""Digits of a frame id (Talk2Radar and View-of-Delft)."""
_ID_EXAMPLE = "42".zfill(ID_WIDTH)


def is_frame_id(text: object) -> bool:
    """Whether ``text`` is a frame id as files write it: exactly :data:`ID_WIDTH` ASCII digits."""
    return isinstance(text, str) and len(text) == ID_WIDTH and text.isascii() and text.isdigit()


def parse_id(text: str) -> str:
    """``text`` (a split-list entry, a file stem) checked by :func:`is_frame_id`.

    Raises:
        RootError: anything else (the caller adds the file and line).
    """
    if not is_frame_id(text):
        raise RootError(
            f"invalid sample id {text!r}: expected {ID_WIDTH} ASCII digits, e.g. {_ID_EXAMPLE}"
        )
    return text


def format_id(sample_id: str | int) -> str:
    """The :data:`ID_WIDTH`-digit form of a frame id held by code: a number in
    ``[0, 10**ID_WIDTH)`` (``7`` -> ``"00007"``) or a string of at most :data:`ID_WIDTH` ASCII
    digits (``"7"`` -> ``"00007"``). Signs, underscores, whitespace, other scripts' digits and
    wider ids are refused (:class:`RootError`)."""
    if isinstance(sample_id, str):
        if not (0 < len(sample_id) <= ID_WIDTH and sample_id.isascii() and sample_id.isdigit()):
            raise RootError(
                f"invalid sample id {sample_id!r}: expected up to {ID_WIDTH} ASCII digits, e.g. "
                f"{_ID_EXAMPLE}"
            )
        return sample_id.zfill(ID_WIDTH)
    try:
        if isinstance(sample_id, bool):
            raise TypeError
        number = operator.index(sample_id)
    except TypeError:
        raise RootError(f"invalid sample id {sample_id!r}: expected an integer") from None
    if not 0 <= number < 10**ID_WIDTH:
        raise RootError(f"invalid sample id {number}: expected 0 to {10**ID_WIDTH - 1}")
    return f"{number:0{ID_WIDTH}d}"


def parse_split_list(text: str, path: Path) -> list[str]:
    """The ids of an ImageSets list's ``text`` (read from ``path``), in order; blank lines are
    skipped.

    Raises:
        RootError: ``path:line:`` an entry that is not a frame id (:func:`parse_id`), or an id
            listed twice.
    """
    out: list[str] = []
    first: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            sid = parse_id(line)
        except RootError as exc:
            raise RootError(f"{path}:{lineno}: {exc}") from exc
        if sid in first:
            raise RootError(
                f"{path}:{lineno}: sample {sid} is listed twice (first on line {first[sid]}); "
                "each id may appear once per split"
            )
        first[sid] = lineno
        out.append(sid)
    return out


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
    "ID_WIDTH",
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
    "is_frame_id",
    "manifest_file",
    "meta_dir",
    "meta_file",
    "parse_id",
    "parse_split_list",
    "radar_folders_in",
    "sample_dir",
    "sample_file",
    "source_dir",
    "split_dir",
    "split_file",
]
