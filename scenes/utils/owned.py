"""Output folders a writer owns: it writes only into a folder it made, or one it recognises as
its own by the marker it wrote there, and never deletes a file it did not write.

The one home of that rule (:func:`owned_output`), for the exporters that write a whole tree:

- **Refused outputs.** An output folder that is, lies inside, or contains a folder it must stay
  apart from (the source it is made from: :func:`check_apart`); an existing path that is not a
  folder; a non-empty folder without this writer's :data:`MARKER`. Each is one line naming the
  folder, and nothing is changed.
- **Staging.** The tree is written into a new hidden folder beside the output (beside the folder
  it links to, for a link: one file system), ``.<name>.<pid>-<random>.staging``, marked as this
  writer's staging from its first moment, then
  installed: renamed into place when the output does not exist; else moved in file by file over
  the files of the earlier export, whose files that the new one does not write are then removed.
  Files the earlier export did not write (the marker lists its files) are kept, and a file of
  the new tree that would replace one of them, or land outside the output through a link the
  user made in it, refuses the install before anything is moved; an earlier file behind such a
  link is kept. A marker that lists a path leaving its folder (``..``, absolute) is no marker.
- **Failures.** A failed export removes its staging folder (only what it wrote); one killed
  outright leaves it behind, and the next export beside it removes the stagings of this writer
  whose process is gone. While files are moved in, the marker lists the earlier and the new files
  together, so that an interrupted install is still recognised as this writer's and the retry
  completes it: nothing a failure leaves blocks the next try.

:func:`inside` is the containment test the others use (and the app's, for folders it must not
write into).
"""

from __future__ import annotations

import contextlib
import glob
import json
import os
import shutil
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path

from scenes.utils.durable import atomic_write_text, fsync_dir, move_file

__all__ = ["MARKER", "FolderError", "check_apart", "inside", "marker_of", "owned_output"]

MARKER = ".talk2pc-output.json"
"""The marker an owning writer leaves in its output: ``{"writer": ..., "files": [...]}`` (the
files it wrote, relative, ``/``-separated)."""
STAGING_SUFFIX = ".staging"
"""The last part of a staging folder's name (``.<name>.<pid>-<random>.staging``)."""


class FolderError(ValueError):
    """An output folder is refused (one line naming it; nothing was changed)."""


def inside(path: str | Path, folder: str | Path) -> bool:
    """Whether ``path`` is ``folder`` or lies under it, links resolved (neither needs to exist)."""
    p, f = Path(path).resolve(), Path(folder).resolve()
    return p == f or f in p.parents


def check_apart(out: str | Path, others: Mapping[str, str | Path]) -> None:
    """Refuse an output folder that is, lies inside or contains one of ``others`` (what each is
    -> its path, e.g. ``{"the source": SRC}``).

    Raises:
        FolderError: one line naming the output, the other folder and how they overlap.
    """
    for what, other in others.items():
        if Path(out).resolve() == Path(other).resolve():
            relation = "is"
        elif inside(out, other):
            relation = "lies inside"
        elif inside(other, out):
            relation = "contains"
        else:
            continue
        raise FolderError(
            f"{out}: {relation} {what} ({other}); choose an output folder apart from it"
        )


def marker_of(folder: str | Path) -> dict | None:
    """The marker of ``folder`` (None when it has none, or one that is not a marker)."""
    path = Path(folder) / MARKER
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("writer"), str):
        return None
    files = data.get("files", [])
    if not isinstance(files, list) or not all(_plain_relative(f) for f in files):
        return None  # a marker naming a file outside its folder is not one this module wrote
    return data


def _plain_relative(name: object) -> bool:
    """Whether ``name`` is a file a marker may list: a relative ``/``-separated path inside the
    folder (no ``..``, ``.`` or empty part, not the marker itself)."""
    if not isinstance(name, str) or not name or name.startswith("/") or "\\" in name:
        return False
    parts = name.split("/")
    return name != MARKER and not any(part in ("", ".", "..") for part in parts)


def _write_marker(folder: Path, writer: str, **fields: object) -> None:
    atomic_write_text(folder / MARKER, json.dumps({"writer": writer, **fields}, indent=0) + "\n")


def _check_output(out: Path, writer: str) -> set[str]:
    """The files of the earlier export at ``out`` (none when it is missing or empty).

    Raises:
        FolderError: ``out`` is not a folder, or a non-empty folder this writer did not mark.
    """
    if not out.exists() and not out.is_symlink():
        return set()
    if not out.is_dir():
        raise FolderError(f"{out}: exists and is not a folder; choose another output folder")
    names = sorted(p.name for p in out.iterdir())
    if not names:
        return set()
    marker = marker_of(out)
    if marker is None or marker.get("staging") or marker["writer"] != writer:
        by = "" if marker is None else f" (its {MARKER} names {marker['writer']})"
        raise FolderError(
            f"{out}: is not empty and was not written by {writer}{by}: it holds "
            f"{', '.join(names[:4])}{', ...' if len(names) > 4 else ''}; choose a new or empty "
            "output folder (nothing was changed)"
        )
    return set(marker.get("files", []))


