"""The annotation store's errors, and how a filesystem error becomes one.

Every store method raises a :class:`StoreError` (or a subclass) with a one-line message, never a
bare ``OSError``; a full disk (``ENOSPC``, ``EDQUOT``) anywhere in an exception's chain is a
:class:`DiskFullError`.
"""

from __future__ import annotations

import contextlib
import errno
from collections.abc import Iterator


class StoreError(RuntimeError):
    """An annotation store operation failed; the message says what and what to do."""


class SaveError(StoreError):
    """A save, edit or delete failed and was undone (or will be completed: see the message)."""


class DiskFullError(SaveError):
    """The disk filled up during an operation; it was undone and nothing is half-visible."""


class ConflictError(StoreError):
    """The pair changed since the draft was opened (another client saved or deleted it)."""


class SplitError(StoreError, ValueError):
    """The split to save into is not one the store offers (nothing was written)."""


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` or an exception it was raised from is a full disk (or quota)."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        seen.add(id(cur))
        if isinstance(cur, OSError) and cur.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        cur = cur.__cause__ or cur.__context__
    return False


def one_line(text: str) -> str:
    """``text`` with every run of whitespace (line breaks included) made one space."""
    return " ".join(str(text).split())


def fs_error(exc: OSError | UnicodeError, what: str) -> StoreError:
    """A store error for a filesystem error met while doing ``what``."""
    if is_disk_full(exc):
        return DiskFullError(f"the disk is full: {what} failed. Free some space and try again.")
    if isinstance(exc, OSError):
        where = f" ({exc.filename})" if exc.filename else ""
        reason = exc.strerror or str(exc)
    else:
        where, reason = "", str(exc)
    return StoreError(one_line(f"{what} failed{where}: {reason}"))


@contextlib.contextmanager
def fs_errors(what: str) -> Iterator[None]:
    """Turn a bare ``OSError`` / ``UnicodeError`` raised inside into a :class:`StoreError`."""
    try:
        yield
    except (OSError, UnicodeError) as exc:
        raise fs_error(exc, what) from exc


def operation_error(exc: BaseException, what: str, outcome: str) -> SaveError:
    """The error of an operation that failed with ``exc`` and was then undone or completed
    (``outcome`` says which)."""
    if is_disk_full(exc):
        return DiskFullError(
            f"the disk is full: {what} failed; {outcome}. Free some space and try again."
        )
    return SaveError(f"{what} failed ({type(exc).__name__}: {exc}); {outcome}")


__all__ = [
    "ConflictError",
    "DiskFullError",
    "SaveError",
    "SplitError",
    "StoreError",
    "fs_error",
    "fs_errors",
    "is_disk_full",
    "one_line",
    "operation_error",
]
