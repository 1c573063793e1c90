"""Durable file IO: atomic writes, links and replacements, and JSON Lines logs that survive a kill.

Every writer of the project goes through this module (the root writer, the synthetic generator, the
annotation store, checkpoints), so a file is either its old or its new content, never a part:

- **Temporaries.** One naming rule: the temporary of ``<dir>/<name>`` is
  ``<dir>/.<name>.<pid>.<thread>.tmp`` (:func:`temp_path`), beside its target so that the rename
  stays on one filesystem, unique per process and thread. :func:`temp_glob` matches them (by the
  start of the target's name) for :func:`remove_temporaries`, which clears what a killed writer
  left behind.
- **Atomic write.** :func:`atomic_file` (and :func:`atomic_write_bytes`,
  :func:`atomic_write_text` on it): write the temporary, flush, ``fsync``, ``os.replace`` over the
  target, then ``fsync`` the folder (:func:`fsync_dir`) so the rename itself is durable. On any
  exception the temporary is removed and the target is untouched.
- **Links.** :func:`link_or_copy` hard-links a file to a new name the same way (a copy, fsynced,
  where links are impossible).
- **Several files at once.** :func:`replace_files` writes every temporary (fsynced) before it
  renames the first: a full disk stops it before any target changed.
- **JSON Lines.** :func:`append_line` appends one line with ``O_APPEND`` and ``fsync``,
  terminating a torn last line first and truncating back when the write fails;
  :func:`read_json_lines` reads a log line by line, reporting unreadable lines (a torn last line
  after a kill) instead of failing, and :func:`drop_torn_tail` cuts such a last line off.

Folder fsyncs are best effort (some filesystems refuse them); file fsyncs are not.
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import shutil
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Generic, TypeVar

from scenes.utils.textfile import BOM, note_bom

T = TypeVar("T")

TEMP_SUFFIX = ".tmp"
"""The last part of every temporary's name (:func:`temp_path`)."""


