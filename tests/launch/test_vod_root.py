"""View-of-Delft roots as they come (issue 13, parts 4 and 5): ``launch.py`` opens the release
layout and chooses a split it can serve, annotation saves pairs into a Talk2Radar root beside the
release without touching it, the frame's label_2 objects are offered as ready-made boxes, and the
Annotate tab's ergonomics (Enter saves, Save disabled with its reason, placements refused at
once, one Class control, the saved id in the panel). Fixtures: ``write_vod_root``
(:mod:`tests.vod_fixtures`)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import launch
from app.serving.served import default_pairs_root
from scenes.frame import RootError
from scenes.talk2radar.root import Talk2RadarRoot


def _files(root: Path) -> dict[str, tuple[int, int]]:
    out = {}
    for folder, _, names in os.walk(root):
        for name in names:
            path = Path(folder) / name
            st = path.stat()
            out[str(path.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


# ---------------------------------------------------------------------------- launch


def test_launch_chooses_a_split_it_can_serve(tmp_path, write_vod_root) -> None:
    root = write_vod_root(tmp_path / "vod", frames=3, splits={"val": [0, 1, 2], "train": [0]})
    opened = launch.open_root(root, None)
    assert opened.radar_folder == "radar" and opened.splits() == ["train", "val"]
    assert launch.choose_split(opened, None) == "val"  # no test list: the next preference
    # VoD's test frames live in testing/, not training/: "test" is skipped, not served broken.
    (root / "lidar" / "ImageSets" / "test.txt").write_text("00007\n00008\n")
    assert launch.choose_split(launch.open_root(root, None), None) == "val"
    with pytest.raises(launch.LaunchError) as info:
        launch.open_root(root, "test")
    message = str(info.value)
    assert "velodyne/00007.bin: missing velodyne file for sample 00007" in message
    assert "2 of the 2 frames listed in" in message and "test.txt" in message


def test_launch_errors_name_the_file_and_exit_2(tmp_path, write_vod_root, capsys) -> None:
    root = write_vod_root(tmp_path / "vod", frames=2)
    (root / "radar" / "training" / "calib" / "00000.txt").unlink()  # in every split
    code = launch.main(["--data", str(root), "--split", "val", "--port", "0"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2 and err.startswith("error: ")
    assert "radar/training/calib/00000.txt: missing calib file for sample 00000" in err
    # Without --split: no split is complete (train and val list frame 0), the first is named.
    code = launch.main(["--data", str(root), "--port", "0"])
    assert code == 2 and "no split can be served" in capsys.readouterr().err
    bare = write_vod_root(tmp_path / "bare", frames=1, splits={})
    (bare / "lidar" / "ImageSets").mkdir()  # a folder without lists (no folder: every frame)
    code = launch.main(["--data", str(bare), "--port", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "no split list" in err and "ImageSets" in err


def test_a_root_without_image_sets_serves_every_frame(tmp_path, write_vod_root) -> None:
    """The devkit's example set has no ImageSets: all frames of velodyne/, with one notice."""
    path = write_vod_root(tmp_path / "example", frames=3, splits={})
    for file in sorted(path.glob("*/training/*/00001.*")):
        file.rename(file.with_stem("00549"))
    assert not (path / "lidar" / "ImageSets").exists()
    root = Talk2RadarRoot(path)
    assert root.splits() == ["all"]
    with pytest.warns(UserWarning, match=r"has no ImageSets folder, so all 3 frames") as notes:
        assert root.ids("all") == ["00000", "00002", "00549"]
    assert len(notes) == 1 and "\n" not in str(notes[0].message)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per root: no second notice
        assert root.ids("test") == ["00000", "00002", "00549"]
    with pytest.warns(UserWarning):
        opened = launch.open_root(path, None)
        assert launch.choose_split(opened, None) == "all"
    (path / "radar" / "training" / "calib" / "00549.txt").unlink()
    with pytest.warns(UserWarning), pytest.raises(launch.LaunchError) as info:
        launch.open_root(path, "all")
    assert "calib/00549.txt: missing calib file" in str(info.value)
    assert "1 of the 3 frames of" in str(info.value) and "velodyne miss files" in str(info.value)
    (path / "lidar" / "training" / "velodyne" / "frame7.bin").write_bytes(b"")
    with pytest.raises(RootError, match=r"frame7\.bin: not named by a frame id"):
        Talk2RadarRoot(path).ids("all")


def test_pairs_of_a_root_without_prompts_go_beside_it(tmp_path, write_vod_root) -> None:
    vod = Talk2RadarRoot(write_vod_root(tmp_path / "vod", frames=1))
    assert default_pairs_root(vod) == tmp_path / "vod-talk2radar"
    from tests.conftest import write_tiny_root

    tiny = Talk2RadarRoot(write_tiny_root(tmp_path / "tiny", frames=1))
    assert default_pairs_root(tiny) == tiny.path  # a Talk2Radar root keeps its pairs


