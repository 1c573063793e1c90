"""A Talk2Radar root on disk: the reader (:class:`Talk2RadarRoot`) and the writer
(:class:`Talk2RadarWriter`).

Layout (spec §1.2)::

    <root>/lidar/ImageSets/{train,val,test}.txt
    <root>/lidar/training/{velodyne,calib,label_2,prompt}/<id>.{bin,txt}
    <root>/radar_5frames/...            (or radar/, radar_3frames/: one radar tree is read)
    <root>/meta/<id>.json               Talk2PC sidecar (prompt type tags, all actors), optional
    <root>/sources/<frame>/             Talk2PC: the shared sensor files of a synthetic frame

Each sample is one frame id with one prompt and the boxes it refers to (``label_2``). The radar
``.bin`` files are in the radar frame as in VoD; :meth:`Talk2RadarRoot.load` brings them into the
LiDAR frame with both calibration files. Ids are 5-digit, zero padded. ``training/image_2/<id>.jpg``
is the camera image where a root has one (VoD's, or the synthetic camera's, hard-linked into both
trees); :attr:`Sample.image` reads it on first access.
"""

from __future__ import annotations

import json
import os
import shutil
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from scenes.actors import Actor
from scenes.calib import IMAGE_SIZE, Calibration, read_calib, sensor_to_lidar, transform_points
from scenes.imagefile import (
    IMAGE_SUFFIXES,
    check_principal_point,
    read_image,
    warn_principal_point,
    write_jpeg,
)
from scenes.kitti import (
    ObjectLabel,
    atomic_write_text,
    boxes_to_labels,
    labels_to_boxes,
    read_label_file,
    write_label_file,
)
from scenes.pointcloud import LIDAR_FEATURES, RADAR_FEATURES, read_points, write_points
from scenes.textfile import read_text_file

RADAR_FOLDERS = ("radar_5frames", "radar_3frames", "radar")
LIDAR_FOLDER = "lidar"


class RootError(ValueError):
    """A Talk2Radar root is incomplete or malformed; the message names the file."""


def format_id(sample_id: str | int) -> str:
    """The 5-digit, zero-padded form of a frame id (``7`` -> ``"00007"``)."""
    try:
        return f"{int(sample_id):05d}"
    except ValueError as exc:
        raise RootError(f"invalid sample id {sample_id!r}: expected an integer") from exc


@dataclass(frozen=True)
class SampleMeta:
    """The Talk2PC sidecar of a sample (``meta/<id>.json``).

    Attributes:
        tags: Prompt type tags (``class``, ``depth``, ``velocity``, ``motion``, ``position``).
        actors: Every actor of the frame (not only the referred ones), LiDAR frame, with velocities.
        referent_ids: ``actor_id`` of the boxes in ``label_2``, in label order.
        weather: ``clear``, ``rain`` or ``fog``.
        ego_velocity: Ego speed along +x in m/s.
        world_id: Index of the synthetic world (samples of one world share sensor files).
        radar_scans: Number of accumulated radar scans (1, 3 or 5).
        extra: Free-form additions (e.g. annotator, source frame).
    """

    tags: frozenset[str] = frozenset()
    actors: tuple[Actor, ...] = ()
    referent_ids: tuple[int, ...] = ()
    weather: str = "clear"
    ego_velocity: float = 0.0
    world_id: int = -1
    radar_scans: int = 5
    extra: Mapping[str, object] = field(default_factory=dict)

    def to_json(self) -> dict:
        """A JSON-serialisable dict."""
        return {
            "tags": sorted(self.tags),
            "actors": [a.to_json() for a in self.actors],
            "referent_ids": [int(i) for i in self.referent_ids],
            "weather": self.weather,
            "ego_velocity": float(self.ego_velocity),
            "world_id": int(self.world_id),
            "radar_scans": int(self.radar_scans),
            "extra": dict(self.extra),
        }

    @staticmethod
    def from_json(data: dict, source: str = "<meta>") -> SampleMeta:
        """Inverse of :meth:`to_json`; errors name ``source``."""
        if not isinstance(data, dict):
            raise RootError(f"{source}: malformed sidecar: expected a JSON object")
        try:
            return SampleMeta(
                tags=frozenset(data.get("tags", ())),
                actors=tuple(Actor.from_json(a) for a in data.get("actors", ())),
                referent_ids=tuple(int(i) for i in data.get("referent_ids", ())),
                weather=str(data.get("weather", "clear")),
                ego_velocity=float(data.get("ego_velocity", 0.0)),
                world_id=int(data.get("world_id", -1)),
                radar_scans=int(data.get("radar_scans", 5)),
                extra=dict(data.get("extra", {})),
            )
        except (AttributeError, KeyError, TypeError, ValueError, IndexError, OverflowError) as exc:
            raise RootError(f"{source}: malformed sidecar: {exc}") from exc


