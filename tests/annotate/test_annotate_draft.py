"""Drafts, their undo / redo history, and validation messages."""

from __future__ import annotations

import math

import numpy as np
import pytest

from annotate import (
    Draft,
    DraftEditor,
    DraftError,
    History,
    Severity,
    ValidationConfig,
    ValidationError,
    changed_box,
    default_box,
    is_pristine,
    proposals,
    validate,
)
from scenes.geometry.calib import vod_lidar_calibration

CAR = (12.0, 3.0, -0.95, 4.2, 1.8, 1.5, 0.4)
PED = (20.0, -5.0, -0.85, 0.7, 0.6, 1.7, -2.9)


# ------------------------------------------------------------------------------------------ draft


def test_operations_return_new_snapshots() -> None:
    empty = Draft()
    one = empty.add_box(CAR, "Car")
    assert empty.boxes == () and len(one.boxes) == 1
    moved = one.move_box(0, 14.0, 2.0)
    assert one.get(0).box[:2] == (12.0, 3.0) and moved.get(0).box[:3] == (14.0, 2.0, -0.95)
    with pytest.raises(AttributeError):
        moved.prompt = "x"  # frozen


def test_box_ids_are_stable_across_deletions() -> None:
    d = Draft().add_box(CAR, "Car").add_box(PED, "Pedestrian").add_box(CAR, "Cyclist")
    d = d.delete_box(1)
    assert d.box_ids == (0, 2) and d.classes == ("Car", "Cyclist")
    d = d.add_box(PED, "Pedestrian")
    assert d.box_ids == (0, 2, 3)  # a deleted id is not reused
    with pytest.raises(DraftError, match=r"no box with id 1 .*\[0, 2, 3\]"):
        d.move_box(1, 0.0, 0.0)


def test_rotate_wraps_and_resize_keeps_the_bottom() -> None:
    d = Draft().add_box(CAR, "Car").rotate_box(0, 3.0 * math.pi / 2.0)
    assert d.get(0).box[6] == pytest.approx(-math.pi / 2.0)
    r = d.resize_box(0, 4.5, 1.9, 2.0)
    bottom_before = CAR[2] - CAR[5] / 2.0
    *_, z, length, width, height, _ = r.get(0).box
    assert (length, width, height) == (4.5, 1.9, 2.0)
    assert z - height / 2.0 == pytest.approx(bottom_before)
    centred = d.resize_box(0, 4.5, 1.9, 2.0, keep_bottom=False)
    assert centred.get(0).box[2] == CAR[2]


def test_impossible_values_are_refused_but_typed_mistakes_are_kept() -> None:
    d = Draft().add_box(CAR, "Car")
    with pytest.raises(DraftError, match="finite"):
        d.move_box(0, float("nan"), 1.0)
    with pytest.raises(DraftError, match="7 values"):
        d.add_box((1.0, 2.0, 3.0), "Car")
    # A negative size or an unknown class is kept for validation to report.
    kept = d.resize_box(0, -1.0, 1.8, 1.5).set_class(0, "Truck")
    assert kept.get(0).box[3] == -1.0 and kept.get(0).cls == "Truck"


def test_adding_a_box_clears_refers_to_nothing() -> None:
    d = Draft().set_refers_to_nothing(True)
    assert d.refers_to_nothing
    assert not d.add_box(CAR, "Car").refers_to_nothing


def test_json_round_trip() -> None:
    d = Draft(sample_id="00012", base_version=3).add_box(CAR, "Car").add_box(PED, "Pedestrian")
    d = d.delete_box(0).set_prompt("the pedestrian")
    assert Draft.from_json(d.to_json()) == d


def test_from_boxes_and_array_views() -> None:
    d = Draft.from_boxes(np.array([CAR, PED]), ["Car", "Pedestrian"], "two")
    np.testing.assert_allclose(d.box_array, [CAR, PED])
    assert d.next_box_id == 2 and d.box_array.dtype == np.float64
    assert Draft().box_array.shape == (0, 7)