# ---------------------------------------------------------------------------- in the app


@pytest.fixture(scope="module")
def vod_app(tmp_path_factory, write_vod_root, torch_threads, serve_app, untrained_model, grounding):
    """The app serving a View-of-Delft root as released, on each grounding path."""
    root = write_vod_root(tmp_path_factory.mktemp("vod-app") / "vod", frames=2)
    with torch_threads(1):
        model = untrained_model(grounding, text_encoder="gru", head__score_threshold=0.0)
        pairs = root.with_name("vod-talk2radar")  # named: a release is never written beside
        with serve_app(root, model, split="val", warm_up=False, pairs_root=pairs) as app:
            yield app


def _connect(app, ws_client):
    before = set(app.sessions)
    client = ws_client(app.port)
    client.pump_until(
        lambda: "/scene/lidar" in client.nodes and "Save pair" in client.gui, 15, "the tab"
    )
    session = app.sessions[(set(app.sessions) - before).pop()]
    panel = next(p for p in app.annotations.panels() if p.session is session)
    client.pump_until(lambda: panel.frame is not None, 5, "the draft's frame")
    return client, panel


def _notified(client, title: str) -> str:
    client.pump_until(lambda: any(t == title for t, _ in client.notifications), 10, title)
    return next(b for t, b in client.notifications if t == title)


def test_ready_made_boxes_enter_saves_beside_the_release(vod_app, ws_client) -> None:
    app = vod_app
    root = app.frames.root.path
    release = _files(root)
    pairs_root = root.with_name("vod-talk2radar")
    client, panel = _connect(app, ws_client)
    try:
        sample = panel.frame.sample
        assert sample.prompt is None and len(sample.boxes) == 4  # label_2: every object
        status = panel.w.status.content
        assert "Pairs are saved into" in status and "vod\\-talk2radar" in status
        # The metric objects are offered: in the 3D view and in the Object list. With a
        # referent-path model they are the labelled boxes its referent stage picks among, only
        # those a pair can hold (app.annotate_tab.labelled): the far car is not offered.
        referent = app.engine.model.cfg.grounding == "referent"
        offered = ("1. Pedestrian · 10.4 m", "2. Car · 15.1 m", "3. Cyclist · 20.6 m")
        offered += () if referent else ("4. Car · 60.0 m",)
        client.pump_until(lambda: "/annotate/ready/edges" in client.nodes, 5, "ready boxes")
        assert client.dropdown("Object") == offered  # nearest first
        assert panel.w.ready.visible  # shown on a root without prompts
        assert panel.w.save.disabled  # nothing to save yet, and the reason is shown
        assert "Save pair is disabled until" in panel.w.checks.content

        # A click on the car adds its label_2 box to the draft (not a default-sized box).
        car = sample.boxes[0]
        client.click_ground(car[0] + 0.5, car[1], panel.frame.ground_z)
        # The draft and the offered boxes change in one refresh on the server's thread: wait
        # for both (the draft is filled before the refresh that updates the offers ends).
        client.pump_until(
            lambda: len(panel.draft.boxes) == 1 and len(panel.ready_boxes) == len(offered) - 1,
            5,
            "the car added",
        )
        np.testing.assert_allclose(panel.draft.boxes[0].box, car, atol=1e-9)
        assert panel.draft.boxes[0].cls == "Car"
        client.pump_until(
            lambda: len(client.dropdown("Object")) == len(offered) - 1, 5, "the list updated"
        )
        # The draft is drawn into the camera panel too.
        layer = panel.session.camera.layer("draft")
        assert layer is not None and np.array_equal(layer.boxes, panel.draft.box_array)
        if not referent:  # the far car (60 m) cannot be saved: adding it is refused at once
            client.set("Object", next(o for o in client.dropdown("Object") if "60.0 m" in o))
            client.click("Add object")
            body = _notified(client, "No ready-made box placed there")
            assert "centre x = 60.00 m is outside the annotated range" in body
        assert len(panel.draft.boxes) == 1

        # Enter in an invalid draft says why; Enter in a valid one saves.
        assert panel.w.save.disabled
        client.set("Pair prompt", "\n")
        assert "the prompt is empty" in _notified(client, "Not saved yet")
        client.set("Pair prompt", "the car ahead on the left")
        client.pump_until(lambda: not panel.w.save.disabled, 5, "Save enabled")
        assert "Ready to save" in panel.w.checks.content
        client.set("Pair prompt", "the car ahead on the left\n")
        client.pump_until(lambda: "Saved pair 00000" in panel.w.status.content, 10, "the id shown")
        assert panel.last_saved == "pair 00000 (new pair) in train"
        assert not panel.draft.boxes and not panel.w.length.visible  # the box fields are cleared
        assert panel.w.prompt.value == ""
    finally:
        client.close()
    # The release is untouched; the pair is a Talk2Radar sample beside it, image and radar tree
    # included.
    assert _files(root) == release
    saved = Talk2RadarRoot(pairs_root).load("00000")
    assert saved.prompt == "the car ahead on the left" and saved.classes == ("Car",)
    np.testing.assert_allclose(saved.boxes[0], car, atol=1e-4)
    assert saved.image_path is not None and saved.image.shape == (1216, 1936, 3)
    assert Talk2RadarRoot(pairs_root).radar_folder == "radar"
    assert len(app.frames) == 2  # the served split is the release's


