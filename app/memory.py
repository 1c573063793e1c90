"""What a browser leaves behind when it goes: collected soon after, and handed back to the system.

Why it is needed (measured, see docs/PERFORMANCE.md "Memory per connection"): a session's GUI
callbacks are closures over the session, which holds its viser client, whose GUI holds the
callbacks: a reference cycle, as in any callback-style GUI. CPython frees a cycle only in a
collection of the generation it has reached, and a session lives long enough to reach the
oldest one, whose full collections are rare in a process holding a model (hundreds of thousands
of long-lived objects: a full collection waits for a quarter as many new survivors). Meanwhile
each browser that left kept its point buffers, camera images and viser's per-client state,
about 9 MB: the server grew from 531 MB to 1.6 GB over 125 connections. Breaking every cycle by
hand would be fragile (any new callback brings it back), so the app collects.

:class:`MemoryReaper`: a daemon thread that, after a browser left (:meth:`MemoryReaper.schedule`),
waits :attr:`~MemoryReaper.delay` seconds (disconnects in that time share one collection), runs a
full ``gc.collect()`` (about 0.2 s of the interpreter on the 2-core machine, so at most one per
:attr:`~MemoryReaper.min_interval` seconds) and then glibc's ``malloc_trim(0)``, which returns the
freed pages of every malloc arena (numpy buffers freed by viser's and the model's worker threads
stay in their threads' arenas otherwise). Where there is no glibc the trim is skipped.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)


def _load_malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None (another C library)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


_MALLOC_TRIM = _load_malloc_trim()


def release_memory() -> int:
    """A full garbage collection, then ``malloc_trim(0)`` where glibc has it; returns the number
    of unreachable objects found."""
    found = gc.collect()
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)
    return found


class MemoryReaper:
    """Collects what departed browsers left (see the module docstring).

    Args:
        delay: Seconds between a disconnect and the collection it asks for.
        min_interval: Fewest seconds between two collections.
    """

    def __init__(self, delay: float = 0.5, min_interval: float = 2.0) -> None:
        self.delay = delay
        self.min_interval = min_interval
        self.collections = 0
        """Collections run so far."""
        self._wanted = threading.Event()
        self._stopped = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Start the thread (idempotent)."""
        if self._thread is None or not self._thread.is_alive():
            self._stopped.clear()
            self._thread = threading.Thread(target=self._run, name="talk2pc-reaper", daemon=True)
            self._thread.start()

    def schedule(self) -> None:
        """A browser left: collect soon."""
        self._wanted.set()

    def stop(self) -> None:
        """End the thread (a collection under way finishes)."""
        self._stopped.set()
        self._wanted.set()

    def _run(self) -> None:
        last = -float("inf")
        while True:
            self._wanted.wait()
            wait = max(self.delay, last + self.min_interval - time.monotonic())
            if self._stopped.wait(wait):
                return
            self._wanted.clear()
            start = time.monotonic()
            found = release_memory()
            last = time.monotonic()
            self.collections += 1
            log.debug("collected %d objects in %.0f ms", found, (last - start) * 1000.0)