@dataclass(frozen=True)
class Sample:
    """One grounding sample: a frame's sensors, one prompt and the boxes it refers to.

    Attributes:
        sample_id: 5-digit frame id.
        lidar: ``(N, 4)`` float32 ``x, y, z, intensity``, LiDAR frame.
        radar: ``(M, 7)`` float32 ``x, y, z, rcs, v_r, v_r_compensated, time``, LiDAR frame.
        boxes: ``(K, 7)`` float64 referred boxes of the metric classes, LiDAR frame.
        classes: ``K`` class names (Car, Pedestrian, Cyclist).
        prompt: The sentence, or None where the root has no prompt folder.
        calib: LiDAR calibration (LiDAR -> camera).
        radar_calib: Radar calibration (radar -> camera), or None without a radar tree.
        labels: Every ``label_2`` line, non-metric classes included.
        meta: The sidecar, where present.
        image_path: The camera image file (``image_2/<id>.jpg``), or None where there is none;
            :attr:`image` reads it.
    """

    sample_id: str
    lidar: np.ndarray = field(repr=False)
    radar: np.ndarray = field(repr=False)
    boxes: np.ndarray = field(repr=False)
    classes: tuple[str, ...]
    prompt: str | None
    calib: Calibration = field(repr=False)
    radar_calib: Calibration | None = field(repr=False, default=None)
    labels: tuple[ObjectLabel, ...] = field(repr=False, default=())
    meta: SampleMeta | None = field(repr=False, default=None)
    image_path: Path | None = field(repr=False, default=None)

    @cached_property
    def image(self) -> np.ndarray | None:
        """The camera image ``(H, W, 3)`` uint8 RGB (row 0 at the top; pixel coordinates as
        ``calib.P2`` projects), read on first access and kept; None without an image file.

        Warns (``UserWarning``, naming the file) when the image size puts P2's principal point
        far from the image centre (:func:`scenes.imagefile.check_principal_point`).

        Raises:
            scenes.imagefile.ImageError: the file is unreadable, corrupt or truncated.
        """
        if self.image_path is None:
            return None
        image = read_image(self.image_path)
        height, width = image.shape[:2]
        principal = (float(self.calib.P2[0, 2]), float(self.calib.P2[1, 2]))
        warn_principal_point((width, height), principal, str(self.image_path))
        return image


def _is_file(path: Path) -> bool:
    """``path.is_file()`` that says False for a path the OS refuses (a name too long)."""
    try:
        return path.is_file()
    except OSError:
        return False


