"""Commands first-class in the app (issue 48.5), on a nuScenes root with Talk2Car commands, driven
through the websocket as a browser would: every frame lists its commands (never "this root has no
prompts"), a click on one runs it as if typed, its referred object is the one referent (drawn
apart, not every annotation), *Other annotations* hides the rest as one group (3D view, camera
image, the Annotate tab's ready-made boxes), and a pair annotated on a test-split sample is
written to ``test_commands.json`` with a ``2d_box`` of integers. The units: ``2d_box`` written as
the release writes it and read tolerantly, the store's split rule, the command in play."""

from __future__ import annotations

import json

import numpy as np
import pytest

from annotate import SplitError
from annotate.talk2car import Talk2CarStore
from app.serving.frame_commands import FrameCommand, button_label, command_in_play, command_objects
from app.serving.ground_truth import labelled_objects
from app.serving.navigation import FrameStore, frame_markdown
from app.serving.served import serve_root
from app.text import md_text
from scenes.datasets.source import NuScenesSource
from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import (
    command_record,
    commands_file,
    pixel_box,
    read_commands,
    write_command_file,
)
from tests.app.ws.session_helpers import connect_annotating

# ---------------------------------------------------------------------------- units


def test_2d_box_is_written_in_whole_pixels_and_read_either_way(nuscenes_root, tmp_path) -> None:
    assert pixel_box((10.2, 20.9, 30.5, 40.0)) == [10, 20, 31, 41]
    assert pixel_box((10, 20, 30, 40)) == [10, 20, 30, 40]  # whole pixels kept
    root = NuScenesRoot(nuscenes_root)
    found = read_commands(nuscenes_root / "commands", "train", root)
    command = found.commands[0]
    record = command_record(command)
    assert all(type(v) is int for v in record["2d_box"]), record["2d_box"]
    x, y, w, h = command.box_2d  # the smallest box of whole pixels around it
    left, top, width, height = record["2d_box"]
    assert left <= x and top <= y and left + width >= x + w - 1e-6 and top + height >= y + h - 1e-6
    # A file with float boxes (as this project wrote them before) still reads.
    records = [
        {**command_record(c), "2d_box": [v + 0.25 for v in c.box_2d]} for c in found.commands
    ]
    write_command_file(tmp_path, "train", {"scene_tokens": [], "commands": records})
    again = read_commands(tmp_path, "train", root)
    assert not again.skipped and len(again.commands) == len(found.commands)
    assert again.commands[0].box_2d[0] == pytest.approx(x + 0.25)


def test_a_sample_has_the_split_of_its_scene_and_the_store_keeps_to_it(
    nuscenes_root, tmp_path
) -> None:
    source = NuScenesSource(nuscenes_root, nuscenes_root / "commands")
    splits = {s: source.sample_split(s) for s in source.ids("all")}
    assert set(splits.values()) == {"train", "val", "test"}
    for split in ("train", "val", "test"):
        scenes = read_commands(nuscenes_root / "commands", split, source.nuscenes).scene_tokens
        for sample, found in splits.items():
            scene = source.nuscenes.tables.records["sample"][sample]["scene_token"]
            assert (found == split) == (scene in scenes)
    store = Talk2CarStore(tmp_path / "pairs", source.nuscenes, split_of=source.sample_split)
    test_sample = next(s for s, split in splits.items() if split == "test")
    assert store.split_for(test_sample) == "test"
    assert store.split_for(test_sample, "test") == "test"
    with pytest.raises(SplitError, match="is in split 'test'"):
        store.split_for(test_sample, "train")
    assert Talk2CarStore(tmp_path / "p2", source.nuscenes).split_for(test_sample) == "train"


def test_every_frame_shows_its_commands_never_the_no_prompts_line(nuscenes_root) -> None:
    served = serve_root(nuscenes_root, talk2car=nuscenes_root / "commands")
    frames = FrameStore(
        served.root, "all", notes=served.frame_notes, commands=served.frame_commands
    )
    without = serve_root(nuscenes_root)  # no --talk2car: says why there are none
    bare = FrameStore(
        without.root, "all", notes=without.frame_notes, commands=without.frame_commands
    )
    for i in range(len(frames)):
        frame = frames.load(i)
        text = frame_markdown(frame, len(frames))
        assert "no prompts" not in text and "Sample prompt" not in text
        commands = served.root.commands(frame.sample_id)
        assert f"*Commands ({len(commands)}):*" in text
        for n, c in enumerate(commands):
            assert f"{n + 1}. {md_text(c.command.text)} → **{c.cls}**" in text
        assert [c.text for c in frame.commands] == [c.command.text for c in commands]
        # The frame's one referent is its first command's, not every annotation.
        assert sum(frame.objects.referent) == 1 < len(frame.objects)
        marked = frame.objects.boxes[np.asarray(frame.objects.referent)][0]
        np.testing.assert_allclose(marked, commands[0].box, atol=1e-9)
        shown = frame_markdown(bare.load(i), len(bare))
        assert "no prompts" not in shown and "started without --talk2car" in shown


