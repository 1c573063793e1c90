"""One writer per run folder: the lock ``model.train``, ``model.adapt`` and ``model.calibrate``
take on the folder they write into (issue 50 item 5).

Two runs on one ``--out`` would both write ``last.pt`` and the run state, and the last writer
would win silently. :func:`run_lock` holds ``<folder>/run.lock`` for the whole command:

- **The file.** A JSON object: ``pid``, ``host``, ``started`` (local ISO time) and ``command``
  (the command line). It is written under ``fcntl.flock`` (held as long as the file is open,
  released by the kernel when the process ends, however it ends) and removed on a clean exit.
- **Held.** While another process holds it (its ``flock`` is taken, or the file names a process
  alive on this host, or one on another host, which cannot be checked), a second run is refused
  with one line naming who holds it: :class:`RunLockError`, ``error: FOLDER is in use by pid N on
  HOST since T (COMMAND); ...``.
- **Stale.** A file left by a process that is gone (killed, a lost machine's run on this host:
  its ``flock`` is free and its pid not alive here, or alive but a process that started after
  the lock was taken: the pid given again) is taken over with one line on stderr
  (``note: FOLDER: took over the stale lock of pid N ...``); ``--resume`` after a ``kill -9``
  goes on.
- **Re-entrant** within one process (``model.train`` calibrates its run folder at its end):
  a nested :func:`run_lock` on a folder this process holds is a no-op.

Under ``torchrun`` only rank 0 takes the lock (:mod:`model.training.loop`), and every rank learns
whether it got it. Every writer of a run folder goes through here; the files themselves are
written by :mod:`scenes.utils.durable`.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import os
import shlex
import socket
import sys
import threading
import unicodedata
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from scenes.utils.durable import sync_descriptor

try:  # POSIX only; elsewhere the pid in the file alone tells a stale lock
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

LOCK_FILE = "run.lock"
"""The lock's name inside the run folder."""

COMMAND_SHOWN = 300
"""The most characters of the holder's command a refusal shows."""

STARTED_SLACK = 2.0
"""Seconds a process may seem to have started after the lock's ``started`` and still be its
holder (``started`` is whole seconds; the boot time /proc gives drifts with the clock)."""

_HELD: dict[str, int] = {}  # resolved folder -> nesting depth, in this process
_HELD_GUARD = threading.Lock()


def _shown(text: str) -> str:
    """``text`` on one line: whitespace runs as one space, control and format characters (a
    lock file is anybody's text) escaped."""
    return "".join(
        ch.encode("unicode_escape").decode("ascii")
        if unicodedata.category(ch) in ("Cc", "Cf", "Zl", "Zp")
        else ch
        for ch in " ".join(text.split())
    )


def _started_after(pid: int, started: str) -> bool:
    """Whether process ``pid`` of this host started after ``started`` (a holder's ISO time):
    then it is not the holder but a later process given the gone holder's pid (False when
    either time cannot be told: /proc missing, an unreadable time)."""
    try:
        when = datetime.datetime.fromisoformat(started).timestamp()
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
        ticks = int(stat[stat.rindex(")") + 2 :].split()[19])  # field 22, starttime
        boot = next(
            int(line.split()[1])
            for line in Path("/proc/stat").read_text(encoding="ascii").splitlines()
            if line.startswith("btime ")
        )
        begun = boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration, OverflowError):
        return False
    return begun > when + STARTED_SLACK


class RunLockError(RuntimeError):
    """Another run holds the folder; the message names it (one line)."""


