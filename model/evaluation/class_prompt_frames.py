"""Which frames of a root the class prompts are asked on, and their camera's image size
(:mod:`model.evaluation.class_prompts`' inputs)."""

from __future__ import annotations

from collections.abc import Sequence

from PIL import Image

from scenes.frame import RootError, Sample
from scenes.geometry.calib import IMAGE_SIZE
from scenes.talk2radar.layout import ID_WIDTH, LABEL, is_frame_id, sample_dir
from scenes.talk2radar.root import Talk2RadarRoot


def image_size_of(sample: Sample) -> tuple[int, int]:
    """``(width, height)`` of the sample's camera image (header only), VoD's without an image.

    Raises:
        RootError: the image file cannot be opened (names the file).
    """
    if sample.image_path is None:
        return IMAGE_SIZE
    try:
        with Image.open(sample.image_path) as img:
            return (int(img.size[0]), int(img.size[1]))
    except (OSError, ValueError, Image.DecompressionBombError) as exc:
        raise RootError(f"{sample.image_path}: unreadable camera image ({exc})") from exc


def root_frame_ids(root: Talk2RadarRoot, split: str) -> list[str]:
    """The frames to score: ``all`` = every ``label_2`` file of the LiDAR tree (frames with
    labels; VoD withholds its test labels), else the ids of ``ImageSets/<split>.txt``.

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


def distinct_scenes(root: Talk2RadarRoot, ids: Sequence[str]) -> list[str]:
    """The first id of each distinct set of sensor files (:func:`model.evaluation.predict.scene_key`):
    Talk2Radar samples of one frame share them; a VoD root's frames are all distinct."""
    from model.evaluation.predict import scene_key

    seen: set[object] = set()
    out = []
    for sid in ids:
        try:
            key = scene_key(root, sid)
        except FileNotFoundError as exc:
            raise RootError(f"{exc.filename}: missing sensor file for sample {sid}") from exc
        if key not in seen:
            seen.add(key)
            out.append(sid)
    return out
