"""Liveness of ``torchrun`` ranks (issue 39 item 3): a rank that stops answering (SIGSTOP, a hang,
a lost machine) ends the run within a bounded time with one line naming it and what to do.

A collective (DDP's gradient all-reduce in ``backward``, :mod:`model.training.distributed`'s
agreements) waits for every rank; gloo and NCCL would wait their process group's timeout (30
minutes) and then fail with a traceback that names no rank. A rank killed outright is already
noticed by ``torchrun`` (its agent ends the others); a *stopped* one is not. So each rank runs a
:class:`RankWatch`: a thread that writes a heartbeat ``(time, pid, host)`` into the process
group's store every :attr:`RankLiveness.beat_s` and reads the others'. The heartbeat does not
depend on the work's pace (a rank validating or writing a checkpoint while the others wait at the
next collective still beats), so its limit is not a per-step time: a rank whose heartbeat is
older than :attr:`RankLiveness.limit_s` is stopped or hung. The watching rank then prints one
line (``error: rank N ...: stopped ...; resume with --resume``), kills that rank where it runs on
this machine (a stopped process takes SIGKILL only, and ``torchrun`` would otherwise wait for it),
and leaves at once with exit code 1 (``os._exit``: its main thread is blocked inside a collective,
which cannot be interrupted). The run state on disk is the last checkpoint's, written atomically,
so ``--resume`` goes on from there.

The limit is ``TALK2PC_RANK_TIMEOUT`` seconds (default :data:`DEFAULT_LIMIT_S`), the beat a
fifth of it: the tests set a few seconds.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

DEFAULT_LIMIT_S = 60.0
"""Seconds without a heartbeat after which a rank counts as stopped (its beat comes every 12 s:
a heavily loaded machine delays a thread by seconds, not by a minute)."""

LIMIT_ENV = "TALK2PC_RANK_TIMEOUT"
"""The environment variable that sets the limit in seconds (all ranks read the same)."""

EXIT_CODE = 1
"""A watching rank's exit code when another rank stopped answering (as for a killed rank)."""

DONE = "done"
"""The heartbeat of a rank that left the process group normally."""


@dataclass(frozen=True)
class RankLiveness:
    """The heartbeat's period and limit, in seconds."""

    limit_s: float = DEFAULT_LIMIT_S

    def __post_init__(self) -> None:
        if not self.limit_s > 0:
            raise ValueError(f"the rank timeout must be > 0 s, got {self.limit_s}")

    @property
    def beat_s(self) -> float:
        """How often a rank beats and looks at the others."""
        return self.limit_s / 5

    @classmethod
    def from_env(cls) -> RankLiveness:
        """:data:`LIMIT_ENV`'s limit, else the default; a value that is not a positive number is
        an error naming the variable."""
        text = os.environ.get(LIMIT_ENV)
        if text is None:
            return cls()
        try:
            return cls(float(text))
        except ValueError as exc:
            raise ValueError(f"{LIMIT_ENV}={text!r}: not a positive number of seconds") from exc


class RankWatch:
    """A rank's heartbeat and its watch over the others (module docstring).

    Args:
        store: The process group's key-value store (``set``, ``get``, ``check``).
        rank: This process's rank.
        world: The number of ranks.
        liveness: The limit.
    """

    def __init__(self, store: Any, rank: int, world: int, liveness: RankLiveness) -> None:
        self.store = store
        self.rank = rank
        self.world = world
        self.liveness = liveness
        self.host = socket.gethostname()
        self._stop = threading.Event()
        self._seen: dict[int, tuple[float, str]] = {}  # rank -> (local time its beat changed, beat)
        self._thread = threading.Thread(target=self._run, name="talk2pc-rank-watch", daemon=False)

    def start(self) -> RankWatch:
        """Beat once (so that the others see this rank at once) and start the thread."""
        self._beat()
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread and wait for it (before the process group is destroyed, and before
        the interpreter exits: never a thread left inside the store's C++ code)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        # The others stop watching this rank: it finished, it did not stop (the store may be
        # gone already, rank 0 having ended first: then nobody is watching).
        with contextlib.suppress(Exception):
            self.store.set(f"talk2pc/beat/{self.rank}", f"{DONE}:{os.getpid()}:{self.host}")

    def _beat(self) -> None:
        self.store.set(f"talk2pc/beat/{self.rank}", f"{time.time()}:{os.getpid()}:{self.host}")

    def _run(self) -> None:
        while not self._stop.wait(self.liveness.beat_s):
            if not threading.main_thread().is_alive():
                # The main thread ended without stop() (an uncaught exception): stop beating, so
                # that the process exits and the others see this rank go instead of a live one.
                return
            try:
                self._beat()
                stopped = self.stopped_rank()
            except Exception:  # the store is gone: the group is closing, or rank 0 ended
                return
            if stopped is not None:
                self._end(*stopped)

    def stopped_rank(self) -> tuple[int, str] | None:
        """``(rank, its last beat)`` of a rank whose heartbeat has not changed for longer than
        the limit (by this process's clock: no clocks compared between machines); None if all
        beat."""
        now = time.monotonic()
        for other in range(self.world):
            if other == self.rank:
                continue
            key = f"talk2pc/beat/{other}"
            beat = self.store.get(key).decode() if self.store.check([key]) else ""
            if beat.startswith(DONE):
                continue
            seen = self._seen.get(other)
            if seen is None or seen[1] != beat:
                self._seen[other] = (now, beat)
            elif now - seen[0] > self.liveness.limit_s:
                return other, beat
        return None

    def _end(self, other: int, beat: str) -> None:
        """Say which rank stopped answering and what to do, kill it where it runs here, and
        leave (module docstring)."""
        _, pid, host = [*beat.split(":", 2), "", ""][:3]
        where = f" (pid {pid} on {host})" if pid else ""
        killed = ""
        if pid and host == self.host:
            try:
                os.kill(int(pid), signal.SIGKILL)
                killed = "; it was killed"
            except (OSError, ValueError):
                pass
        sys.stderr.write(
            f"error: rank {other}{where} has not answered for more than "
            f"{self.liveness.limit_s:g} s ({LIMIT_ENV}): stopped (SIGSTOP, Ctrl-Z), hung or "
            f"lost{killed}; rank {self.rank} ends the run; the run folder holds the last "
            f"checkpoint: start the same torchrun command again with --resume\n"
        )
        sys.stderr.flush()
        os._exit(EXIT_CODE)


__all__ = ["DEFAULT_LIMIT_S", "EXIT_CODE", "LIMIT_ENV", "RankLiveness", "RankWatch"]
