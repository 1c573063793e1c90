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
older than the limit (:meth:`RankLiveness.limit`) is stopped or hung. The watching rank then
prints one line (``error: rank N ...: stopped ...; resume with --resume``), kills that rank where
it runs on this machine (a stopped process takes SIGKILL only, and ``torchrun`` would otherwise
wait for it), and leaves at once with exit code 1 (``os._exit``: its main thread is blocked inside
a collective, which cannot be interrupted). The run state on disk is the last checkpoint's,
written atomically, so ``--resume`` goes on from there.

The limit follows the run's own pace (issue 50 item 5: a fixed minute let a frozen rank hold a
run of sub-second steps silently for as long): once training steps have been timed
(:meth:`RankWatch.note_step`, the training loop's wall time per step, collectives included), it
is :data:`STEP_MULTIPLE` times the median of the last :data:`STEPS_KEPT` steps (the first step
of a process aside: its warm-up takes several steps' time), at least
:data:`FLOOR_S` (a loaded machine delays a thread by seconds) and at most ``TALK2PC_RANK_TIMEOUT``
seconds (default :data:`DEFAULT_LIMIT_S`); before the first step (set-up, the frozen scenes'
encoding) it is :data:`STARTUP_LIMIT_S`, or ``TALK2PC_RANK_TIMEOUT`` when that is smaller. The
beat comes every fifth of the smallest limit the run can have: the tests set a few seconds.
"""

from __future__ import annotations

import collections
import contextlib
import os
import signal
import socket
import statistics
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

DEFAULT_LIMIT_S = 60.0
"""The most seconds without a heartbeat before a rank counts as stopped, however slow its steps
(a heavily loaded machine delays a thread by seconds, not by a minute)."""

STARTUP_LIMIT_S = 30.0
"""The limit before a training step has been timed (at most ``TALK2PC_RANK_TIMEOUT``)."""

FLOOR_S = 10.0
"""The least limit, however fast the steps (at most ``TALK2PC_RANK_TIMEOUT``)."""

STEP_MULTIPLE = 20.0
"""The limit in steps: this many times the median recent step."""

STEPS_KEPT = 20
"""Recent step times the limit looks at (their median)."""

LIMIT_ENV = "TALK2PC_RANK_TIMEOUT"
"""The environment variable that sets the limit in seconds (all ranks read the same)."""

EXIT_CODE = 1
"""A watching rank's exit code when another rank stopped answering (as for a killed rank)."""

DONE = "done"
"""The heartbeat of a rank that left the process group normally."""


@dataclass(frozen=True)
class RankLiveness:
    """The heartbeat's period and limit, in seconds (module docstring).

    Attributes:
        limit_s: The most the limit can be (``TALK2PC_RANK_TIMEOUT``).
        startup_s: The limit before a step has been timed (capped by ``limit_s``).
        floor_s: The least limit from timed steps (capped by ``limit_s``).
        step_multiple: The limit in steps of the median recent one.
    """

    limit_s: float = DEFAULT_LIMIT_S
    startup_s: float = STARTUP_LIMIT_S
    floor_s: float = FLOOR_S
    step_multiple: float = STEP_MULTIPLE

    def __post_init__(self) -> None:
        if not self.limit_s > 0:
            raise ValueError(f"the rank timeout must be > 0 s, got {self.limit_s}")
        if not (self.startup_s > 0 and self.floor_s > 0 and self.step_multiple > 0):
            raise ValueError("the rank watch's start-up limit, floor and step multiple must be > 0")

    @property
    def beat_s(self) -> float:
        """How often a rank beats and looks at the others: a fifth of the smallest limit."""
        return min(self.limit_s, self.floor_s, self.startup_s) / 5

    def limit(self, step_s: float | None) -> float:
        """Seconds without a heartbeat after which a rank counts as stopped, for a run whose
        median recent step took ``step_s`` seconds (None: no step timed yet)."""
        if step_s is None:
            return min(self.limit_s, self.startup_s)
        return min(self.limit_s, max(self.floor_s, self.step_multiple * step_s))

    def explain(self, step_s: float | None) -> str:
        """How :meth:`limit` came about, for the line that names a stopped rank."""
        if step_s is None:
            return f"the start-up limit, before any step; {LIMIT_ENV} caps it"
        return (
            f"{self.step_multiple:g} x the median recent step of {step_s:.3g} s, at least "
            f"{min(self.floor_s, self.limit_s):g} s, at most {self.limit_s:g} s: {LIMIT_ENV}"
        )

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
        self._steps: collections.deque[float] = collections.deque(maxlen=STEPS_KEPT)
        self._steps_lock = threading.Lock()
        self._warm = False  # the first step (its warm-up) is not one of the recent steps
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

    def note_step(self, seconds: float) -> None:
        """A training step of this rank took ``seconds`` (the limit follows the recent ones; the
        first step noted, its warm-up, is left out)."""
        with self._steps_lock:
            if self._warm:
                self._steps.append(float(seconds))
            self._warm = True

    def step_s(self) -> float | None:
        """The median of the recent steps noted, or None before one counts."""
        with self._steps_lock:
            return statistics.median(self._steps) if self._steps else None

    def limit(self) -> float:
        """The limit now (:meth:`RankLiveness.limit` of the recent steps)."""
        return self.liveness.limit(self.step_s())

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
        limit = self.limit()
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
            elif now - seen[0] > limit:
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
        step_s = self.step_s()
        sys.stderr.write(  # on a line of its own (a progress bar may end without one)
            f"\nerror: rank {other}{where} has not answered for more than "
            f"{self.liveness.limit(step_s):.3g} s ({self.liveness.explain(step_s)}): stopped "
            f"(SIGSTOP, Ctrl-Z), hung or lost{killed}; rank {self.rank} ends the run; the run "
            "folder holds the last checkpoint: start the same torchrun command again with "
            "--resume\n"
        )
        sys.stderr.flush()
        os._exit(EXIT_CODE)


__all__ = [
    "DEFAULT_LIMIT_S",
    "EXIT_CODE",
    "FLOOR_S",
    "LIMIT_ENV",
    "STARTUP_LIMIT_S",
    "STEP_MULTIPLE",
    "RankLiveness",
    "RankWatch",
]