def test_the_command_in_play_and_its_referent() -> None:
    boxes = np.array(
        [[10.0, 0, 0, 4, 2, 1.5, 0], [20.0, 3, 0, 4, 2, 1.5, 0], [5.0, -2, 0, 1, 1, 2, 0]]
    )
    objects = labelled_objects(boxes, ["Car", "Car", "Pedestrian"], boxes, ["Car"] * 3, "labels")
    assert all(objects.referent)  # what a nuScenes frame's objects were: every one a referent
    commands = (
        FrameCommand("follow the car", boxes[1], "Car"),
        FrameCommand("stop near the person", boxes[2], "Pedestrian"),
    )
    marked = command_objects(objects, commands[1])
    assert sum(marked.referent) == 1 and marked.classes[marked.referent.index(True)] == "Pedestrian"
    assert sum(command_objects(objects, None).referent) == 0
    assert command_in_play(commands, 0, "stop near the person") == 1
    assert command_in_play(commands, 1, "a prompt of my own") == 1
    assert command_in_play(None, None, "follow the car") is None
    assert button_label(0, "x" * 100).endswith("…") and len(button_label(0, "x" * 100)) < 80


# ---------------------------------------------------------------------------- the app


def _connect(app, ws_client):
    return connect_annotating(
        app,
        ws_client,
        ("/scene/lidar", "/gt/referents/edges"),
        "the scene, the referent and the Annotate tab",
    )


def _test_sample(app) -> int:
    """The frame of a test-split sample with two commands whose referents differ."""
    source = app.frames.root
    for i, sid in enumerate(app.frames.ids):
        commands = source.commands(sid)
        two = len(commands) >= 2 and np.abs(commands[0].box - commands[1].box).max() > 0.5
        if source.sample_split(sid) == "test" and two:
            return i
    raise AssertionError("no test-split sample with two commands")


def test_a_click_on_a_command_runs_it_and_marks_its_referent(nusc_all, ws_client) -> None:
    app = nusc_all
    app.go_to(0)
    client, session, panel = _connect(app, ws_client)
    try:
        first = app.frames.root.commands(app.frame.sample_id)
        for i, c in enumerate(first):  # the first frame lists its commands, one button each
            assert button_label(i, c.command.text) in client.gui
        assert sum(session.objects.referent) == 1  # its first command's referent alone
        app.go_to(_test_sample(app))
        commands = app.frames.root.commands(app.frame.sample_id)
        label = button_label(1, commands[1].command.text)
        client.pump_until(lambda: label in client.gui, 10, "the new frame's command buttons")
        client.click(label)
        client.pump_until(
            lambda: (
                session.answer is not None and session.answer.prompt == commands[1].command.text
            ),
            60,
            "the command's answer",
        )
        assert session.prompt_field.value == commands[1].command.text  # as if typed
        assert session.command == 1 and session.commands.buttons[1].color == "green"
        referents = session.objects.boxes[np.asarray(session.objects.referent)]
        assert len(referents) == 1
        np.testing.assert_allclose(referents[0], commands[1].box, atol=1e-9)
        gt = session.camera.layer("gt")
        assert gt is not None and len(gt.boxes) == 1 and gt.labels == ("referent",)
        np.testing.assert_allclose(gt.boxes[0], commands[1].box, atol=1e-9)
        others = session.camera.layer("others")
        assert others is not None and len(others.boxes) == len(session.objects) - 1

        # *Other annotations*: one control hides every other annotation, the referent stays.
        assert panel.view.ready.count > 0 and panel.view.ready.visible
        client.set("Other annotations", False)
        client.pump_until(lambda: client.visible.get("/gt/edges") is False, 10, "others hidden")
        assert client.visible.get("/gt/referents/edges", True) is True
        assert "others" in session.camera._hidden and "gt" not in session.camera._hidden
        client.pump_until(lambda: not panel.view.ready.visible, 10, "the ready-made boxes hidden")
        hidden = [
            n for n, shown in client.visible.items() if n.startswith("/gt/labels/") and not shown
        ]
        labelled = [i for i, r in enumerate(session.objects.referent) if not r and i < 20]
        assert sorted(hidden) == sorted(f"/gt/labels/{i}" for i in labelled)
        client.set("Other annotations", True)
        client.pump_until(lambda: client.visible.get("/gt/edges") is True, 10, "others shown")
        client.pump_until(lambda: panel.view.ready.visible, 10, "the ready-made boxes shown")
    finally:
        client.close()


def test_a_pair_on_a_test_sample_goes_to_test_commands(nusc_all, ws_client) -> None:
    app = nusc_all
    app.go_to(_test_sample(app))
    client, _, panel = _connect(app, ws_client)
    try:
        sample = app.frame.sample
        client.pump_until(lambda: panel.w.split.value == "test", 10, "Split: test")
        assert panel.w.split.disabled
        k = next(i for i, b in enumerate(sample.boxes) if 8 < b[0] < 40 and abs(b[1]) < 6)
        client.click_ground(sample.boxes[k][0], sample.boxes[k][1], panel.frame.ground_z)
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 10, "the labelled box added")
        client.set("Pair prompt", "stop right behind that one\n")
        client.pump_until(lambda: "Saved pair" in panel.w.status.content, 20, "the save")
    finally:
        client.close()
    folder = app.annotations.path / "commands"
    assert not commands_file(folder, "train").exists()
    found = read_commands(folder, "test", NuScenesRoot(app.frames.root.path))
    assert [c.text for c in found.commands] == ["stop right behind that one"]
    data = json.loads(commands_file(folder, "test").read_text())
    assert all(type(v) is int for v in data["commands"][0]["2d_box"])
