"""Reading a Talk2Radar root: :class:`Talk2RadarRoot` and the :class:`Sample` it loads.

The layout (every path) is :mod:`scenes.talk2radar.layout`; the writer is :mod:`scenes.talk2radar.writer` and the sidecar
:mod:`scenes.frame.sample_meta` (both re-exported here, with the layout names readers use). Each sample is
one frame id with one prompt and the boxes it refers to (``label_2``). The radar ``.bin`` files are
in the radar frame as in VoD; :meth:`Talk2RadarRoot.load` brings them into the LiDAR frame with both
calibration files. ``training/image_2/<id>.jpg`` is the camera image where a root has one (VoD's,
or the synthetic camera's, hard-linked into both trees); :attr:`Sample.image` reads it on first
access, and the 2D boxes of ``label_2`` are clipped to its size (:attr:`Sample.image_size`).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from scenes.frame.kitti import labels_to_boxes, read_label_file
from scenes.frame.sample import Sample
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.calib import read_calib, sensor_to_lidar, transform_points
from scenes.geometry.classes import VOD, ClassSet
from scenes.talk2radar.layout import (
    CALIB,
    FOLDER_SUFFIX,
    IMAGE,
    IMAGE_SUFFIXES,
    LABEL,
    LIDAR_FOLDER,
    PROMPT,
    RADAR_FOLDERS,
    VELODYNE,
    format_id,
    meta_file,
    parse_id,
    parse_split_list,
    radar_folders_in,
    sample_dir,
    sample_file,
    split_dir,
    split_file,
)
from scenes.talk2radar.pointcloud import LIDAR_FEATURES, RADAR_FEATURES, read_points
from scenes.talk2radar.writer import (
    LABEL_DECIMALS,
    SampleText,
    SensorFiles,
    Talk2RadarWriter,
    sample_text,
)
from scenes.utils.errors import RootError
from scenes.utils.textfile import claim_root, read_json_file, read_prompt_file, read_text_file

__all__ = [  # with the writer and the layout names readers use, re-exported
    "ALL_FRAMES",
    "LABEL_DECIMALS",
    "LIDAR_FOLDER",
    "RADAR_FOLDERS",
    "SampleText",
    "SensorFiles",
    "Talk2RadarRoot",
    "Talk2RadarWriter",
    "format_id",
    "sample_text",
]

ALL_FRAMES = "all"
"""The split name :meth:`Talk2RadarRoot.splits` gives a root without an ImageSets folder."""


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
        sidecar: Whether to read Talk2PC's ``meta/`` sidecars. False: nothing under ``meta/`` is
            ever touched and :attr:`Sample.meta` is None, as on a real release (training and
            evaluation on labels alone).
        classes: The class set a ``label_2`` is read into (:attr:`Sample.boxes`,
            :meth:`load_referents`; default ``vod``): its label names are mapped by
            :meth:`scenes.geometry.classes.ClassSet.label_class`, the others are left out
            (:attr:`Sample.labels` keeps every line).
    """

    def __init__(
        self,
        path: str | Path,
        radar: str | None = "auto",
        sidecar: bool = True,
        classes: ClassSet = VOD,
    ) -> None:
        self.path = Path(path)
        self.classes = classes
        self.sidecar = sidecar
        self.lidar_dir = self.path / LIDAR_FOLDER
        if not self.lidar_dir.is_dir():
            raise RootError(f"{self.path}: not a Talk2Radar root (no {LIDAR_FOLDER}/ folder)")
        present = radar_folders_in(self.path)
        if radar == "auto":
            radar = present[0] if present else None
        elif radar is not None and radar not in present:
            raise RootError(
                f"{self.path}: radar tree {radar!r} not found (present: {present or 'none'})"
            )
        self.radar_folder = radar
        self.radar_dir = self.path / radar if radar else None
        self._has_prompts = self.has_prompts
        self._all_frames_noted = False
        claim_root(self.path)

    @property
    def has_prompts(self) -> bool:
        """Whether the LiDAR tree has a ``prompt/`` folder now (a Talk2Radar root; a
        View-of-Delft release has none). Samples are read as the root was when opened."""
        return sample_dir(self.lidar_dir, PROMPT).is_dir()

    def __repr__(self) -> str:
        return f"Talk2RadarRoot({str(self.path)!r}, radar={self.radar_folder!r})"

    def splits(self) -> list[str]:
        """Names of the ImageSets files present (e.g. ``['test', 'train', 'val']``);
        ``[ALL_FRAMES]`` for a root without an ImageSets folder (:meth:`ids`)."""
        if not split_dir(self.lidar_dir).is_dir():
            return [ALL_FRAMES]
        return sorted(p.stem for p in split_dir(self.lidar_dir).glob("*.txt"))

    def ids(self, split: str) -> list[str]:
        """The ids listed in ``lidar/ImageSets/<split>.txt`` (blank lines skipped).

        A root without an ``ImageSets`` folder (the View-of-Delft devkit's example set) serves
        every frame of ``lidar/training/velodyne/`` as any split, with a one-line notice
        (``UserWarning``, once per root object).

        Raises:
            RootError: the list is missing or unreadable, an entry is not a 5-digit ASCII frame
                id (:func:`scenes.talk2radar.layout.parse_split_list`), or an id is listed twice; the
                message names file and line.
        """
        if not split_dir(self.lidar_dir).is_dir():
            return self._all_frames(split)
        path = split_file(self.lidar_dir, split)
        if not _is_file(path):
            raise RootError(f"{path}: split {split!r} not found (present: {self.splits()})")
        return parse_split_list(read_text_file(path, "split list", RootError), path)

    def frame_ids(self) -> list[str]:
        """Every frame of ``lidar/training/velodyne/`` (sorted ids), whatever the ImageSets say.

        Raises:
            RootError: a point file not named by a frame id (names the file).
        """
        folder = sample_dir(self.lidar_dir, VELODYNE)
        ids = []
        for path in sorted(folder.glob(f"*{FOLDER_SUFFIX[VELODYNE]}")):
            try:
                ids.append(parse_id(path.stem))
            except RootError as exc:
                raise RootError(f"{path}: not named by a frame id ({exc})") from exc
        return ids

    def _all_frames(self, split: str) -> list[str]:
        """Every frame (:meth:`frame_ids`), for a root without ImageSets, with a notice."""
        folder = sample_dir(self.lidar_dir, VELODYNE)
        ids = self.frame_ids()
        if not self._all_frames_noted:
            self._all_frames_noted = True
            warnings.warn(
                f"{self.lidar_dir} has no ImageSets folder, so all {len(ids)} frames of "
                f"{folder} are served as split {split!r} (and as any other split).",
                UserWarning,
                stacklevel=3,
            )
        return ids

    def _file(self, tree: Path, folder: str, sample_id: str) -> Path:
        path = sample_file(tree, folder, sample_id)
        if not path.exists() and not path.is_symlink():
            raise RootError(f"{path}: missing {folder} file for sample {sample_id}")
        return path  # something is there: its reader says what is wrong with it, if anything

    def load_prompt(self, sample_id: str | int) -> str | None:
        """The prompt of a sample, or None where the root has no prompts: the file's one
        sentence as :func:`scenes.utils.textfile.read_prompt_file` reads it (a byte-order mark removed,
        NFKC, spaces collapsed: the text the app would run).

        Raises:
            RootError: the file is missing, unreadable, not UTF-8 text, holds a character or a
                line break the prompt rule refuses, is too long, or holds no sentence.
        """
        sid = format_id(sample_id)
        if not self._has_prompts:
            return None
        path = self._file(self.lidar_dir, PROMPT, sid)
        prompt = read_prompt_file(path, RootError)
        if not prompt:
            raise RootError(f"{path}: the prompt file of sample {sid} is empty")
        return prompt

    def load_meta(self, sample_id: str | int) -> SampleMeta | None:
        """The sidecar of a sample, or None where it has none.

        Raises:
            RootError: the sidecar is unreadable, not text (:mod:`scenes.utils.textfile`), not JSON or
                not a sidecar object.
        """
        if not self.sidecar:
            return None
        path = meta_file(self.path, format_id(sample_id))
        if not path.exists() and not path.is_symlink():
            return None
        data = read_json_file(path, "sidecar", RootError)
        return SampleMeta.from_json(data, source=str(path))

    def source_meta(self, sample_id: str | int) -> SampleMeta:
        """The sidecar of a sample of a root written by ``scenes.synth`` (what the exports read:
        it lists every object of the frame).

        Raises:
            RootError: the sample has no sidecar (names the file), or :meth:`load_meta`'s.
        """
        meta = self.load_meta(sample_id)
        if meta is None:
            raise RootError(
                f"{meta_file(self.path, format_id(sample_id))}: missing sidecar; the export needs "
                "a root written by scenes.synth (its sidecars list every object of the frame)"
            )
        return meta

    def frame_key(self, sample_id: str | int) -> tuple[object, ...]:
        """The identity of a sample's frame: ``(device, inode)`` of its LiDAR and radar point files
        and of both calibrations (and the radar tree read). This is the one definition of "the
        same frame" (training groups, prediction's scene cache, class prompts): samples of one
        synthetic world, or annotated from one source frame, share these files as hard links; a
        release's frames are each their own. It reads sensor files' metadata only, never a
        sidecar; a copied root without hard links merely loses the sharing."""
        sid = format_id(sample_id)
        files = [
            sample_file(self.lidar_dir, VELODYNE, sid),
            sample_file(self.lidar_dir, CALIB, sid),
        ]
        if self.radar_dir is not None:
            files += [
                sample_file(self.radar_dir, VELODYNE, sid),
                sample_file(self.radar_dir, CALIB, sid),
            ]
        key: list[object] = [self.radar_folder]
        for path in files:
            try:
                stat = path.stat()
            except OSError as exc:
                raise RootError(
                    f"{path}: cannot read the sensor file of sample {sid}: {exc}"
                ) from exc
            key.append((stat.st_dev, stat.st_ino))
        return tuple(key)

    def image_path(self, sample_id: str | int) -> Path | None:
        """The camera image of a sample (``training/image_2/<id>.jpg``, or ``.png``, in the LiDAR
        tree, else in the radar tree), or None where there is none."""
        sid = format_id(sample_id)
        trees = [self.lidar_dir] + ([self.radar_dir] if self.radar_dir is not None else [])
        for tree in trees:
            for suffix in IMAGE_SUFFIXES:
                path = sample_file(tree, IMAGE, sid, suffix)
                if path.exists() or path.is_symlink():
                    return path  # something is there: read_image says what is wrong with it
        return None

    def load_referents(self, sample_id: str | int) -> tuple[np.ndarray, tuple[str, ...]]:
        """The boxes ``(K, 7)`` (LiDAR frame) and class names of a sample's ``label_2`` of the
        root's class set (``classes``), without reading its point clouds."""
        sid = format_id(sample_id)
        calib = read_calib(self._file(self.lidar_dir, CALIB, sid))
        labels = read_label_file(self._file(self.lidar_dir, LABEL, sid))
        return labels_to_boxes(labels, calib, self.classes)

    def load_sensors(self, sample_id: str | int) -> Sample:
        """A sample's sensor files only, as an unlabelled recording has them: its LiDAR and
        radar points and calibrations and its camera image's path; no label, prompt or sidecar
        file is read (``boxes`` empty, ``prompt`` and ``meta`` None, ``labels`` empty), so a root
        without ``label_2/``, ``prompt/`` or ``meta/`` reads (``python -m model.adapt``)."""
        sid = format_id(sample_id)
        calib = read_calib(self._file(self.lidar_dir, CALIB, sid))
        lidar = read_points(self._file(self.lidar_dir, VELODYNE, sid), LIDAR_FEATURES)
        radar = np.zeros((0, RADAR_FEATURES), dtype=np.float32)
        radar_calib = None
        if self.radar_dir is not None:
            radar_calib = read_calib(self._file(self.radar_dir, CALIB, sid))
            radar_raw = read_points(self._file(self.radar_dir, VELODYNE, sid), RADAR_FEATURES)
            radar = transform_points(radar_raw, sensor_to_lidar(calib, radar_calib)).astype(
                np.float32
            )
        return Sample(
            sample_id=sid,
            lidar=lidar,
            radar=radar,
            boxes=np.zeros((0, 7)),
            classes=(),
            prompt=None,
            calib=calib,
            radar_calib=radar_calib,
            image_path=self.image_path(sid),
        )

    def load(self, sample_id: str | int) -> Sample:
        """Load one sample (:meth:`load_sensors` and its label, prompt and sidecar); every error
        names the offending file."""
        sid = format_id(sample_id)
        sensors = self.load_sensors(sid)
        labels = tuple(read_label_file(self._file(self.lidar_dir, LABEL, sid)))
        boxes, classes = labels_to_boxes(labels, sensors.calib, self.classes)
        return Sample(
            sample_id=sid,
            lidar=sensors.lidar,
            radar=sensors.radar,
            boxes=boxes,
            classes=classes,
            prompt=self.load_prompt(sid),
            calib=sensors.calib,
            radar_calib=sensors.radar_calib,
            labels=labels,
            meta=self.load_meta(sid),
            image_path=sensors.image_path,
        )