@dataclass(frozen=True)
class LockHolder:
    """Who holds (or held) a run folder's lock, as its file says.

    Attributes:
        pid: Its process id.
        host: The host name it ran on.
        started: When it took the lock (local ISO time).
        command: Its command line.
    """

    pid: int
    host: str
    started: str
    command: str

    @classmethod
    def me(cls) -> LockHolder:
        """This process."""
        now = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
        return cls(os.getpid(), socket.gethostname(), now, shlex.join(sys.orig_argv))

    @classmethod
    def parse(cls, text: str) -> LockHolder | None:
        """The holder a lock file's text names, or None (empty or not a holder: a file cut off
        between its creation and its first write)."""
        try:
            data = json.loads(text)
            return cls(
                int(data["pid"]), str(data["host"]), str(data["started"]), str(data["command"])
            )
        except (ValueError, KeyError, TypeError):
            return None

    def text(self) -> str:
        return json.dumps(self.__dict__) + "\n"

    def alive(self) -> bool | None:
        """Whether its process is alive: True / False on this host, None on another (unknown)."""
        if self.host != socket.gethostname():
            return None
        if self.pid == os.getpid():
            return True
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # another user's live process
            pass
        return not _started_after(self.pid, self.started)

    def describe(self) -> str:
        """``pid N on HOST since T (COMMAND)``: one line (whitespace collapsed, other control
        characters shown escaped, a long command cut)."""
        command = _shown(self.command)
        if len(command) > COMMAND_SHOWN:
            command = command[: COMMAND_SHOWN - 3] + "..."
        return f"pid {self.pid} on {_shown(self.host)} since {_shown(self.started)} ({command})"


def lock_path(folder: str | Path) -> Path:
    """The lock file of a run folder."""
    return Path(folder) / LOCK_FILE


def read_holder(folder: str | Path) -> LockHolder | None:
    """Who the folder's lock file names (None: no file, or an unreadable one)."""
    try:
        return LockHolder.parse(lock_path(folder).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError):
        return None


def _refuse(folder: Path, holder: LockHolder | None, what: str) -> RunLockError:
    who = holder.describe() if holder is not None else "another process"
    return RunLockError(
        f"{folder} is in use by {who}: one run writes a run folder at a time; wait for it to "
        f"end, or give {what} another folder (if no such run is going on, remove "
        f"{lock_path(folder)})"
    )


def _try_flock(fd: int) -> bool:
    if fcntl is None:  # pragma: no cover
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _open_locked(path: Path, folder: Path, what: str) -> int:
    """The lock file opened and ``flock``-ed by this process (the same file as ``path`` names
    now: one removed meanwhile by its holder is opened again)."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
        if not _try_flock(fd):
            os.close(fd)
            raise _refuse(folder, read_holder(folder), what)
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(path))
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)  # its holder removed it between our open and our flock: again


@contextlib.contextmanager
def run_lock(folder: str | Path, what: str = "--out") -> Iterator[None]:
    """Hold ``folder``'s lock for the ``with`` block (module docstring); ``folder`` is created
    (and, with the parents made for it, removed again at the end when left empty).

    Args:
        folder: The run folder written into.
        what: The flag that names it (in the refusal's advice).

    Raises:
        RunLockError: another live process holds it (one line naming it).
        OSError: the folder or its lock file cannot be made.
    """
    folder = Path(folder)
    made = [p for p in (folder, *folder.parents) if not p.exists()]  # deepest first
    folder.mkdir(parents=True, exist_ok=True)
    key = str(folder.resolve())
    with _HELD_GUARD:
        if key in _HELD:
            _HELD[key] += 1
            nested = True
        else:
            nested = False
    if nested:
        try:
            yield
        finally:
            with _HELD_GUARD:
                _HELD[key] -= 1
        return
    path = lock_path(folder)
    fd = _open_locked(path, folder, what)
    try:
        old = LockHolder.parse(os.pread(fd, 1 << 16, 0).decode("utf-8", errors="replace"))
        if old is not None and old.pid != os.getpid():
            if old.alive() is not False:  # alive here, or on another host: not ours to take
                raise _refuse(folder, old, what)
            print(
                f"note: {folder}: took over the stale lock of {old.describe()}: that process is "
                "gone",
                file=sys.stderr,
            )
        os.ftruncate(fd, 0)
        os.pwrite(fd, LockHolder.me().text().encode("utf-8"), 0)
        sync_descriptor(fd)
    except BaseException:
        os.close(fd)
        raise
    with _HELD_GUARD:
        _HELD[key] = 1
    try:
        yield
    finally:
        with _HELD_GUARD:
            del _HELD[key]
        with contextlib.suppress(OSError):
            path.unlink()  # still under the flock: nobody took it meanwhile
        os.close(fd)
        for made_here in made:  # a run that wrote nothing (refused settings) leaves no folder
            with contextlib.suppress(OSError):
                made_here.rmdir()


__all__ = ["LOCK_FILE", "LockHolder", "RunLockError", "lock_path", "read_holder", "run_lock"]
