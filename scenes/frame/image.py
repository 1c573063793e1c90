"""Camera image files (``image_2/<id>.jpg``): a strict reader, a header-only size reader and an
atomic JPEG writer.

Images are ``(H, W, 3)`` uint8 RGB arrays, row 0 at the top. Pixel ``(row j, column i)`` covers
``[i, i + 1) x [j, j + 1)`` in image coordinates (its centre is at ``(i + 0.5, j + 0.5)``), the
convention under which ``P2`` projects and :func:`scenes.geometry.calib.boxes_2d` clips to ``[0, W]``.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np
from PIL import Image

from scenes.geometry.calib import IMAGE_SIZE
from scenes.utils.durable import atomic_write_bytes
from scenes.utils.textfile import read_file_bytes

PRINCIPAL_POINT_TOLERANCE = 0.05
"""An image whose size puts P2's principal point further than this fraction of the width (height)
from the image centre is probably not the image P2 describes (VoD's is 0.4 % and 1.4 % off)."""


class ImageError(ValueError):
    """An image file is missing, unreadable, corrupt or truncated; the message names the file."""


def read_image(path: str | Path) -> np.ndarray:
    """Decode an image file fully into ``(H, W, 3)`` uint8 RGB (grey or CMYK files are converted).

    Raises:
        ImageError: the file is missing or unreadable, not an image, corrupt or truncated.
    """
    path = Path(path)
    raw = read_file_bytes(path, "image file", ImageError)
    if not raw:
        raise ImageError(f"{path}: the image file is empty")
    try:
        with Image.open(io.BytesIO(raw)) as img:
            img.load()  # decodes everything: a truncated file fails here, not later
            rgb = img.convert("RGB")
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as exc:
        raise ImageError(f"{path}: corrupt or truncated image ({exc})") from exc
    return np.asarray(rgb, dtype=np.uint8).copy()


def read_image_size(path: str | Path) -> tuple[int, int]:
    """``(width, height)`` of an image file, from its header only (nothing is decoded).

    Raises:
        ImageError: the file is missing or unreadable, or not an image.
    """
    path = Path(path)
    try:
        with Image.open(path) as img:
            return (int(img.size[0]), int(img.size[1]))
    except FileNotFoundError as exc:
        raise ImageError(f"{path}: image file not found") from exc
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as exc:
        raise ImageError(f"{path}: unreadable image header ({exc})") from exc


def check_principal_point(
    image_size: tuple[int, int], principal_point: tuple[float, float], source: str
) -> str | None:
    """A warning text when P2's principal point ``(cx, cy)`` (pixels) is far from the centre of an
    image of ``(width, height)`` (see :data:`PRINCIPAL_POINT_TOLERANCE`), else None."""
    width, height = image_size
    cx, cy = principal_point
    off_x, off_y = abs(cx - width / 2) / width, abs(cy - height / 2) / height
    if max(off_x, off_y) <= PRINCIPAL_POINT_TOLERANCE:
        return None
    return (
        f"{source}: the image is {width} x {height} but P2's principal point is at "
        f"({cx:.1f}, {cy:.1f}), {100 * off_x:.0f} % / {100 * off_y:.0f} % of the size away from "
        "its centre; the calib may describe an image of another size"
    )


def warn_principal_point(
    image_size: tuple[int, int], principal_point: tuple[float, float], source: str
) -> None:
    """Issue :func:`check_principal_point`'s warning (a ``UserWarning``), if any."""
    message = check_principal_point(image_size, principal_point, source)
    if message is not None:
        warnings.warn(message, UserWarning, stacklevel=3)


def encode_jpeg(image: np.ndarray, quality: int = 90) -> bytes:
    """JPEG bytes of an ``(H, W, 3)`` uint8 RGB image (4:2:0, deterministic for equal input)."""
    arr = np.asarray(image)
    if arr.dtype != np.uint8 or arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"image must be (H, W, 3) uint8, got {arr.shape} {arr.dtype}")
    buffer = io.BytesIO()
    Image.fromarray(arr).save(buffer, format="JPEG", quality=int(quality))
    return buffer.getvalue()


def write_jpeg(path: str | Path, image: np.ndarray, quality: int = 90) -> None:
    """Write ``image`` (``(H, W, 3)`` uint8) as a JPEG atomically
    (:func:`scenes.utils.durable.atomic_write_bytes`)."""
    path = Path(path)
    data = encode_jpeg(image, quality)
    atomic_write_bytes(path, data)


def label_image_size(image: Path | None, known: tuple[int, int] | None = None) -> tuple[int, int]:
    """The one rule for the image size the 2D boxes of ``label_2`` are clipped to: ``known`` (the
    size of an image just written), else the size of the frame's camera image ``image`` (read from
    its header), else VoD's 1936 x 1216 (a frame without an image).

    Raises:
        ImageError: ``image`` is unreadable.
    """
    if known is not None:
        return known
    return read_image_size(image) if image is not None else IMAGE_SIZE