class Talk2RadarRoot:
    """Reads a Talk2Radar root (the real layout or one written by :class:`Talk2RadarWriter`).

    Args:
        path: The root folder (containing ``lidar/`` and a radar tree).
        radar: Radar tree to read (``radar_5frames``, ``radar_3frames``, ``radar``), ``"auto"``
            for the first present in that order, or None to read no radar (empty ``(0, 7)``).
    """

    def __init__(self, path: str | Path, radar: str | None = "auto") -> None:
        self.path = Path(path)
        self.lidar_dir = self.path / LIDAR_FOLDER
        if not self.lidar_dir.is_dir():
            raise RootError(f"{self.path}: not a Talk2Radar root (no {LIDAR_FOLDER}/ folder)")
        present = [name for name in RADAR_FOLDERS if (self.path / name).is_dir()]
        if radar == "auto":
            radar = present[0] if present else None
        elif radar is not None and radar not in present:
            raise RootError(
                f"{self.path}: radar tree {radar!r} not found (present: {present or 'none'})"
            )
        self.radar_folder = radar
        self.radar_dir = self.path / radar if radar else None
        self._has_prompts = (self.lidar_dir / "training" / "prompt").is_dir()

    def __repr__(self) -> str:
        return f"Talk2RadarRoot({str(self.path)!r}, radar={self.radar_folder!r})"

    def splits(self) -> list[str]:
        """Names of the ImageSets files present (e.g. ``['test', 'train', 'val']``)."""
        return sorted(p.stem for p in (self.lidar_dir / "ImageSets").glob("*.txt"))

    def ids(self, split: str) -> list[str]:
        """The 5-digit ids listed in ``lidar/ImageSets/<split>.txt`` (blank lines skipped).

        Raises:
            RootError: the list is missing or unreadable, a line is not an integer, or an id is
                listed twice (``2`` and ``00002`` are the same id); the message names file and line.
        """
        path = self.lidar_dir / "ImageSets" / f"{split}.txt"
        if not _is_file(path):
            raise RootError(f"{path}: split {split!r} not found (present: {self.splits()})")
        out: list[str] = []
        first: dict[str, int] = {}
        text = read_text_file(path, "split list", RootError)
        for lineno, line in enumerate(text.splitlines(), start=1):
            if line.strip():
                try:
                    sid = format_id(line.strip())
                except RootError as exc:
                    raise RootError(f"{path}:{lineno}: {exc}") from exc
                if sid in first:
                    raise RootError(
                        f"{path}:{lineno}: sample {sid} is listed twice (first on line "
                        f"{first[sid]}); each id may appear once per split"
                    )
                first[sid] = lineno
                out.append(sid)
        return out

    def _file(self, tree: Path, folder: str, sample_id: str, ext: str) -> Path:
        path = tree / "training" / folder / f"{sample_id}.{ext}"
        if not path.exists() and not path.is_symlink():
            raise RootError(f"{path}: missing {folder} file for sample {sample_id}")
        return path  # something is there: its reader says what is wrong with it, if anything

    def load_prompt(self, sample_id: str | int) -> str | None:
        """The prompt of a sample (whole file, stripped), or None where the root has no prompts.

        Raises:
            RootError: the file is missing, unreadable, not UTF-8 text, or holds no sentence.
        """
        sid = format_id(sample_id)
        if not self._has_prompts:
            return None
        path = self._file(self.lidar_dir, "prompt", sid, "txt")
        prompt = read_text_file(path, "prompt file", RootError).strip()
        if not prompt:
            raise RootError(f"{path}: the prompt file of sample {sid} is empty")
        return prompt

    def load_meta(self, sample_id: str | int) -> SampleMeta | None:
        """The sidecar of a sample, or None where it has none.

        Raises:
            RootError: the sidecar is unreadable, not UTF-8, not JSON or not a sidecar object.
        """
        path = self.path / "meta" / f"{format_id(sample_id)}.json"
        if not path.exists() and not path.is_symlink():
            return None
        text = read_text_file(path, "sidecar", RootError)
        try:
            data = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as exc:
            raise RootError(f"{path}: invalid JSON: {exc}") from exc
        return SampleMeta.from_json(data, source=str(path))

    def image_path(self, sample_id: str | int) -> Path | None:
        """The camera image of a sample (``training/image_2/<id>.jpg``, or ``.png``, in the LiDAR
        tree, else in the radar tree), or None where there is none."""
        sid = format_id(sample_id)
        trees = [self.lidar_dir] + ([self.radar_dir] if self.radar_dir is not None else [])
        for tree in trees:
            for suffix in IMAGE_SUFFIXES:
                path = tree / "training" / "image_2" / f"{sid}{suffix}"
                if path.exists() or path.is_symlink():
                    return path  # something is there: read_image says what is wrong with it
        return None

    def load(self, sample_id: str | int) -> Sample:
        """Load one sample; every error names the offending file."""
        sid = format_id(sample_id)
        calib = read_calib(self._file(self.lidar_dir, "calib", sid, "txt"))
        lidar = read_points(self._file(self.lidar_dir, "velodyne", sid, "bin"), LIDAR_FEATURES)
        radar = np.zeros((0, RADAR_FEATURES), dtype=np.float32)
        radar_calib = None
        if self.radar_dir is not None:
            radar_calib = read_calib(self._file(self.radar_dir, "calib", sid, "txt"))
            radar_raw = read_points(
                self._file(self.radar_dir, "velodyne", sid, "bin"), RADAR_FEATURES
            )
            radar = transform_points(radar_raw, sensor_to_lidar(calib, radar_calib)).astype(
                np.float32
            )
        labels = tuple(read_label_file(self._file(self.lidar_dir, "label_2", sid, "txt")))
        boxes, classes = labels_to_boxes(labels, calib)
        return Sample(
            sample_id=sid,
            lidar=lidar,
            radar=radar,
            boxes=boxes,
            classes=classes,
            prompt=self.load_prompt(sid),
            calib=calib,
            radar_calib=radar_calib,
            labels=labels,
            meta=self.load_meta(sid),
            image_path=self.image_path(sid),
        )


