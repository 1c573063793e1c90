"""Pairs annotated on a nuScenes root saved as Talk2Car commands (annotate.talk2car), without the
app: what is written, that the loader reads it back with the same box, what is refused, and the
root kind's frames (app.serving.served_nuscenes). A tiny exported root (the ``nuscenes_root`` fixture)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from annotate import Draft, StoreError, ValidationError
from annotate.talk2car import Talk2CarStore, referred_annotation
from app.serving.served import serve_root
from app.serving.served_nuscenes import NuScenesServed, frame_notes
from scenes.datasets.source import NuScenesSource
from scenes.nuscenes.classes import model_class
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import read_commands


@pytest.fixture(scope="module")
def source(nuscenes_root: Path) -> NuScenesSource:
    return NuScenesSource(nuscenes_root, nuscenes_root / "commands")


def _referable(root: NuScenesRoot, sample: str) -> tuple[int, np.ndarray, str]:
    """The first annotation of ``sample`` in the class set wholly in front of CAM_FRONT."""
    boxes, categories, attributes = root.annotation_boxes(sample)
    for i, (box, cat, att) in enumerate(zip(boxes, categories, attributes, strict=True)):
        cls = model_class(cat, att)
        if cls is not None and 8 < box[0] < 40 and abs(box[1]) < 6:
            return i, box, cls
    raise AssertionError("no referable annotation")


def test_the_frames_of_a_nuscenes_root(source: NuScenesSource) -> None:
    root = source.nuscenes
    assert source.splits() == ["all", "train", "val", "test"]
    assert source.ids("all") == list(root.samples)
    assert set(source.ids("val")) <= set(root.samples) and source.ids("val")
    sample = source.load(source.ids("train")[0])
    frame = root.frame(sample.sample_id)
    assert sample.lidar.shape == frame.lidar.shape and sample.radar.shape[1] == 7
    assert len(sample.boxes) == len(sample.classes) <= len(frame.boxes)
    assert sample.image_path == frame.image_path
    np.testing.assert_array_equal(sample.calib.P2, frame.calib.P2)
    np.testing.assert_array_equal(sample.calib.Tr_velo_to_cam, frame.calib.Tr_velo_to_cam)
    commands = source.commands(sample.sample_id)
    assert commands and sample.prompt == commands[0].command.text
    notes = frame_notes(source, sample)
    assert "*Scene* " in notes and f"*Commands ({len(commands)}):*" in notes
    with pytest.raises(Exception, match="no split 'nope'"):
        source.ids("nope")


def test_a_saved_command_reads_back_with_the_same_box(
    source: NuScenesSource, tmp_path: Path
) -> None:
    root = source.nuscenes
    token = source.ids("val")[0]  # a command goes into its sample's split (issue 48.5)
    sample = source.load(token)
    served = serve_root(source, pairs=tmp_path / "pairs")
    assert isinstance(served, NuScenesServed) and served.named
    store = served.open_store()
    assert isinstance(store, Talk2CarStore) and not (tmp_path / "pairs").exists()
    index, box, cls = _referable(root, token)
    draft = Draft().set_prompt("pull over behind that one").add_box(box, cls)
    assert served.draft_issues(draft, sample) == ()
    first = store.save(draft, served.source_frame(sample), split="val", request="k1")
    again = store.save(draft, served.source_frame(sample), split="val", request="k1")
    assert again.repeated and again.sample_id == first.sample_id  # one command, not two
    file = tmp_path / "pairs" / "commands" / "val_commands.json"
    data = json.loads(file.read_text())
    assert len(data["commands"]) == 1
    record = data["commands"][0]
    frame = root.frame(token)
    assert record["sample_token"] == frame.cam_front_token  # a CAM_FRONT sample_data token
    assert record["box_token"] == frame.annotation_tokens[index]
    assert record["obj_name"] == frame.categories[index]
    assert data["scene_tokens"] == [frame.scene_token] == [record["scene_token"]]
    assert all(isinstance(v, str) for v in record["rotation"])  # four strings, as released
    # What the public talk2car.py (Talk2CarSlim) reads of each command.
    for key in ("scene_token", "translation", "size", "rotation", "obj_name", "command_token",
                "command", "sample_token", "2d_box", "t2c_img", "box_token"):  # fmt: skip
        assert key in record
    assert [float(v) for v in record["rotation"]] and len(record["2d_box"]) == 4
    x, _, w, h = record["2d_box"]
    assert w > 0 and h > 0 and x >= 0 and x + w <= frame.image_size[0] + 1e-6
    found = read_commands(tmp_path / "pairs" / "commands", "val", root)
    assert not found.skipped and [c.command_token for c in found.commands] == [first.sample_id]
    ref = found.referent[first.sample_id]
    np.testing.assert_allclose(ref.box, box, atol=1e-6)
    assert (ref.cls, ref.index) == (cls, index)
    assert found.commands[0].text == "pull over behind that one"
    assert [p.sample_id for p in store.pairs()] == [first.sample_id]
    # A second save appends; a deletion removes just that one.
    second = store.save(draft.set_prompt("follow it"), served.source_frame(sample), split="val")
    assert [c.text for c in store.commands("val")] == ["pull over behind that one", "follow it"]
    store.delete(first.sample_id)
    assert [c.command_token for c in store.commands("val")] == [second.sample_id]
    with pytest.raises(StoreError, match="not reopened"):
        store.open(second.sample_id)


def test_a_command_refers_to_exactly_one_labelled_annotation(
    source: NuScenesSource, tmp_path: Path
) -> None:
    root = source.nuscenes
    token = source.ids("all")[0]
    sample = source.load(token)
    served = serve_root(source, pairs=tmp_path / "pairs")
    store = served.open_store()
    boxes, categories, attributes = root.annotation_boxes(token)
    _, box, cls = _referable(root, token)
    two = (
        Draft()
        .set_prompt("the two of them")
        .add_box(box, cls)
        .add_box(box + np.array([0, 3, 0, 0, 0, 0, 0]), cls)
    )
    moved = Draft().set_prompt("that one").add_box(box + np.array([0.5, 0, 0, 0, 0, 0, 0]), cls)
    nothing = Draft().set_prompt("nothing there").set_refers_to_nothing(True)
    for draft, words in (
        (two, "exactly one labelled annotation: the draft has 2 boxes"),
        (moved, "is not one of the sample's labelled annotations"),
        (nothing, "refers to nothing"),
    ):
        issues = served.draft_issues(draft, sample)
        assert any(words in i.message for i in issues), (words, issues)
        with pytest.raises(ValidationError, match=words.split(":")[0]):
            store.save(draft, served.source_frame(sample), split="train")
    assert referred_annotation(Draft(), boxes, categories, attributes) == (None, ())
    assert not (tmp_path / "pairs").exists()  # nothing refused was written


def test_nothing_is_written_without_pairs(source: NuScenesSource) -> None:
    served = serve_root(source)
    assert not served.named
    assert served.pairs_path.name == source.path.name + "-talk2car"
    assert "--pairs" in served.unnamed_message()