def test_default_box_stands_on_the_ground() -> None:
    box = default_box("Car", 10.0, -2.0, ground_z=-1.7, yaw=4.0)
    # The class's mean size, its one home (scenes.geometry.classes): a VoD car is 1.6 m high,
    # not the 1.5 m of annotate.draft's former table of its own.
    assert box[:2] == (10.0, -2.0) and box[3:6] == (4.2, 1.8, 1.6)
    assert box[2] - box[5] / 2.0 == pytest.approx(-1.7)
    assert box[6] == pytest.approx(4.0 - 2.0 * math.pi)
    assert default_box("Pedestrian", 5.0, 0.0)[2] == pytest.approx(-1.7 + 1.75 / 2.0)


# ------------------------------------------------------------------------------------------ history


def test_undo_redo_sequence() -> None:
    editor = DraftEditor()
    a = editor.add_box(CAR, "Car")
    editor.set_prompt("the car")
    editor.move_box(a, 13.0, 3.0)
    b = editor.add_box(PED, "Pedestrian")
    editor.set_class(b, "Cyclist")
    assert editor.history.undo_label == "box 2 -> Cyclist"

    assert editor.undo().get(b).cls == "Pedestrian"
    assert editor.undo().box_ids == (0,)
    assert editor.undo().get(a).box[0] == 12.0
    assert editor.undo().prompt == ""
    assert editor.undo() == Draft()
    assert not editor.history.can_undo
    assert editor.undo() == Draft()  # no-op at the start

    assert editor.redo().box_ids == (0,)
    assert editor.redo().prompt == "the car"
    assert editor.history.redo_label == "move box 1"
    # A new edit after undos drops the redo branch.
    editor.delete_box(a)
    assert not editor.history.can_redo
    assert editor.redo().boxes == ()
    assert editor.undo().prompt == "the car" and editor.draft.box_ids == (0,)


def test_unchanged_edit_is_not_recorded_and_merge_keys_fold_drags() -> None:
    editor = DraftEditor()
    a = editor.add_box(CAR, "Car")
    editor.move_box(a, 12.0, 3.0)  # same place: nothing recorded
    assert len(editor.history) == 1
    for i in range(10):  # a gizmo drag: one undo step
        editor.move_box(a, 12.0 + 0.1 * i, 3.0, merge_key=("drag", 1))
    editor.rotate_box(a, 1.0, merge_key=("drag", 1))
    assert len(editor.history) == 2
    assert editor.undo().get(a).box == CAR
    # Typing a prompt merges by default; an explicit None makes every keystroke a step.
    for text in ("t", "th", "the"):
        editor.set_prompt(text)
    editor.set_prompt("the car", merge_key=None)
    assert editor.undo().prompt == "the"
    assert editor.undo().prompt == ""


def test_history_is_bounded() -> None:
    history = History(Draft(), max_steps=5)
    for i in range(20):
        history.apply(Draft(prompt=str(i)))
    assert len(history) == 5
    for _ in range(10):
        history.undo()
    assert history.present.prompt == "14"
    with pytest.raises(ValueError, match="max_steps"):
        History(Draft(), max_steps=0)


# ------------------------------------------------------------------------------------------ validation


def _valid() -> Draft:
    return Draft().set_prompt("the car ahead").add_box(CAR, "Car").add_box(PED, "Pedestrian")


INVALID = [
    (_valid().set_prompt("   "), "prompt", "the prompt is empty"),
    (_valid().set_prompt("two\nlines"), "prompt", "U+000A (LF)"),
    (Draft().set_prompt("a car"), "boxes", "no boxes: add at least one box, or mark"),
    (
        _valid().set_refers_to_nothing(True),
        "boxes",
        "marked as referring to nothing but the draft has 2 box(es)",
    ),
    (_valid().set_class(1, "truck"), "box[1].class", "box 2 of 2: class 'truck' is not one of"),
    (_valid().resize_box(0, 0.0, 1.8, 1.5), "box[0].size", "box 1 of 2 (Car): length must be"),
    (_valid().resize_box(1, 0.7, 0.6, -1.0), "box[1].size", "(Pedestrian): height must be"),
    (_valid().resize_box(0, 4.2, 25.0, 1.5), "box[0].size", "width 25 m is larger than 20 m"),
    (_valid().move_box(0, -1.0, 3.0), "box[0].position", "centre x = -1.00 m is outside"),
    (_valid().move_box(1, 20.0, -26.0), "box[1].position", "centre y = -26.00 m is outside"),
    (_valid().move_box(0, 12.0, 3.0, 6.0), "box[0].position", "centre z = 6.00 m is outside"),
    (
        _valid().move_box(1, 3.0, 20.0),
        "box[1].image",
        "box 2 of 2 (Pedestrian): the box is outside",
    ),
]