def temp_path(path: str | Path) -> Path:
    """The temporary of ``path``: ``.<name>.<pid>.<thread>.tmp`` in the same folder."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}{TEMP_SUFFIX}")


def temp_glob(name_start: str = "") -> str:
    """The glob pattern of the temporaries of the targets whose names start with ``name_start``
    (``"00012."``: every file of sample 12; ``""``: all of a folder's temporaries)."""
    return f".{glob.escape(name_start)}*{TEMP_SUFFIX}"


def remove_temporaries(folder: str | Path, name_start: str = "") -> None:
    """Delete the temporaries in ``folder`` of the targets whose names start with ``name_start``
    (:func:`temp_glob`); a missing folder has none."""
    for tmp in Path(folder).glob(temp_glob(name_start)):
        tmp.unlink(missing_ok=True)


def fsync_dir(path: str | Path) -> None:
    """Fsync a folder, so that a rename or a new file in it is durable; best effort (errors,
    e.g. a filesystem that refuses it or a missing folder, are ignored)."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _sync_file(handle: IO[Any]) -> None:
    handle.flush()
    os.fsync(handle.fileno())


def sync_descriptor(fd: int) -> None:
    """Flush an open file descriptor's data to the disk (a lock file written in place)."""
    os.fsync(fd)


def move_file(src: str | Path, dst: str | Path) -> None:
    """Move a finished file into place by one rename (same file system), its folder synced."""
    os.replace(src, dst)
    fsync_dir(Path(dst).parent)


@contextlib.contextmanager
def atomic_file(path: str | Path, binary: bool = True) -> Iterator[IO[Any]]:
    """Write ``path`` atomically through the handle this yields (binary, or UTF-8 text with
    ``binary=False``): the temporary is fsynced and renamed over ``path`` when the block ends, and
    the folder fsynced; when the block raises, the temporary is removed and ``path`` is untouched.
    Missing parent folders are created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path(path)
    try:
        with open(tmp, "wb") if binary else open(tmp, "w", encoding="utf-8") as handle:
            yield handle
            _sync_file(handle)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (:func:`atomic_file`)."""
    with atomic_file(path) as handle:
        handle.write(data)


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_file`)."""
    with atomic_file(path, binary=False) as handle:
        handle.write(text)


def _same_file(a: str | Path, b: str | Path) -> bool:
    """Whether both paths exist and name the same file (False where either is missing)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def link_or_copy(src: str | Path, dst: str | Path) -> None:
    """Hard-link ``src`` to ``dst``, replacing ``dst`` atomically (a copy, fsynced, where links are
    impossible, e.g. across filesystems); the folder is fsynced. Nothing to do where ``dst`` is
    already ``src`` (the same file, or another link to it): a rename onto a link of the same file
    does nothing, and would leave the temporary behind."""
    dst = Path(dst)
    if _same_file(src, dst):
        return
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path(dst)
    tmp.unlink(missing_ok=True)
    try:
        try:
            os.link(src, tmp)
        except OSError:
            shutil.copyfile(src, tmp)
            with open(tmp, "rb+") as handle:
                os.fsync(handle.fileno())
        os.replace(tmp, dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(dst.parent)


def replace_files(targets: Sequence[tuple[Path, str]]) -> None:
    """Replace several text files (UTF-8): every ``(path, text)`` is written to its temporary and
    fsynced first, then each is renamed over its target, then their folders are fsynced. A failure
    in the first phase (a full disk) leaves every target untouched; the temporaries are always
    removed."""
    staged: list[tuple[Path, Path]] = []
    try:
        for path, text in targets:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = temp_path(path)
            staged.append((tmp, path))
            with open(tmp, "w", encoding="utf-8") as handle:
                handle.write(text)
                _sync_file(handle)
        for tmp, path in staged:
            os.replace(tmp, path)
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
    for folder in dict.fromkeys(path.parent for _, path in staged):
        fsync_dir(folder)


# ------------------------------------------------------------------------------------ JSON Lines


def append_line(path: str | Path, line: str) -> None:
    """Append one line (``line`` plus a line break) to a text file, creating it: ``O_APPEND``,
    then ``fsync``.

    A missing line break at the end of the file (a torn last line) is written first, so the new
    line stands alone; when the write fails the file is truncated back to its former size.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        size = os.fstat(fd).st_size
        prefix = b""
        if size and os.pread(fd, 1, size - 1) != b"\n":
            prefix = b"\n"
        data = prefix + line.encode("utf-8") + b"\n"
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except BaseException:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, size)
            raise
    finally:
        os.close(fd)


def append_json_line(path: str | Path, value: object) -> None:
    """Append ``json.dumps(value)`` as one line (:func:`append_line`)."""
    append_line(path, json.dumps(value))


LINE_ERRORS = (ValueError, KeyError, TypeError, AttributeError, IndexError, RecursionError)
"""What a line's parse may raise to say "unreadable" (``json.JSONDecodeError`` is a ValueError)."""


@dataclass(frozen=True)
class JsonLines(Generic[T]):
    """A JSON Lines file as read by :func:`read_json_lines`.

    Attributes:
        path: The file.
        entries: ``(line number, parsed value)`` of every readable line, in file order.
        unreadable: ``(line number, why)`` of every line that could not be read.
        last_line: Number of the last non-blank line (0: none).
        last_offset: Byte offset at which that line starts.
    """

    path: Path
    entries: tuple[tuple[int, T], ...]
    unreadable: tuple[tuple[int, str], ...]
    last_line: int = 0
    last_offset: int = 0

    @property
    def torn_tail(self) -> bool:
        """Whether the last line is unreadable (what a kill in the middle of an append leaves)."""
        return bool(self.unreadable) and self.unreadable[-1][0] == self.last_line


def read_json_lines(
    path: str | Path, parse: Callable[[Any], T] = lambda value: value
) -> JsonLines[T]:
    """Read a JSON Lines file (a missing file has no lines); blank lines are skipped.

    Args:
        path: The file.
        parse: Turns a line's JSON value into an entry; raising one of :data:`LINE_ERRORS` makes
            the line unreadable.

    Never fails on a line's content (an undecodable byte is replaced, then fails to parse):
    unreadable lines are reported in :attr:`JsonLines.unreadable`. A leading UTF-8 byte-order
    mark is no part of the first line (and is said once per root:
    :func:`scenes.utils.textfile.note_bom`); a CRLF line end is JSON whitespace.
    """
    path = Path(path)
    if not path.is_file():
        return JsonLines(path, (), ())
    raw = path.read_bytes()
    skip = len(BOM) if raw.startswith(BOM) else 0
    if skip:
        note_bom(path, "log")
    entries: list[tuple[int, T]] = []
    unreadable: list[tuple[int, str]] = []
    last_line = last_offset = offset = 0
    for lineno, chunk in enumerate(raw.split(b"\n"), start=1):
        start, offset = offset, offset + len(chunk) + 1
        line = chunk[skip if lineno == 1 else 0 :].decode("utf-8", errors="replace")
        if not line.strip():
            continue
        last_line, last_offset = lineno, start
        try:
            entries.append((lineno, parse(json.loads(line))))
        except LINE_ERRORS as exc:
            unreadable.append((lineno, str(exc)))
    return JsonLines(path, tuple(entries), tuple(unreadable), last_line, last_offset)


def drop_torn_tail(log: JsonLines[Any]) -> None:
    """Cut an unreadable last line off the file ``log`` was read from (no-op when the last line
    reads), durably."""
    if not log.torn_tail:
        return
    fd = os.open(log.path, os.O_RDWR)
    try:
        os.ftruncate(fd, log.last_offset)
        os.fsync(fd)
    finally:
        os.close(fd)


__all__ = [
    "LINE_ERRORS",
    "TEMP_SUFFIX",
    "JsonLines",
    "append_json_line",
    "append_line",
    "atomic_file",
    "atomic_write_bytes",
    "atomic_write_text",
    "drop_torn_tail",
    "fsync_dir",
    "link_or_copy",
    "read_json_lines",
    "remove_temporaries",
    "replace_files",
    "temp_glob",
    "temp_path",
]
