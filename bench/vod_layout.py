"""A synthetic root in the View-of-Delft release layout: ``python -m bench.vod_layout --src S --out D``.

``scenes.synth`` writes a Talk2Radar root: one sample per prompt, label_2 holding only the
prompt's referents. A View-of-Delft root, as researchers download it, has one entry per frame and
label_2 holding *every* annotated object of the camera's field of view, metric classes and others
(``bicycle``, ``bicycle_rack``, ``moped_scooter``, ``rider``, ...), and no prompts. This converter
writes that layout from a synthetic root, so the class-prompt check (:mod:`model.class_prompts`)
can be run on real-format frames without the real data. The data stay synthetic.

Output (``D``)::

    D/lidar/ImageSets/<split>.txt                  the source's splits, one id per frame
    D/lidar/training/{velodyne,calib,image_2}/<id>  hard links to the source's files
    D/lidar/training/label_2/<id>.txt               every object of the frame in the camera view
    D/<radar tree>/training/{velodyne,calib,label_2}/<id>, D/<radar tree>/ImageSets/ (same tree
                                                    name as the source: radar_5frames by default)

One frame per synthetic world (the samples of a world share their sensor files); its id is the
world's first sample id. label_2 holds the world's actors that a sensor sees (the sidecar's actors
minus ``extra["unsensed_actor_ids"]``: nothing an annotator could label is left out, nothing
invisible is added) and its street clutter with its VoD class, each kept where its box is in the
camera image (:func:`model.class_prompts.in_camera_view`), as VoD annotates the camera's view. No
``prompt/`` and no ``meta/`` folder are written. Errors are one line, ``error: ...``, exit 2.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from model.class_prompts import in_camera_view
from scenes.calib import IMAGE_SIZE, Calibration, read_calib, sensor_to_lidar, transform_points
from scenes.kitti import ObjectLabel, atomic_write_text, boxes_to_labels, write_label_file
from scenes.pointcloud import write_points
from scenes.root import LIDAR_FOLDER, RootError, Talk2RadarRoot, format_id


@dataclass(frozen=True)
class ConversionReport:
    """What :func:`convert` wrote.

    Attributes:
        splits: Split name -> frame ids.
        objects: Label class -> count over the frames (metric and non-metric classes).
        radar_folder: The radar tree's name.
    """

    splits: dict[str, list[str]]
    objects: dict[str, int]
    radar_folder: str

    @property
    def frames(self) -> int:
        return sum(len(v) for v in self.splits.values())


def _link(src: Path, dst: Path) -> None:
    """Hard-link ``src`` to ``dst`` (a copy where links are impossible)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def frame_labels(
    boxes: np.ndarray,
    classes: Sequence[str],
    calib: Calibration,
    image_size: tuple[int, int] = IMAGE_SIZE,
) -> list[ObjectLabel]:
    """VoD-style ground-truth labels (``truncated = occluded = 0``, score 1) of the LiDAR-frame
    boxes ``(K, 7)`` in the camera image; the others are left out."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 7)
    seen = in_camera_view(b, calib, image_size)
    kept = [c for c, s in zip(classes, seen, strict=True) if s]
    return boxes_to_labels(b[seen], kept, calib, image_size=image_size)


def write_vod_frame(
    out: str | Path,
    sample_id: str | int,
    lidar: np.ndarray,
    radar: np.ndarray,
    lidar_calib: Calibration,
    radar_calib: Calibration,
    boxes: np.ndarray,
    classes: Sequence[str],
    radar_folder: str = "radar",
    camera_view_only: bool = True,
) -> list[ObjectLabel]:
    """Write one frame in the VoD layout from arrays (the tests' fixtures).

    Args:
        lidar: ``(N, 4)`` LiDAR frame.
        radar: ``(M, 7)`` in the LiDAR frame; written in the radar frame, as VoD.
        boxes: ``(K, 7)`` LiDAR frame, every object of the frame; ``classes`` their label names.
        camera_view_only: Label only the objects in the camera image (VoD's 1936 x 1216), as VoD;
            False labels every box (to test that the scorer leaves the others out).

    Returns:
        The labels written.
    """
    out = Path(out)
    sid = format_id(sample_id)
    lidar_tree, radar_tree = out / LIDAR_FOLDER / "training", out / radar_folder / "training"
    write_points(lidar_tree / "velodyne" / f"{sid}.bin", np.asarray(lidar, np.float32))
    to_radar = np.linalg.inv(sensor_to_lidar(lidar_calib, radar_calib))
    radar_arr = transform_points(np.asarray(radar, np.float64).reshape(-1, 7), to_radar)
    write_points(radar_tree / "velodyne" / f"{sid}.bin", radar_arr)
    atomic_write_text(lidar_tree / "calib" / f"{sid}.txt", lidar_calib.to_text())
    atomic_write_text(radar_tree / "calib" / f"{sid}.txt", radar_calib.to_text())
    if camera_view_only:
        labels = frame_labels(boxes, classes, lidar_calib)
    else:
        labels = boxes_to_labels(np.asarray(boxes, np.float64).reshape(-1, 7), classes, lidar_calib)
    for tree in (lidar_tree, radar_tree):
        write_label_file(tree / "label_2" / f"{sid}.txt", labels, decimals=6)
    return labels


def write_image_sets(
    out: str | Path, radar_folder: str, splits: Mapping[str, Sequence[str | int]]
) -> None:
    """``ImageSets/<split>.txt`` in the LiDAR and the radar tree."""
    for split, ids in splits.items():
        text = "".join(format_id(i) + "\n" for i in ids)
        for tree in (LIDAR_FOLDER, radar_folder):
            atomic_write_text(Path(out) / tree / "ImageSets" / f"{split}.txt", text)


def _image_size(path: Path | None) -> tuple[int, int]:
    if path is None:
        return IMAGE_SIZE
    try:
        with Image.open(path) as img:
            return (int(img.size[0]), int(img.size[1]))
    except (OSError, ValueError) as exc:
        raise RootError(f"{path}: unreadable camera image ({exc})") from exc


def convert(src: str | Path, out: str | Path) -> ConversionReport:
    """Write the VoD-layout version of the synthetic root ``src`` into ``out`` (see the module doc).

    Raises:
        RootError: ``src`` is not a synthetic root with sidecars, or ``out`` is not empty.
    """
    src, out = Path(src), Path(out)
    root = Talk2RadarRoot(src, radar="auto")
    if root.radar_dir is None or root.radar_folder is None:
        raise RootError(f"{src}: no radar tree")
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise RootError(f"{out}: exists and is not an empty folder; choose another --out")
    radar_folder = root.radar_folder
    splits: dict[str, list[str]] = {}
    objects: Counter[str] = Counter()
    done: set[int] = set()
    for split in root.splits():
        splits[split] = []
        for sid in root.ids(split):
            meta = root.load_meta(sid)
            if meta is None:
                raise RootError(
                    f"{src / 'meta' / (sid + '.json')}: missing sidecar; the converter needs the "
                    "roots scenes.synth writes (every actor is in the sidecar)"
                )
            if meta.world_id in done:
                continue
            done.add(meta.world_id)
            unsensed = {int(i) for i in meta.extra.get("unsensed_actor_ids", [])}
            actors = [a for a in meta.actors if a.actor_id not in unsensed]
            clutter = list(meta.extra.get("clutter", []))
            boxes = np.array(
                [a.box for a in actors] + [np.asarray(c["box"], np.float64) for c in clutter]
            ).reshape(-1, 7)
            classes = [a.cls for a in actors] + [str(c["cls"]) for c in clutter]
            calib_path = root.lidar_dir / "training" / "calib" / f"{sid}.txt"
            calib = read_calib(calib_path)
            image = root.image_path(sid)
            labels = frame_labels(boxes, classes, calib, _image_size(image))
            lidar_tree = out / LIDAR_FOLDER / "training"
            radar_tree = out / radar_folder / "training"
            for tree_src, tree_dst in ((root.lidar_dir, lidar_tree), (root.radar_dir, radar_tree)):
                for folder, ext in (("velodyne", "bin"), ("calib", "txt")):
                    name = f"{sid}.{ext}"
                    _link(tree_src / "training" / folder / name, tree_dst / folder / name)
                write_label_file(tree_dst / "label_2" / f"{sid}.txt", labels, decimals=6)
            if image is not None:
                _link(image, lidar_tree / "image_2" / image.name)
            objects.update(lab.name for lab in labels)
            splits[split].append(sid)
    if not any(splits.values()):
        raise RootError(f"{src}: no samples in its ImageSets lists")
    write_image_sets(out, radar_folder, splits)
    return ConversionReport(splits, dict(sorted(objects.items())), radar_folder)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m bench.vod_layout",
        description="Write a synthetic root (scenes.synth) in the View-of-Delft release layout: "
        "one entry per frame, label_2 with every object in the camera view, no prompts.",
    )
    p.add_argument("--src", required=True, type=Path, help="a root written by scenes.synth")
    p.add_argument("--out", required=True, type=Path, help="new (or empty) output folder")
    args = p.parse_args(argv)
    try:
        report = convert(args.src, args.out)
    except ValueError as exc:
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: {exc.filename or args.out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    counts = ", ".join(f"{k} {len(v)}" for k, v in report.splits.items())
    objects = ", ".join(f"{k} {v}" for k, v in report.objects.items())
    print(
        f"{args.out}: {report.frames} frames ({counts}), radar tree {report.radar_folder}; "
        f"labels: {objects}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