@pytest.mark.parametrize(("draft", "field", "text"), INVALID, ids=[i[1] for i in INVALID])
def test_each_invalid_draft_gets_its_own_message(draft: Draft, field: str, text: str) -> None:
    report = validate(draft, calib=vod_lidar_calibration())
    assert not report.ok
    (issue,) = report.errors
    assert issue.field == field and text in issue.message
    with pytest.raises(ValidationError) as info:
        report.raise_if_invalid()
    assert text in str(info.value)


def test_messages_are_distinct() -> None:
    messages = [validate(d, calib=vod_lidar_calibration()).errors[0].message for d, _, _ in INVALID]
    assert len(set(messages)) == len(messages)


def test_valid_draft_and_warnings() -> None:
    assert validate(_valid(), calib=vod_lidar_calibration()).issues == ()
    assert validate(Draft().set_prompt("nothing").set_refers_to_nothing(True)).ok
    # Far and small: tall enough in 3D, but under the evaluation's 40 px in the image.
    far = (
        Draft()
        .set_prompt("the far pedestrian")
        .add_box((50.0, 0.0, -1.2, 0.5, 0.5, 1.0, 0), "Pedestrian")
    )
    report = validate(far, calib=vod_lidar_calibration())
    assert report.ok and [w.field for w in report.warnings] == ["box[0].image"]
    assert "40 px" in report.warnings[0].message
    dup = _valid().add_box(CAR, "Car")
    report = validate(dup)
    assert report.ok and "boxes 1 and 3 overlap" in report.warnings[0].message
    assert report.warnings[0].severity is Severity.WARNING
    long_prompt = _valid().set_prompt(" ".join(["word"] * 31))
    assert validate(long_prompt).ok and validate(long_prompt).warnings


def test_range_and_image_checks_are_configurable() -> None:
    d = _valid().move_box(0, 60.0, 3.0)
    assert not validate(d).ok
    assert validate(d, ValidationConfig(x_range=(0.0, 70.0))).ok
    side = _valid().move_box(1, 3.0, 20.0)
    assert validate(side).ok  # no calibration: no image check
    config = ValidationConfig(require_in_image=False)
    assert validate(side, config, calib=vod_lidar_calibration()).ok


def test_proposals_skip_duplicates_and_other_classes() -> None:
    existing = np.array([[10.0, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0]])
    pred = np.array(
        [
            [10.1, 0.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # IoU ~0.95 with the draft box: duplicate
            [20.0, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0],
            [20.2, 5.0, -1.0, 4.0, 2.0, 1.5, 0.0],  # duplicate of the previous proposal
            [30.0, 0.0, -1.0, 0.7, 0.7, 1.7, 0.0],
        ]
    )
    boxes, classes, duplicates = proposals(pred, ["Car", "Car", "Car", "Pedestrian"], existing)
    assert classes == ("Car", "Pedestrian") and duplicates == 2
    np.testing.assert_array_equal(boxes, pred[[1, 3]])
    boxes, classes, _ = proposals(pred, ["Car", "Truck", "Car", "Car"], existing, limit=1)
    assert classes == ("Car",) and boxes[0, 0] == 20.2  # "Truck" is not a metric class


def test_changed_box_finds_the_added_or_edited_box() -> None:
    one = Draft().add_box(default_box("Car", 10.0, 0.0), "Car")
    two = one.add_box(default_box("Cyclist", 20.0, 1.0), "Cyclist")
    assert changed_box(one, two) == 1
    assert changed_box(two, two.move_box(0, 11.0, 0.0)) == 0
    assert changed_box(two, two.delete_box(1)) is None
    assert changed_box(two, one) is None


def test_is_pristine_only_for_an_untouched_new_pair() -> None:
    assert is_pristine(Draft())
    assert is_pristine(Draft().set_prompt("  \n"))  # whitespace is nothing worth keeping
    assert not is_pristine(Draft().set_prompt("the car"))
    assert not is_pristine(Draft().add_box(CAR, "Car"))
    assert not is_pristine(Draft().set_refers_to_nothing(True))
    assert not is_pristine(Draft(sample_id="00003"))  # a reopened pair, even emptied
