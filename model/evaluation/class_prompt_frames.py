"""Which frames of a root the class prompts are asked on (distinct scenes of the frames
:func:`scenes.datasets.family_files.labelled_frame_ids` gives), and their camera's image size
(:mod:`model.evaluation.class_prompts`' inputs)."""

from __future__ import annotations

from collections.abc import Sequence

from PIL import Image

from scenes.frame import FrameSource, RootError, Sample
from scenes.geometry.calib import IMAGE_SIZE


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


def distinct_scenes(root: FrameSource, ids: Sequence[str]) -> list[str]:
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