def _placing(app) -> str | None:
    """The modifier of a click that places a box: Shift on the referent path, whose frames here
    are labelled (sentence first: a plain click only picks, issue 39.6); none on the other."""
    return "shift" if app.engine.model.cfg.grounding == "referent" else None


def test_placements_outside_the_range_are_refused_at_once(vod_app, ws_client) -> None:
    client, panel = _connect(vod_app, ws_client)
    place = _placing(vod_app)
    try:
        ground = panel.frame.ground_z
        client.click_ground(55.0, -12.0, ground, place)
        body = _notified(client, "No box placed there")
        assert "centre x = 55.00 m is outside the annotated range [0, 51.2] m" in body
        client.click_ground(4.0, 15.0, ground, place)  # in range, beside the car: not in the image
        client.pump_until(
            lambda: sum(t == "No box placed there" for t, _ in client.notifications) == 2,
            10,
            "the second refusal",
        )
        assert "outside the camera image" in client.notifications[-1][1]
        assert not panel.draft.boxes
    finally:
        client.close()


def test_new_box_class_never_relabels_and_change_class_does(vod_app, ws_client) -> None:
    client, panel = _connect(vod_app, ws_client)
    place = _placing(vod_app)
    try:
        ground = panel.frame.ground_z
        client.click_ground(30.0, 0.0, ground, place)
        client.pump_until(lambda: panel.w.length.visible, 5, "a car, its fields shown")
        client.set("New box class", "Cyclist")  # the next box's class: the selected car stays
        client.pump_until(lambda: panel.w.cls.value == "Cyclist", 5, "the class")
        client.click_ground(35.0, 4.0, ground, place)
        client.pump_until(lambda: len(panel.draft.boxes) == 2, 5, "the next box")
        assert panel.draft.classes == ("Car", "Cyclist")
        client.click("Change class", "Pedestrian")  # an explicit act on the selected box
        client.pump_until(lambda: panel.draft.classes[1] == "Pedestrian", 5, "the relabel")
        assert panel.draft.classes[0] == "Car" and panel.w.cls.value == "Cyclist"
        client.click("Draft", "Undo")
        client.pump_until(lambda: panel.draft.classes == ("Car", "Cyclist"), 5, "the undo")
    finally:
        client.close()


def test_a_pair_saved_beside_reopens_on_its_source_frame(vod_app, ws_client) -> None:
    """The pair's id belongs to the pairs root: reopening it shows the served frame it was
    annotated on, never the served sample that happens to share its id."""
    app = vod_app
    store = app.annotations.store
    next_id = max((int(p.sample_id) for p in store.pairs()), default=-1) + 1
    source = 1 if next_id == 0 else 0  # a served frame whose id is not the pair's
    other = 1 - source
    app.go_to(source)
    client, panel = _connect(app, ws_client)
    try:
        client.pump_until(lambda: panel.frame.name == f"0000{source}", 5, "the source frame")
        offered = 3 if app.engine.model.cfg.grounding == "referent" else 4  # not the far car
        client.pump_until(lambda: len(client.dropdown("Object")) == offered, 5, "the objects")
        client.click("Add object")  # the nearest: the pedestrian
        client.pump_until(lambda: len(panel.draft.boxes) == 1, 5, "the pedestrian")
        client.set("Pair prompt", "the pedestrian on the right\n")
        client.pump_until(lambda: panel.last_saved is not None, 10, "the save")
        sid = panel.last_saved.split()[1]
        assert sid == f"{next_id:05d}" != f"0000{source}"
        assert store.history(sid)[-1].source["sample_id"] == f"0000{source}"
        app.go_to(other)
        client.pump_until(lambda: panel.session.frame.index == other, 5, "another frame")
        client.pump_until(lambda: any(o.startswith(sid) for o in client.dropdown("Pair")), 5, "")
        client.set("Pair", next(o for o in client.dropdown("Pair") if o.startswith(sid)))
        client.click("Open pair")
        # The draft is reset a moment before the panel's frame is set (the server's thread).
        expected = frozenset({f"0000{source}"})
        client.pump_until(
            lambda: panel.draft.sample_id == sid and panel.frame.sample_ids == expected,
            5,
            "the pair opened on its source frame",
        )
        client.pump_until(lambda: panel.session.frame.index == source, 5, "its frame shown")
        assert panel.draft.classes == ("Pedestrian",)
    finally:
        app.go_to(0)
        client.close()
