"""Reviews of saved pairs (issue 19.4): the manifest's ``review`` lines (annotate.review) and the
approved ids training and evaluation restrict to (scenes.talk2radar.reviews.approved_ids)."""

from __future__ import annotations

import pytest

from annotate import AnnotationStore, ConflictError, SourceFrame, StoreError, default_box
from annotate.draft import Draft
from annotate.review import record_review, review_states
from scenes.talk2radar.layout import manifest_file
from scenes.talk2radar.reviews import approved_ids


def _store_with_two_pairs(tmp_path, write_tiny_root):
    root = write_tiny_root(tmp_path / "root", frames=1)
    store = AnnotationStore(root)
    ids = []
    for x in (12.0, 20.0):
        draft = Draft().add_box(default_box("Car", x, 2.0), "Car").set_prompt(f"the car at {x}")
        ids.append(store.save(draft, SourceFrame.from_root(root, 0), annotator="ada").sample_id)
    return root, store, ids


def test_reviews_are_manifest_lines_and_only_approved_current_versions_count(
    tmp_path, write_tiny_root
) -> None:
    root, store, (a, b) = _store_with_two_pairs(tmp_path, write_tiny_root)
    assert approved_ids(root, "train") == ()
    record_review(store, a, "approved", "rita", version=1)
    record_review(store, b, "rejected", "rita", version=1, note="the box is  too long")
    assert approved_ids(root, "train") == (a,)
    assert approved_ids(root, "test") == ()  # the tiny root's own samples were never reviewed
    states = review_states(store)
    assert states[b].review.verdict == "rejected" and states[b].review.note == "the box is too long"
    # A review changes no version and no listed state; the history holds the changes only.
    assert store.version(a) == 1 and [p.annotator for p in store.pairs()] == ["ada", "ada"]
    assert [r.action.value for r in store.history(a)] == ["create"]

    # The fix: a new version, approved by its reviewer; the old verdict no longer counts.
    fixed = store.open(b)
    fixed = fixed.set_box(fixed.boxes[0].box_id, default_box("Car", 20.5, 2.0))
    version = store.save(fixed, annotator="rita").version
    assert version == 2 and approved_ids(root, "train") == (a,)
    record_review(store, b, "fixed", "rita", version=version)
    assert approved_ids(root, "train") == (a, b)

    # An edit after an approval is a new, unreviewed version.
    edited = store.open(a).set_prompt("the nearer car")
    store.save(edited, annotator="ada")
    assert approved_ids(root, "train") == (b,)
    with pytest.raises(ConflictError, match="now version 2"):
        record_review(store, a, "approved", "rita", version=1)
    with pytest.raises(ValueError, match="verdict must be one of"):
        record_review(store, a, "fine", "rita", version=2)
    store.delete(b, annotator="ada")
    with pytest.raises(StoreError, match="not listed"):
        record_review(store, b, "approved", "rita", version=3)
    assert approved_ids(root, "train") == ()

    lines = manifest_file(root).read_text().splitlines()
    review = next(line for line in lines if '"review"' in line)
    assert '"verdict": "approved"' in review and '"annotator": "rita"' in review
    with manifest_file(root).open("a") as f:
        f.write('{"action": "review", "sample_id": "0')  # a torn last line is skipped
    record_review(store, a, "approved", "rita", version=2)
    assert approved_ids(root, "train") == (a,)