def _alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _remove_stale_stagings(out: Path, writer: str) -> None:
    """Remove the staging folders beside ``out`` that this writer made in a process now gone."""
    pattern = f".{glob.escape(out.name)}.*{STAGING_SUFFIX}"
    for folder in out.parent.glob(pattern):
        marker = marker_of(folder) if folder.is_dir() and not folder.is_symlink() else None
        ours = marker is not None and marker.get("staging") and marker["writer"] == writer
        if ours and not _alive(marker.get("pid") if marker else None):
            shutil.rmtree(folder, ignore_errors=True)


def _files(folder: Path) -> list[str]:
    """Every file under ``folder`` but its marker, relative and ``/``-separated, sorted."""
    return sorted(
        p.relative_to(folder).as_posix()
        for p in folder.rglob("*")
        if (p.is_file() or p.is_symlink()) and p != folder / MARKER
    )


def _install(staging: Path, out: Path, writer: str, old: set[str]) -> None:
    """Move the staged tree into ``out`` (module docstring: the earlier export's files replaced
    or removed, every other file kept)."""
    files = _files(staging)
    if not out.exists():  # an empty folder is kept (its mode, owner, a shell's cwd in it)
        _write_marker(staging, writer, files=files)
        os.rename(staging, out)
        fsync_dir(out.parent)
        return
    for rel in files:
        target = out / rel
        for parent in [*reversed(Path(rel).parents)][1:]:
            blocked = (out / parent).exists() and not (out / parent).is_dir()
            if blocked and parent.as_posix() not in old:
                raise FolderError(
                    f"{out / parent}: is in the way of {rel} and was not written by "
                    f"{writer}; move it and export again (nothing was changed)"
                )
        if not inside(target.parent, out):
            raise FolderError(
                f"{target}: lies outside {out} once links are resolved (a linked folder in it); "
                "the export writes only into its own folder (nothing was changed)"
            )
        if (target.exists() or target.is_symlink()) and (rel not in old or target.is_dir()):
            raise FolderError(
                f"{target}: was not written by {writer} and the export would replace it; move "
                "it and export again (nothing was changed)"
            )
    _write_marker(out, writer, files=sorted(old | set(files)))
    for rel in files:
        target = out / rel
        for parent in [*reversed(Path(rel).parents)][1:]:
            if (out / parent).is_file():  # an earlier file of ours where a folder goes now
                (out / parent).unlink()
        target.parent.mkdir(parents=True, exist_ok=True)
        move_file(staging / rel, target)
    for rel in sorted(old - set(files)):
        target = out / rel
        if not inside(target.parent, out):  # behind a link the user made: not ours to remove
            continue
        if target.is_file() or target.is_symlink():
            target.unlink()
        for parent in Path(rel).parents:
            if parent == Path("."):
                break
            with contextlib.suppress(OSError):  # not empty (or gone): kept
                (out / parent).rmdir()
    _write_marker(out, writer, files=files)
    fsync_dir(out)


@contextlib.contextmanager
def owned_output(
    out: str | Path, writer: str, apart: Mapping[str, str | Path] | None = None
) -> Iterator[Path]:
    """Write a tree into ``out`` through a staging folder (module docstring): checks ``out``
    (:func:`check_apart` against ``apart``; new, empty, or marked by ``writer``), yields the
    staging folder to write the whole tree into, and installs it when the block ends without an
    error (the staging folder is removed when it raises).

    Args:
        out: The output folder.
        writer: Who writes (``scenes.export_nuscenes``): the marker's name for it.
        apart: Folders ``out`` must not be, lie in or contain (what each is -> its path).

    Raises:
        FolderError: a refused output (one line naming it; nothing was changed).
    """
    out = Path(os.path.abspath(out))  # "." and "a/.." have a name and a parent outside them
    check_apart(out, apart or {})
    old = _check_output(out, writer)
    real = out.resolve()  # a link to a folder: stage beside the folder (one file system)
    real.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_stagings(real, writer)
    staging = real.parent / f".{real.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}{STAGING_SUFFIX}"
    staging.mkdir()
    try:
        _write_marker(staging, writer, staging=True, pid=os.getpid())
        yield staging
        (staging / MARKER).unlink()
        _install(staging, out, writer, old)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
