"""The journals of interrupted operations: ``annotations/pending/<op>.json``.

Before an operation touches the root it writes a journal with what it is about to do: ``op`` (a
unique hex id), ``action`` (``create``, ``edit`` or ``delete``), ``sample_id``, ``splits``, the
manifest ``record`` it will append and, for an edit, ``restore``: the old text of every file it
replaces (None for a file that did not exist), by path relative to the root. The operation removes
its journal when done; a journal found later is resolved by :mod:`annotate.transaction`. A journal
that cannot be resolved is set aside in ``annotations/unresolved/``; the ids of both folders stay
reserved.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
from pathlib import Path

from annotate.errors import StoreError, one_line, operation_error
from scenes.utils.durable import atomic_write_text, fsync_dir
from scenes.utils.textfile import read_json_file

log = logging.getLogger(__name__)


class Journals:
    """The pending and set-aside journals of one store.

    Args:
        pending: ``annotations/pending``.
        unresolved: ``annotations/unresolved``.
    """

    def __init__(self, pending: Path, unresolved: Path) -> None:
        self.pending_dir = pending
        self.unresolved_dir = unresolved

    def path(self, op: str) -> Path:
        """The journal file of operation ``op``."""
        return self.pending_dir / f"{op}.json"

    def write(self, journal: dict) -> None:
        """Write a journal (atomically, its folder fsynced: :func:`scenes.utils.durable.atomic_write_text`)
        before its operation starts.

        Raises:
            SaveError, DiskFullError: it could not be written (nothing was saved).
        """
        try:
            atomic_write_text(self.path(journal["op"]), json.dumps(journal))
        except Exception as exc:
            raise operation_error(exc, "starting the operation", "nothing was saved") from exc

    def remove(self, op: str) -> None:
        """Remove a finished operation's journal; a failure is only logged (the operation is
        done, and a journal left behind resolves as "done" next time)."""
        try:
            self.path(op).unlink(missing_ok=True)
        except OSError as exc:
            log.warning("cannot remove the journal %s: %s", self.path(op), exc)
        fsync_dir(self.pending_dir)

    def pending(self) -> list[Path]:
        """The pending journals, oldest first."""
        journals = []
        for path in self.pending_dir.glob("*.json"):
            with contextlib.suppress(OSError):  # vanished meanwhile
                journals.append((path.stat().st_mtime, path))
        return [path for _, path in sorted(journals)]

    @staticmethod
    def read(path: Path) -> dict:
        """A journal's content (errors: :class:`StoreError` naming the file, JSON errors)."""
        journal = read_json_file(path, "journal", StoreError)
        if not isinstance(journal, dict):
            raise StoreError(f"{path}: the journal is not a JSON object")
        return journal

    def max_id(self) -> int:
        """The highest sample id of the pending and set-aside journals (-1: none)."""
        best = -1
        for folder in (self.pending_dir, self.unresolved_dir):
            for path in folder.glob("*.json"):
                with contextlib.suppress(StoreError, ValueError, KeyError, TypeError):
                    best = max(best, int(self.read(path)["sample_id"]))
        return best

    def set_aside(self, path: Path, exc: BaseException) -> str:
        """Move a journal recovery cannot resolve to ``annotations/unresolved/`` (its id stays
        reserved) and log a warning; returns the line the store's ``recover`` reports."""
        why = one_line(f"{type(exc).__name__}: {exc}")
        target = self.unresolved_dir / path.name
        try:
            self.unresolved_dir.mkdir(parents=True, exist_ok=True)
            os.replace(path, target)
            fsync_dir(self.pending_dir)
            where = f"moved to {target}"
        except OSError as move_exc:
            where = f"left in place: cannot move it ({move_exc.strerror or move_exc})"
        log.warning(
            "%s: an interrupted operation could not be resolved (%s); %s; the store carries on, "
            "check that operation's files by hand",
            path,
            why,
            where,
        )
        return f"{path.stem}: set aside ({why}; {where})"


__all__ = ["Journals"]
