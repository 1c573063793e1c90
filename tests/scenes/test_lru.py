"""scenes.utils.lru.LRUCache: recency order, the count and byte bounds, removal, threads."""

from __future__ import annotations

import threading

import pytest

from scenes.utils.lru import LRUCache


def test_get_marks_used_and_the_least_recently_used_goes_first() -> None:
    cache: LRUCache[str, int] = LRUCache(2)
    cache.put("a", 1)
    cache.put("b", 2)
    assert cache.get("a") == 1  # "a" is now the most recently used
    cache.put("c", 3)
    assert cache.keys() == ["a", "c"] and "b" not in cache
    assert cache.get("b") is None and cache.get("b", -1) == -1
    assert "a" in cache and cache.keys() == ["a", "c"]  # ``in`` does not mark used
    cache.put("a", 10)  # replacing keeps one entry and marks it used
    assert len(cache) == 2 and cache.get("a") == 10 and cache.keys() == ["c", "a"]


def test_zero_items_keeps_nothing_and_shrinking_evicts() -> None:
    off: LRUCache[str, int] = LRUCache(0)
    off.put("a", 1)
    assert len(off) == 0 and off.get("a") is None
    cache: LRUCache[int, str] = LRUCache(4)
    for i in range(4):
        cache.put(i, str(i))
    cache.max_items = 1
    assert cache.keys() == [3] and cache.max_items == 1
    cache.max_items = 3
    cache.put(4, "4")
    assert cache.keys() == [3, 4]


def test_byte_bound_counts_sizes_and_refuses_an_entry_too_large() -> None:
    cache: LRUCache[str, bytes] = LRUCache(10, max_bytes=10, size_of=len)
    cache.put("a", b"12345")
    cache.put("b", b"1234")
    assert cache.nbytes == 9 and len(cache) == 2
    cache.put("c", b"12")  # 11 bytes: "a" (the least recently used) goes
    assert cache.keys() == ["b", "c"] and cache.nbytes == 6
    cache.put("b", b"1")  # a replaced value's bytes are given back
    assert cache.nbytes == 3
    cache.put("huge", b"x" * 11)  # larger than the bound alone: nothing of it is kept
    assert "huge" not in cache and cache.nbytes == 0 and len(cache) == 0


def test_pop_discard_if_and_clear() -> None:
    cache: LRUCache[int, bytes] = LRUCache(5, max_bytes=100, size_of=len)
    for i in range(5):
        cache.put(i, b"x" * i)
    assert cache.pop(4) == b"xxxx" and cache.pop(4) is None and cache.nbytes == 6
    assert cache.discard_if(lambda key, value: key % 2 == 1) == 2
    assert cache.keys() == [0, 2] and cache.nbytes == 2 and list(cache) == [0, 2]
    cache.clear()
    assert len(cache) == 0 and cache.nbytes == 0


def test_bad_bounds_are_refused() -> None:
    with pytest.raises(ValueError, match="max_items"):
        LRUCache(-1)
    with pytest.raises(ValueError, match="size_of"):
        LRUCache(3, max_bytes=10)
    with pytest.raises(ValueError, match="max_bytes"):
        LRUCache(3, max_bytes=-1, size_of=len)
    cache: LRUCache[int, int] = LRUCache(3)
    with pytest.raises(ValueError, match="max_items"):
        cache.max_items = -2


def test_threads_sharing_a_cache_keep_its_bounds() -> None:
    cache: LRUCache[int, bytes] = LRUCache(8, max_bytes=64, size_of=len)
    errors: list[BaseException] = []

    def work(offset: int) -> None:
        try:
            for i in range(2000):
                key = (offset + i) % 20
                if cache.get(key) is None:
                    cache.put(key, b"x" * (key % 9))
                if i % 50 == 0:
                    cache.discard_if(lambda k, _: k == offset)
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(t,)) for t in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(cache) <= 8 and cache.nbytes <= 64
    assert cache.nbytes == sum(len(cache.get(k) or b"") for k in cache)