@dataclass(frozen=True)
class SensorFiles:
    """The sensor files of one source frame, shared (hard-linked) by the samples made from it.

    Attributes:
        folder: ``<root>/sources/<frame_key>``.
        lidar_bin, radar_bin, lidar_calib, radar_calib: Paths of the four files.
        image: The camera image (``image.jpg``), or None where the frame has none.
        image_size: ``(width, height)`` of that image (the 2D boxes of ``label_2`` are clipped
            to it), or None for VoD's 1936 x 1216.
    """

    folder: Path
    lidar_bin: Path
    radar_bin: Path
    lidar_calib: Path
    radar_calib: Path
    image: Path | None = None
    image_size: tuple[int, int] | None = None


def _link_or_copy(src: Path, dst: Path) -> None:
    """Hard-link ``src`` to ``dst`` (replacing it atomically); copy where links are impossible."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f".{dst.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.unlink(missing_ok=True)
    try:
        os.link(src, tmp)
    except OSError:
        shutil.copyfile(src, tmp)
    os.replace(tmp, dst)


class Talk2RadarWriter:
    """Writes samples in the Talk2Radar layout that :class:`Talk2RadarRoot` and the official VoD
    evaluation read.

    Every file is written atomically (temporary file, fsync, rename). ``label_2`` and ``prompt`` are
    written identically into the LiDAR and the radar tree, as in Talk2Radar.
    """

    def __init__(self, root: str | Path, radar_folder: str = "radar_5frames") -> None:
        if radar_folder not in RADAR_FOLDERS:
            raise ValueError(f"radar_folder must be one of {RADAR_FOLDERS}, got {radar_folder!r}")
        self.root = Path(root)
        self.radar_folder = radar_folder
        self.trees = (self.root / LIDAR_FOLDER, self.root / radar_folder)

    def write_sensors(
        self,
        frame_key: str,
        lidar: np.ndarray,
        radar: np.ndarray,
        lidar_calib: Calibration,
        radar_calib: Calibration,
        image: np.ndarray | None = None,
        jpeg_quality: int = 90,
    ) -> SensorFiles:
        """Write one frame's sensors under ``sources/<frame_key>/``.

        Args:
            lidar: ``(N, 4)`` LiDAR frame.
            radar: ``(M, 7)`` in the LiDAR frame; stored in the radar frame as VoD does.
            image: ``(H, W, 3)`` uint8 camera image whose projection is ``lidar_calib.P2``
                (written as ``image.jpg``), or None.
            jpeg_quality: JPEG quality of the image.
        """
        folder = self.root / "sources" / frame_key
        files = SensorFiles(
            folder=folder,
            lidar_bin=folder / "lidar.bin",
            radar_bin=folder / "radar.bin",
            lidar_calib=folder / "lidar_calib.txt",
            radar_calib=folder / "radar_calib.txt",
        )
        if image is not None:
            image = np.asarray(image)
            if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
                raise ValueError(
                    f"{frame_key}: the image must be (H, W, 3) uint8, got {image.shape} {image.dtype}"
                )
            size = (int(image.shape[1]), int(image.shape[0]))
            problem = check_principal_point(
                size, (float(lidar_calib.P2[0, 2]), float(lidar_calib.P2[1, 2])), frame_key
            )
            if problem is not None:
                raise ValueError(problem)
            files = replace(files, image=folder / "image.jpg", image_size=size)
            write_jpeg(files.image, image, jpeg_quality)
        lidar_to_radar = np.linalg.inv(sensor_to_lidar(lidar_calib, radar_calib))
        write_points(files.lidar_bin, np.asarray(lidar, dtype=np.float32).reshape(-1, 4))
        radar_arr = np.asarray(radar, dtype=np.float64).reshape(-1, 7)
        write_points(files.radar_bin, transform_points(radar_arr, lidar_to_radar))
        atomic_write_text(files.lidar_calib, lidar_calib.to_text())
        atomic_write_text(files.radar_calib, radar_calib.to_text())
        return files

    def write_sample(
        self,
        sample_id: str | int,
        files: SensorFiles,
        boxes: np.ndarray,
        classes: Sequence[str],
        prompt: str,
        meta: SampleMeta | None = None,
        calib: Calibration | None = None,
    ) -> str:
        """Write one sample (sensor links, camera image link, labels, prompt, sidecar); returns its
        5-digit id. The 2D boxes of ``label_2`` are clipped to ``files.image_size`` (VoD's
        1936 x 1216 where None).

        The label file is written last among the tree files so that a sample whose label exists is
        complete; the id becomes visible to readers only through :meth:`write_image_sets`.
        """
        sid = format_id(sample_id)
        if not prompt or not prompt.strip():
            raise ValueError(f"sample {sid}: the prompt is empty")
        calib = calib if calib is not None else read_calib(files.lidar_calib)
        image_size = files.image_size if files.image_size is not None else IMAGE_SIZE
        labels = boxes_to_labels(boxes, list(classes), calib, image_size=image_size)
        lidar_tree, radar_tree = self.trees
        _link_or_copy(files.lidar_bin, lidar_tree / "training" / "velodyne" / f"{sid}.bin")
        _link_or_copy(files.lidar_calib, lidar_tree / "training" / "calib" / f"{sid}.txt")
        _link_or_copy(files.radar_bin, radar_tree / "training" / "velodyne" / f"{sid}.bin")
        _link_or_copy(files.radar_calib, radar_tree / "training" / "calib" / f"{sid}.txt")
        if files.image is not None:
            for tree in self.trees:
                _link_or_copy(files.image, tree / "training" / "image_2" / f"{sid}.jpg")
        if meta is not None:
            atomic_write_text(
                self.root / "meta" / f"{sid}.json", json.dumps(meta.to_json(), indent=1)
            )
        for tree in self.trees:
            atomic_write_text(tree / "training" / "prompt" / f"{sid}.txt", prompt.strip() + "\n")
        for tree in self.trees:
            write_label_file(tree / "training" / "label_2" / f"{sid}.txt", labels, decimals=6)
        return sid

    def write_image_sets(self, splits: Mapping[str, Sequence[str | int]]) -> None:
        """Write ``ImageSets/<split>.txt`` in both trees (atomically, replacing old lists)."""
        for split, ids in splits.items():
            text = "".join(format_id(i) + "\n" for i in ids)
            for tree in self.trees:
                atomic_write_text(tree / "ImageSets" / f"{split}.txt", text)
