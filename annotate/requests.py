"""Idempotent requests: a second request with the same key gets the first one's result.

:class:`RequestLog` backs :meth:`annotate.AnnotationStore.save` (the key is the caller's, e.g. the
version of its editor's draft): a scripted double click sends two saves of one draft within
milliseconds, on two threads, and must save once. A request whose key is running waits for it;
one whose key succeeded gets that result without running; a failure is forgotten (the request
may be tried again once, say, disk space is freed). The last ``size`` successes are remembered.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

R = TypeVar("R")


@dataclass
class _Entry(Generic[R]):
    what: object
    done: threading.Event = field(default_factory=threading.Event)
    result: R | None = None
    error: BaseException | None = None


class RequestLog(Generic[R]):
    """Requests by key (see the module docstring); thread-safe.

    Args:
        size: Successful requests remembered.
    """

    def __init__(self, size: int = 256) -> None:
        self.size = size
        self._entries: OrderedDict[Hashable, _Entry[R]] = OrderedDict()
        self._lock = threading.Lock()

    def run(self, key: Hashable, what: object, fn: Callable[[], R]) -> tuple[R, bool]:
        """``(fn(), False)`` for a new key; ``(first result, True)`` for a key that ran or runs
        (waiting for it); the first's exception when it fails while this one waits.

        Raises:
            ValueError: ``key`` was used for another ``what`` (compared with ``==``).
        """
        with self._lock:
            entry = self._entries.get(key)
            first = entry is None
            if entry is None:
                entry = self._entries[key] = _Entry(what)
            elif entry.what != what:
                raise ValueError(f"request {key!r} was made before for something else")
        if not first:
            entry.done.wait()
            if entry.error is not None:
                raise entry.error
            return entry.result, True  # type: ignore[return-value]
        try:
            entry.result = fn()
        except BaseException as exc:
            entry.error = exc
            with self._lock:
                self._entries.pop(key, None)
            raise
        finally:
            entry.done.set()
        with self._lock:
            while len(self._entries) > self.size:
                self._entries.popitem(last=False)
        return entry.result, False
