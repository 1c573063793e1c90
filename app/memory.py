"""What a browser leaves behind when it goes: collected soon after, and handed back to the system.

Why it is needed: a session's GUI callbacks are closures over the session, which holds its viser
client, whose GUI holds the callbacks: a reference cycle, as in any callback-style GUI. CPython
frees a cycle only in a collection of the generation it has reached, and a session lives long
enough to reach the oldest one, whose full collections are rare in a process holding a model
(hundreds of thousands of long-lived objects: a full collection waits for a quarter as many new
survivors). Meanwhile each browser that left kept its point buffers, camera images and viser's
per-client state (``python -m bench.perf.soak --baseline``: the server before grew from 635 MB to
1,752 MB over 300 visits; docs/PERFORMANCE.md, "Memory per connection"). Breaking every cycle by
hand would be fragile (any new callback brings it back), so the app collects.

:class:`MemoryReaper`: a daemon thread that, after a browser left (:meth:`MemoryReaper.schedule`),
waits :attr:`~MemoryReaper.delay` seconds (disconnects in that time share one collection) and runs
a full ``gc.collect()`` (at most one per :attr:`~MemoryReaper.min_interval` seconds). Once no
browser has left for :attr:`~MemoryReaper.quiet` seconds it also calls glibc's
``malloc_trim(0)``, which returns the freed pages of every malloc arena to the system (numpy
buffers freed by viser's and the model's worker threads stay in their threads' arenas otherwise).
Not after every collection: the next visitor's buffers would fault those pages in again, which
made visits under churn clearly slower; freed memory is reused meanwhile. Where there is no glibc the trim is skipped.

:func:`freeze_startup_objects` (``AppConfig.freeze_startup``, which ``launch.py`` sets) makes the
collections cheap: what exists before the first browser connects is never scanned again.
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


def trim_heap() -> bool:
    """``malloc_trim(0)`` where glibc has it; returns whether it ran."""
    if _MALLOC_TRIM is None:
        return False
    _MALLOC_TRIM(0)
    return True


def freeze_startup_objects() -> None:
    """Collect, then move every object alive now to CPython's permanent generation
    (``gc.freeze``), so that later full collections (the reaper's) only scan what was made
    since: the model, the server and the caches are never garbage, and scanning them made each
    collection take 0.2-0.5 s on the 2-core machine. For the process that serves (``launch.py``);
    an object frozen here that later becomes cyclic garbage is never freed, so it is called
    before any browser connects."""
    gc.collect()
    gc.freeze()


class MemoryReaper:
    """Collects what departed browsers left (see the module docstring).

    Args:
        delay: Seconds between a disconnect and the collection it asks for.
        min_interval: Fewest seconds between two collections.
        quiet: Seconds without a disconnect after a collection before the heap is trimmed.
    """

    def __init__(self, delay: float = 0.5, min_interval: float = 2.0, quiet: float = 5.0) -> None:
        self.delay = delay
        self.min_interval = min_interval
        self.quiet = quiet
        self.collections = 0
        """Collections run so far."""
        self.trims = 0
        """Heap trims run so far."""
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
            found = gc.collect()
            last = time.monotonic()
            self.collections += 1
            log.debug("collected %d objects in %.0f ms", found, (last - start) * 1000.0)
            if not self._wanted.wait(self.quiet) and not self._stopped.is_set():
                self.trims += trim_heap()
