"""The one least-recently-used cache: bounded by a count of entries and, optionally, by bytes.

Every cache of the project that keeps "the last few" of something uses it: the app's loaded
frames (:class:`app.serving.navigation.FrameStore`) and encoded scenes (:class:`app.engine.GroundingEngine`),
prediction's encoded scenes and the text encoder's token features (``model/``). It lives in
``scenes/`` because every package may import ``scenes`` and it imports nothing of the project.

- :meth:`LRUCache.get` marks an entry used; ``in`` (:meth:`LRUCache.__contains__`) does not.
- :meth:`LRUCache.put` stores an entry as the most recently used, then drops the least recently
  used ones while more than ``max_items`` entries (or more than ``max_bytes`` bytes, as counted
  by ``size_of``) are kept. ``max_items = 0`` keeps nothing (a disabled cache); an entry larger
  than ``max_bytes`` on its own is not kept either.
- Thread-safe: every method holds the cache's one lock, so browsers' threads and the model's
  worker threads may share a cache; a value is computed outside it (check, compute, put).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from typing import Generic, TypeVar, overload

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")
D = TypeVar("D")


class LRUCache(Generic[K, V]):
    """A least-recently-used mapping (see the module docstring).

    Args:
        max_items: Most entries kept (``>= 0``; 0 keeps none).
        max_bytes: Most bytes kept, summed over the entries by ``size_of`` (None: no byte bound).
        size_of: Bytes of one value (needed with ``max_bytes``; read once, when it is put).

    Raises:
        ValueError: a negative bound, or ``max_bytes`` without ``size_of``.
    """

    def __init__(
        self,
        max_items: int,
        max_bytes: int | None = None,
        size_of: Callable[[V], int] | None = None,
    ) -> None:
        if max_bytes is not None and (max_bytes < 0 or size_of is None):
            raise ValueError(
                f"LRUCache: max_bytes must be >= 0 and come with size_of, got {max_bytes}"
            )
        self._max_items = _check_items(max_items)
        self.max_bytes = max_bytes
        self._size_of = size_of
        self._entries: OrderedDict[K, tuple[V, int]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    @property
    def max_items(self) -> int:
        """Most entries kept; setting it drops the least recently used ones beyond it."""
        return self._max_items

    @max_items.setter
    def max_items(self, value: int) -> None:
        with self._lock:
            self._max_items = _check_items(value)
            self._evict()

    @property
    def nbytes(self) -> int:
        """Bytes of the kept entries (0 without ``size_of``)."""
        return self._bytes

    def __len__(self) -> int:
        return len(self._entries)

    def __contains__(self, key: object) -> bool:
        """Whether ``key`` is kept (it is not marked used)."""
        with self._lock:
            return key in self._entries

    @overload
    def get(self, key: K) -> V | None: ...

    @overload
    def get(self, key: K, default: D) -> V | D: ...

    def get(self, key: K, default: object = None) -> object:
        """The value of ``key``, marked most recently used; ``default`` when it is not kept."""
        with self._lock:
            entry = self._entries.get(key)
            if entry is None:
                return default
            self._entries.move_to_end(key)
            return entry[0]

    def put(self, key: K, value: V) -> None:
        """Keep ``value`` under ``key`` as the most recently used entry (replacing an old one),
        then drop the least recently used entries beyond the bounds."""
        size = self._size_of(value) if self._size_of is not None else 0
        with self._lock:
            old = self._entries.pop(key, None)
            if old is not None:
                self._bytes -= old[1]
            self._entries[key] = (value, size)
            self._bytes += size
            self._evict()

    def pop(self, key: K, default: V | None = None) -> V | None:
        """Remove ``key``; its value, or ``default`` when it was not kept."""
        with self._lock:
            entry = self._entries.pop(key, None)
            if entry is None:
                return default
            self._bytes -= entry[1]
            return entry[0]

    def discard_if(self, stale: Callable[[K, V], bool]) -> int:
        """Remove every entry for which ``stale(key, value)`` holds; returns how many."""
        with self._lock:
            gone = [k for k, (v, _) in self._entries.items() if stale(k, v)]
            for key in gone:
                self._bytes -= self._entries.pop(key)[1]
            return len(gone)

    def clear(self) -> None:
        """Remove every entry."""
        with self._lock:
            self._entries.clear()
            self._bytes = 0

    def keys(self) -> list[K]:
        """The kept keys, least recently used first (a copy)."""
        with self._lock:
            return list(self._entries)

    def __iter__(self) -> Iterator[K]:
        return iter(self.keys())

    def _evict(self) -> None:
        """Drop the least recently used entries beyond the bounds; hold the lock."""
        while len(self._entries) > self._max_items or (
            self.max_bytes is not None and self._bytes > self.max_bytes
        ):
            _, (_, size) = self._entries.popitem(last=False)
            self._bytes -= size


def _check_items(max_items: int) -> int:
    if max_items < 0:
        raise ValueError(f"LRUCache: max_items must be >= 0, got {max_items}")
    return int(max_items)


__all__ = ["LRUCache"]
