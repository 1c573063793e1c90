"""Liveness of prediction workers (:mod:`model.evaluation.predict_pool`): a worker that dies or
stops answering ends the run within a bounded time, with one line naming the worker and what to
do (issue 39 item 3).

- Each task, when a worker starts it, sends ``(task, pid, time)`` on a queue (:data:`StartQueue`),
  so this process knows which worker holds which frame and since when.
- The limits come from the work's own size (:class:`Liveness`): a started task may take
  ``factor`` times this process's slowest measured seconds per sample for its samples, at least
  ``floor_s`` (a worker's first task at least ``start_s``: it loads what the worker loads
  lazily); a task nobody has started, ``start_s`` after the last sign of life of any worker (a
  worker's start: an interpreter, torch, the model, MiniLM: about 3 s on an idle 2-core
  machine) or the task limit once the workers have started.
- A worker past its limit is reported with its state (``/proc``: stopped, running, sleeping) and
  the pool is ended by killing its workers (a stopped process cannot finish its task, and
  ``shutdown`` would wait for it forever). A worker that died (``BrokenProcessPool``) is named by
  its exit status.
- Nothing is written by the pool itself: the caller writes prediction files and reports only
  after the last result, so a run that ends here leaves no partial output behind as if whole.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from multiprocessing.process import BaseProcess
from multiprocessing.queues import SimpleQueue

StartQueue = SimpleQueue
"""The queue on which workers say which task they start: ``(task index, pid, time.time())``."""

RETRY = (
    "nothing was written; run the command again, or with --workers 1 to predict in this "
    "process alone"
)
"""What to do, the end of every :class:`PredictionWorkerError` line."""


class PredictionWorkerError(RuntimeError):
    """A prediction worker died or stopped answering; the message (one line) names it, the
    frame it held and what to do."""


@dataclass(frozen=True)
class Liveness:
    """How long prediction workers may go without a result (module docstring).

    Attributes:
        factor: A started task may take this many times this process's slowest seconds per
            sample, times its samples.
        floor_s: ... but at least this many seconds.
        start_s: Seconds a task may wait for any worker to start it before the first worker
            has started (their start: the interpreter, torch, the model).
        poll_s: How often the wait for a result looks at the workers.
    """

    factor: float = 20.0
    floor_s: float = 20.0
    start_s: float = 60.0
    poll_s: float = 0.25

    def __post_init__(self) -> None:
        for name in ("factor", "floor_s", "start_s", "poll_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"Liveness.{name} must be > 0, got {getattr(self, name)}")

    @classmethod
    def with_floor(cls, seconds: float) -> Liveness:
        """The default limits with ``floor_s = seconds`` and ``start_s = 3 * seconds`` (the
        evaluate command's ``--worker-timeout``)."""
        return cls(floor_s=seconds, start_s=3 * seconds)

    def task_limit(self, seconds_per_sample: float | None, samples: int) -> float:
        """Seconds a started task of ``samples`` samples may take, given this process's slowest
        measured seconds per sample (None: none measured yet: :attr:`floor_s`)."""
        if seconds_per_sample is None:
            return self.floor_s
        return max(self.floor_s, self.factor * seconds_per_sample * samples)


def process_state(pid: int) -> str:
    """A process's scheduling state as ``/proc/PID/stat`` gives it, in words ("stopped",
    "running", "sleeping", ...); "" where unknown (not Linux, or gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as handle:
            stat = handle.read()
    except OSError:
        return ""
    code = stat[stat.rfind(")") + 2 : stat.rfind(")") + 3]
    return {
        "R": "running",
        "S": "sleeping",
        "D": "waiting on the disk",
        "T": "stopped (SIGSTOP or Ctrl-Z)",
        "t": "stopped by a debugger",
        "Z": "exited",
    }.get(code, code)


def exit_words(code: int | None) -> str:
    """A process's exit status in words: "killed by SIGKILL", "exited with code 3"."""
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exited with code {code}"


class WorkerWatch:
    """What this process knows of its workers' progress (module docstring).

    Args:
        liveness: The limits.
        groups: The tasks' sample ids, by task index.
        processes: The pool's worker processes, pid -> process (read again at each look: the
            pool starts them as work comes, and its manager thread may empty the map once the pool
            breaks, so each look also keeps its own copy: :meth:`known`).
    """

    def __init__(
        self,
        liveness: Liveness,
        groups: Sequence[tuple[str, ...]],
        processes: Mapping[int, BaseProcess],
    ) -> None:
        self.liveness = liveness
        self.groups = groups
        self.processes = processes
        self._known: dict[int, BaseProcess] = {}
        self.started: dict[int, tuple[int, float]] = {}
        """task index -> (pid, time.time() it started)."""
        self.last_sign = time.time()
        """When a worker last started or finished a task (or the pool was made)."""
        self.any_started = False
        self.done: set[int] = set()
        self.workers_seen: set[int] = set()
        self.first_tasks: set[int] = set()
        """Tasks that were their worker's first (they load what a worker loads lazily)."""
        self.seconds_per_sample: float | None = None
        self._pids: dict[int, int] = {}  # pid -> worker number (1-based, in start order)

    def measured(self, seconds: float, samples: int) -> None:
        """This process predicted ``samples`` samples in ``seconds``: the slowest rate sets the
        limits."""
        rate = seconds / max(samples, 1)
        self.seconds_per_sample = max(rate, self.seconds_per_sample or 0.0)

    def known(self) -> dict[int, BaseProcess]:
        """Every worker process seen so far, pid -> process: the pool's map as it is now and as
        it was at the earlier looks (a broken pool's manager may have emptied it already)."""
        self._known.update(list(self.processes.items()))
        return dict(self._known)

    def heard(self, queue: StartQueue) -> None:
        """Read the workers' start messages."""
        self.known()
        while not queue.empty():
            task, pid, when = queue.get()
            if pid not in self.workers_seen:
                self.workers_seen.add(pid)
                self.first_tasks.add(task)
            if task not in self.done:  # a start read after its result came back
                self.started[task] = (pid, when)
            self.any_started = True
            self.last_sign = max(self.last_sign, when)

    def finished(self, task: int) -> None:
        """Task ``task``'s result came back (or it was cancelled, or failed)."""
        self.done.add(task)
        self.started.pop(task, None)
        self.last_sign = time.time()

    def _name(self, pid: int) -> str:
        for known in self.known():
            self._pids.setdefault(known, len(self._pids) + 1)
        number = self._pids.get(pid)
        count = max(len(self._pids), 1)
        return f"prediction worker {number or '?'} of {count} (pid {pid})"

    def _frames(self, task: int) -> str:
        ids = self.groups[task]
        return f"sample {ids[0]}" if len(ids) == 1 else f"samples {ids[0]}-{ids[-1]}"

    def overdue(self, task: int) -> PredictionWorkerError | None:
        """The error to end the run with when task ``task`` (the next result due) is past its
        limit; None while it is within it."""
        now = time.time()
        samples = len(self.groups[task])
        limit = self.liveness.task_limit(self.seconds_per_sample, samples)
        how = (
            f"{self.liveness.factor:g}x this process's {self.seconds_per_sample:.2f} s per "
            f"sample, at least {self.liveness.floor_s:g} s"
            if self.seconds_per_sample is not None
            else f"at least {self.liveness.floor_s:g} s"
        )
        if task in self.first_tasks and self.liveness.start_s > limit:
            limit = self.liveness.start_s
            how = "its worker's first task, which loads what a worker loads lazily"
        if task in self.started:
            pid, since = self.started[task]
            if now - since <= limit:
                return None
            state = process_state(pid)
            return PredictionWorkerError(
                f"{self._name(pid)} has returned nothing for {now - since:.0f} s on "
                f"{self._frames(task)} ({limit:.0f} s allowed: {how})"
                + (f"; it is {state}" if state else "")
                + f"; the workers were ended and {RETRY}"
            )
        allowed = limit if self.any_started else self.liveness.start_s
        if now - self.last_sign <= allowed:
            return None
        states = [
            f"{self._name(pid)}: {process_state(pid) or exit_words(p.exitcode)}"
            for pid, p in self.known().items()
        ]
        what = "since the last result" if self.any_started else "since the pool started"
        return PredictionWorkerError(
            f"no prediction worker started {self._frames(task)} in {now - self.last_sign:.0f} s "
            f"{what} ({allowed:.0f} s allowed; {'; '.join(states) or 'no worker started'}); "
            f"the workers were ended and {RETRY}"
        )

    def died(self, starts: StartQueue) -> PredictionWorkerError:
        """The error for a broken pool (a worker ended abruptly): the worker that died first
        (not killed by the pool's own SIGTERM of the others), its exit status and its frame
        (``starts`` read first; a message is one pipe write, whole or absent, so a killed
        worker leaves none half written)."""
        self.heard(starts)
        processes = self.known()
        deadline = time.monotonic() + 5.0  # the pool ends the others with SIGTERM: their codes
        for p in list(processes.values()):
            p.join(timeout=max(0.0, deadline - time.monotonic()))
        codes = {pid: p.exitcode for pid, p in processes.items()}
        dead = [pid for pid, code in codes.items() if code not in (None, -signal.SIGTERM)]
        dead = dead or [pid for pid, code in codes.items() if code is not None]
        if not dead:
            return PredictionWorkerError(f"a prediction worker ended abruptly; {RETRY}")
        parts = []
        for pid in dead:
            held = [task for task, (p, _) in self.started.items() if p == pid]
            at = f" while predicting {self._frames(min(held))}" if held else ""
            parts.append(f"{self._name(pid)} {exit_words(codes[pid])}{at}")
        hint = (
            " (SIGKILL is also what the kernel's out-of-memory killer sends: with less memory "
            "free, use fewer --workers)"
            if any(codes[pid] == -signal.SIGKILL for pid in dead)
            else ""
        )
        return PredictionWorkerError(f"{'; '.join(parts)}{hint}; {RETRY}")

    def end(self) -> None:
        """Kill every worker still alive (SIGKILL: a stopped process takes no other signal)."""
        for p in self.known().values():
            if p.exitcode is None:
                p.kill()


DEFAULT_LIVENESS = Liveness()
"""The limits a prediction run uses unless told otherwise."""

__all__ = [
    "DEFAULT_LIVENESS",
    "Liveness",
    "PredictionWorkerError",
    "StartQueue",
    "WorkerWatch",
    "exit_words",
    "process_state",
]
