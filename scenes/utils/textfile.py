"""The strict file reads shared by the Talk2Radar readers: :func:`read_file_bytes` (point clouds,
images, and under :func:`read_text_file`: labels, calibrations, prompts, split lists, sidecars):
one error type per kind of file, one line naming the file."""

from __future__ import annotations

from pathlib import Path


def read_file_bytes(path: str | Path, what: str, error: type[Exception]) -> bytes:
    """The bytes of ``path``.

    Args:
        path: The file.
        what: What it is, for the message (``"point-cloud file"``).
        error: The exception type to raise.

    Raises:
        error: the file is missing or unreadable (a folder, a symlink loop, no permission); the
            one-line message names the file.
    """
    path = Path(path)
    try:
        return path.read_bytes()
    except FileNotFoundError as exc:
        raise error(f"{path}: {what} not found") from exc
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from exc


def read_text_file(path: str | Path, what: str, error: type[Exception]) -> str:
    """The UTF-8 text of ``path``.

    Args:
        path: The file.
        what: What it is, for the message (``"label file"``).
        error: The exception type to raise (e.g. :class:`scenes.talk2radar.kitti.LabelError`).

    Raises:
        error: the file is missing, unreadable (a folder, a symlink loop, no permission), not
            UTF-8, or binary (it holds a NUL byte); the one-line message names the file.
    """
    path = Path(path)
    raw = read_file_bytes(path, what, error)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(
            f"{path}: the {what} is not UTF-8 text (byte {exc.start} is {raw[exc.start]:#04x})"
        ) from exc
    if "\0" in text:
        raise error(f"{path}: the {what} is binary, not text (a NUL byte at {text.index(chr(0))})")
    return text
