"""Reviewing saved pairs: a reviewer's verdict on a version of a pair, in the manifest.

:func:`record_review` appends a ``review`` line to the store's manifest (the one append,
:meth:`annotate.manifest.Manifest.append`, under the store's lock): the pair's id, the version
reviewed, the verdict (``approved``, ``rejected``, or ``fixed``: the reviewer saved an edit and
approves the version it wrote), the reviewer's name and an optional note. Nothing else changes: a
review is no new version, and a pair's files are untouched. Reviewing a version that is no longer
the pair's current one (someone saved an edit meanwhile) is refused with
:class:`~annotate.errors.ConflictError`.

What the reviews say (a pair's current version and its latest review; the approved ids of a
split for training and evaluation): :mod:`scenes.talk2radar.reviews`, the one reader.
"""

from __future__ import annotations

import uuid

from annotate.errors import ConflictError, StoreError
from annotate.manifest import Action, ManifestRecord, conflict_message
from annotate.store import AnnotationStore
from annotate.validation import clean_annotator, clean_field
from scenes.talk2radar.layout import format_id
from scenes.talk2radar.reviews import VERDICTS, PairState, pair_states
from scenes.utils.text_policy import NOTE


def record_review(
    store: AnnotationStore,
    sample_id: str | int,
    verdict: str,
    reviewer: str,
    *,
    version: int,
    note: str = "",
) -> ManifestRecord:
    """Record a review of version ``version`` of a pair (see the module docstring).

    Raises:
        ValueError: ``verdict`` is not one of :data:`scenes.talk2radar.reviews.VERDICTS`.
        ValidationError: the text policy refuses the reviewer's name or the note.
        StoreError: the pair is not listed in any split (deleted, or never saved).
        ConflictError: ``version`` is not the pair's current version.
    """
    if verdict not in VERDICTS:
        raise ValueError(f"verdict must be one of {', '.join(VERDICTS)}, got {verdict!r}")
    sid = format_id(sample_id)
    reviewer = clean_annotator(reviewer)  # the one text policy (scenes.utils.text_policy)
    note = clean_field(note, NOTE, "note")
    with store.transactions.locked():
        splits = store.splits_of(sid)
        if not splits:
            raise StoreError(f"sample {sid} is not listed in any split of {store.path}")
        current = store.version(sid)
        if current != version:
            raise ConflictError(conflict_message(sid, version, store.history(sid)))
        record = ManifestRecord(
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
        store.manifest.append(record.to_json())
    return record


def review_states(store: AnnotationStore) -> dict[str, PairState]:
    """Every pair's current version and the latest review of it
    (:func:`scenes.talk2radar.reviews.pair_states` of the store's manifest)."""
    return pair_states(r.to_json() for r in store.records())
