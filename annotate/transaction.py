"""How the store changes a root and never loses a pair: locking, journals, commit, undo.

Every change (create, edit, delete) runs inside :meth:`Transactions.transaction`, the one
transaction helper:

- **Locking.** Operations on one root are serialised by an in-process lock (threads of one server)
  and ``fcntl.flock`` on ``annotations/.lock`` (other processes); another writer is waited for up
  to ``lock_timeout`` seconds.
- **Recovery first.** Under the lock, every pending journal is resolved before the operation runs
  (:meth:`Transactions.recover_all`; also when a store opens).
- **Journal.** Before touching the root the operation writes its journal
  (:meth:`Transaction.begin`, :mod:`annotate.journal`); it is removed when the operation is done.
- **Commit point.** A sample exists for readers once its id is in ``lidar/ImageSets/<split>.txt``
  (:class:`scenes.talk2radar.root.Talk2RadarRoot` reads the LiDAR tree's lists). A create writes the
  sample's files first, then the radar tree's list, then the LiDAR tree's list (the commit), then
  the manifest line. A deletion removes the id from the LiDAR tree's lists first. An edit writes
  all its new files (fsynced) before the first replaces an old one.
- **Undo or complete.** When the operation fails, or a journal is found later (a crash, a kill, a
  full disk), :meth:`Transactions.resolve` completes an operation that passed its commit point
  (lists of both trees, manifest line) and undoes one that did not (a new sample's files are
  deleted, an edit's old files are written back); the failure is raised as
  :class:`~annotate.errors.DiskFullError` / :class:`~annotate.errors.SaveError`. Orphan files that
  no journal claims are never listed and never reused (ids are allocated beyond every id found).
- **Nothing blocks the store.** A journal that cannot be resolved (unreadable, or its undo fails
  for a reason other than a full disk) is set aside with a logged warning. While the disk is full,
  an interrupted edit that still needs its old files written back keeps its journal and every
  operation raises :class:`~annotate.errors.DiskFullError` until space is freed.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path

from annotate.errors import (
    DiskFullError,
    StoreError,
    fs_error,
    fs_errors,
    is_disk_full,
    operation_error,
)
from annotate.journal import Journals
from annotate.manifest import Manifest
from annotate.tree import RootFiles, holds
from scenes.talk2radar.layout import format_id
from scenes.utils.durable import fsync_dir, replace_files

try:  # POSIX only; elsewhere the in-process lock alone serialises writers.
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

_PROCESS_LOCKS: dict[str, threading.Lock] = {}
_PROCESS_LOCKS_GUARD = threading.Lock()


def _process_lock(path: Path) -> threading.Lock:
    """The in-process lock of a root (one per resolved path: every store of it shares it)."""
    key = str(path.resolve())
    with _PROCESS_LOCKS_GUARD:
        return _PROCESS_LOCKS.setdefault(key, threading.Lock())


class Transaction:
    """One operation inside :meth:`Transactions.transaction`: nothing is journalled until
    :meth:`begin`; a failure before it simply propagates."""

    def __init__(self, journals: Journals) -> None:
        self._journals = journals
        self.journal: dict | None = None
        self.what = ""

    def begin(self, journal: dict, what: str) -> None:
        """Write ``journal`` (see :mod:`annotate.journal`): from now on a failure is undone or
        completed and raised as a :class:`~annotate.errors.SaveError` about ``what``."""
        self._journals.write(journal)
        self.journal, self.what = journal, what


class Transactions:
    """Journalled operations on one root (see the module docstring).

    Args:
        files: The root's files.
        manifest: Its manifest.
        journals: Its journals.
        lock_file: ``annotations/.lock``.
        lock_timeout: Seconds to wait for another writer before :class:`StoreError`.
    """

    def __init__(
        self,
        files: RootFiles,
        manifest: Manifest,
        journals: Journals,
        lock_file: Path,
        lock_timeout: float,
    ) -> None:
        self.files = files
        self.manifest = manifest
        self.journals = journals
        self.lock_file = lock_file
        self.lock_timeout = float(lock_timeout)
        self._thread_lock = _process_lock(files.path)

    @contextlib.contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the root's in-process lock and its file lock."""
        if not self._thread_lock.acquire(timeout=self.lock_timeout):
            raise StoreError(f"{self.files.path}: another save is still running; try again")
        try:
            try:
                self.lock_file.parent.mkdir(parents=True, exist_ok=True)  # the first write's
                fd = os.open(self.lock_file, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise fs_error(exc, f"opening the lock file {self.lock_file}") from exc
            try:
                if fcntl is not None:
                    deadline = time.monotonic() + self.lock_timeout
                    while True:
                        try:
                            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                            break
                        except BlockingIOError:
                            if time.monotonic() > deadline:
                                raise StoreError(
                                    f"{self.files.path}: another process holds the annotation "
                                    f"lock ({self.lock_file}); try again"
                                ) from None
                            time.sleep(0.01)
                yield
            finally:
                os.close(fd)  # releases the flock
        finally:
            self._thread_lock.release()

    @contextlib.contextmanager
    def transaction(self, what: str) -> Iterator[Transaction]:
        """Run one operation: lock, resolve pending journals, then the body, which calls
        :meth:`Transaction.begin` before it touches the root. Filesystem errors become
        :class:`StoreError` s about ``what``; a failure after ``begin`` is undone (or completed,
        when it passed the commit point and the rest succeeds on a second try) and raised."""
        with self.locked(), fs_errors(what):
            self.recover_all()
            tx = Transaction(self.journals)
            try:
                yield tx
            except BaseException as exc:
                if tx.journal is None:
                    raise
                self._fail(tx.journal, exc, tx.what)
            if tx.journal is not None:
                self.journals.remove(tx.journal["op"])

    def _fail(self, journal: dict, exc: BaseException, what: str) -> None:
        """Undo (or complete) an interrupted operation, then raise a clear error.

        Returns normally only when the operation could be completed after all (its commit point
        had passed and the rest succeeded on the second try).
        """
        try:
            outcome = self.resolve(journal)
        except Exception as rec_exc:
            if not isinstance(exc, Exception):
                raise
            raise operation_error(
                exc,
                what,
                f"it will be resolved the next time the store opens (journal "
                f"{self.journals.path(journal['op'])}; recovery failed: {rec_exc})",
            ) from exc
        self.journals.remove(journal["op"])
        if not isinstance(exc, Exception):
            raise exc
        if outcome == "completed":
            return
        raise operation_error(exc, what, "nothing was saved; earlier pairs are intact") from exc

    def resolve(self, journal: Mapping[str, object]) -> str:
        """Complete or undo one journalled operation; returns ``"completed"``, ``"rolled back"``
        or ``"done"`` (it had finished; only the journal was left)."""
        files = self.files
        op = str(journal["op"])
        sid = format_id(journal["sample_id"])  # type: ignore[arg-type]
        action = str(journal["action"])
        splits = [str(s) for s in journal.get("splits", ())]  # type: ignore[attr-defined]
        record = journal.get("record")
        if self.manifest.has_op(op):
            return "done"
        if action == "create":
            committed = any(files.in_split(files.lidar_dir, sid, s) for s in splits)
            if committed:
                for s in splits:
                    files.add_to_split(sid, s)
                self.manifest.append(record)  # type: ignore[arg-type]
                return "completed"
            for tree in files.radar_trees():
                for s in splits:
                    files.remove_from_split(tree, sid, s)
            files.remove_sample_files(sid)
            return "rolled back"
        if action == "edit":
            restore = journal.get("restore") or {}
            targets = []
            for rel, text in restore.items():  # type: ignore[union-attr]
                path = files.path / rel
                if text is None:
                    path.unlink(missing_ok=True)
                elif not holds(path, str(text)):  # unchanged files need no writing back
                    targets.append((path, str(text)))
            replace_files(targets)
            files.remove_temporaries(sid)
            return "rolled back"
        if action == "delete":
            committed = any(not files.in_split(files.lidar_dir, sid, s) for s in splits)
            if not committed:
                return "rolled back"
            for tree in files.all_trees():
                for s in splits:
                    files.remove_from_split(tree, sid, s)
            self.manifest.append(record)  # type: ignore[arg-type]
            return "completed"
        raise StoreError(f"unknown action {action!r} in journal {self.journals.path(op)}")

    def recover_all(self) -> tuple[str, ...]:
        """Resolve every pending journal (hold the lock); also sweep stale temporary lists.

        A journal that cannot be resolved is set aside and never blocks the store; one whose undo
        needs disk space that is missing stays, and :class:`DiskFullError` is raised after the
        others are resolved.
        """
        done: list[str] = []
        full: list[str] = []
        for path in self.journals.pending():
            try:
                journal = self.journals.read(path)
                what = f"{format_id(journal['sample_id'])}: {journal['action']}"
                outcome = self.resolve(journal)
                path.unlink(missing_ok=True)
                done.append(f"{what} {outcome}")
            except Exception as exc:
                if is_disk_full(exc):
                    full.append(path.name)
                    continue
                done.append(self.journals.set_aside(path, exc))
        self.files.sweep_list_temporaries((self.journals.pending_dir,))
        if done:
            fsync_dir(self.journals.pending_dir)
        if full:
            raise DiskFullError(
                f"the disk is full: {len(full)} interrupted operation(s) in "
                f"{self.journals.pending_dir} cannot be undone yet ({', '.join(full)}); nothing "
                "else was changed. Free some space and try again."
            )
        return tuple(done)


__all__ = ["Transaction", "Transactions"]
