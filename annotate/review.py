"""Reviewing saved pairs: a reviewer's verdict on a version of a pair, in the manifest.

:func:`record_review` appends a ``review`` line to the store's manifest (the one append,
:meth:`annotate.manifest.Manifest.append`, under the store's lock): the pair's id, the version
reviewed, the verdict (``approved``, ``rejected``, or ``fixed``: the reviewer saved an edit and
approves the version it wrote), the reviewer's name and an optional note. Nothing else changes: a
review is no new version, and a pair's files are untouched. Reviewing a version that is no longer
the pair's current one (someone saved an edit meanwhile) is refused with
:class:`~annotate.errors.ConflictError`, and so is a verdict on a version someone else decided
after the reviewer was shown it (``seen``: the message says who decided what). A verdict is an
idempotent request (``request``): repeating its key writes nothing and returns the first line.

What the reviews say (a pair's current version and its latest review; the approved ids of a
split for training and evaluation): :mod:`scenes.talk2radar.reviews`, the one reader.
"""

from __future__ import annotations

import threading
import uuid
import weakref
from dataclasses import dataclass

from annotate.errors import ConflictError, StoreError
from annotate.manifest import Action, ManifestRecord, conflict_message
from annotate.requests import RequestLog
from annotate.store import AnnotationStore
from annotate.validation import clean_annotator, clean_field
from scenes.talk2radar.layout import format_id
from scenes.talk2radar.reviews import VERDICTS, PairState, pair_states
from scenes.utils.text_policy import NOTE

ANY_REVIEW = "*"
"""``seen`` of :func:`record_review` that checks nothing about earlier reviews."""

REMEMBERED_REVIEWS = 256
"""Successful review requests a store remembers (:func:`record_review`)."""


@dataclass(frozen=True)
class ReviewResult:
    """What :func:`record_review` recorded: the manifest line, and whether the request was a
    repeat (nothing written this time; ``record`` is the first request's line)."""

    record: ManifestRecord
    repeated: bool = False


def latest_review(
    store: AnnotationStore, sample_id: str | int, version: int
) -> ManifestRecord | None:
    """The latest review line of version ``version`` of a pair (None: none)."""
    lines = [r for r in store.manifest.reviews(sample_id) if r.version == version]
    return lines[-1] if lines else None


_REQUESTS: weakref.WeakKeyDictionary[AnnotationStore, RequestLog[ReviewResult]] = (
    weakref.WeakKeyDictionary()
)
_REQUESTS_LOCK = threading.Lock()


def _requests(store: AnnotationStore) -> RequestLog[ReviewResult]:
    """The review requests of one store by key (kept as long as the store)."""
    with _REQUESTS_LOCK:
        log = _REQUESTS.get(store)
        if log is None:
            log = _REQUESTS[store] = RequestLog(REMEMBERED_REVIEWS)
        return log


def record_review(
    store: AnnotationStore,
    sample_id: str | int,
    verdict: str,
    reviewer: str,
    *,
    version: int,
    note: str = "",
    seen: str | None = ANY_REVIEW,
    request: str | None = None,
) -> ReviewResult:
    """Record a review of version ``version`` of a pair (see the module docstring).

    Args:
        seen: The ``op`` of the latest review of that version the reviewer was shown (None:
            they saw none); a review recorded since is a decision they did not see, and this
            one is refused with who decided what. :data:`ANY_REVIEW`: no such check.
        request: The caller's key of this verdict (the app's: its tab, the pair and version
            shown, ``seen`` and the verdict): a request with the key of one running waits for
            it, one of one that succeeded gets its result with ``repeated`` and writes nothing
            (:class:`annotate.requests.RequestLog`), so three clicks within milliseconds write
            one line.

    Raises:
        ValueError: ``verdict`` is not one of :data:`scenes.talk2radar.reviews.VERDICTS`, or ``request``
            was used before for another verdict.
        ValidationError: the text policy refuses the reviewer's name or the note.
        StoreError: the pair is not listed in any split (deleted, or never saved).
        ConflictError: ``version`` is not the pair's current version, or a review of it was
            recorded after ``seen``.
    """
    if verdict not in VERDICTS:
        raise ValueError(f"verdict must be one of {', '.join(VERDICTS)}, got {verdict!r}")
    sid = format_id(sample_id)
    reviewer = clean_annotator(reviewer)  # the one text policy (scenes.utils.text_policy)
    note = clean_field(note, NOTE, "note")

    def record() -> ReviewResult:
        with store.transactions.locked():
            splits = store.splits_of(sid)
            if not splits:
                raise StoreError(f"sample {sid} is not listed in any split of {store.path}")
            current = store.version(sid)
            if current != version:
                raise ConflictError(conflict_message(sid, version, store.history(sid)))
            latest = latest_review(store, sid, version)
            if seen != ANY_REVIEW and (latest.op if latest is not None else None) != seen:
                raise ConflictError(decided_message(latest, seen))
            line = ManifestRecord(
                action=Action.REVIEW,
                sample_id=sid,
                version=current,
                time=store.clock(),
                annotator=reviewer,
                op=uuid.uuid4().hex,
                splits=splits,
                verdict=verdict,
                note=note,
            )
            store.manifest.append(line.to_json())
        return ReviewResult(line)

    if request is None:
        return record()
    what = (sid, version, verdict, reviewer, note, seen)
    result, repeated = _requests(store).run(request, what, record)
    return ReviewResult(result.record, repeated=True) if repeated else result


def decided_message(latest: ManifestRecord | None, seen: str | None) -> str:
    """Why a verdict is refused when the version's reviews changed since the reviewer saw them."""
    if latest is None:  # the review seen is gone: the manifest was rewritten by hand
        return f"the review {seen} shown is no longer in the manifest; reopen the pair"
    return (
        f"pair {latest.sample_id} version {latest.version} was {latest.verdict} by "
        f"{latest.annotator} at {latest.time}, after it was opened here; nothing was recorded "
        "(reopen it and decide again if you disagree)"
    )


def review_states(store: AnnotationStore) -> dict[str, PairState]:
    """Every pair's current version and the latest review of it
    (:func:`scenes.talk2radar.reviews.pair_states` of the store's manifest)."""
    return pair_states(r.to_json() for r in store.records())
