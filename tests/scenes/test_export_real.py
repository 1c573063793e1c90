"""The real-format export (``python -m scenes.export_real``, issue 24 part 4): a synthetic root
written as Talk2Radar (one prompt per frame, label_2 = its referents, no sidecar) and as
View-of-Delft (label_2 = every annotated object, VoD class names), read by the real readers
without ever opening ``meta/``; the VoD labelling rules; resuming and errors. Fixtures:
``real_format_source`` and ``real_format_roots`` (``conftest.py``)."""

from __future__ import annotations

import builtins
import io
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from scenes.export_real import export, main
from scenes.frame.kitti import read_label_file
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.calib import boxes_lidar_to_camera
from scenes.synth.vod_labels import ABSENT_CLASSES, VOD_CLASSES, frame_objects
from scenes.synth.world import RIDER_IN_CYCLIST, cyclist_mesh, rider_boxes
from scenes.synth.world.materials import Mat
from scenes.talk2radar.layout import TRAIN_VAL
from scenes.talk2radar.pointcloud import read_points
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels, objects_from_labels

TREES = ("lidar", "radar", "radar_5frames")
SPLITS = ("train", "val", "test")


def _first_samples(source: Path) -> dict[str, str]:
    """Source frame id -> its split: the first sample of each world, read independently of the
    export (from the sidecars' world ids)."""
    root = Talk2RadarRoot(source)
    out, worlds = {}, set()
    for split in SPLITS:
        for sid in root.ids(split):
            world = root.load_meta(sid).world_id
            if world not in worlds:
                worlds.add(world)
                out[sid] = split
    return out


def _in_view_centre(boxes: np.ndarray, sample) -> np.ndarray:
    """Box centres ``(K, 2)`` in pixels and their depth, projected with the frame's P2."""
    cam = boxes_lidar_to_camera(boxes, sample.calib)
    centre = cam.location.copy()
    centre[:, 1] -= cam.dimensions_hwl[:, 0] / 2  # the bottom centre up to the geometric centre
    uvw = np.c_[centre, np.ones(len(centre))] @ sample.calib.P2.T
    return uvw[:, :2] / uvw[:, 2:3], uvw[:, 2]


def test_the_talk2radar_tree_is_the_release_layout_with_one_prompt_per_frame(
    real_format_roots, real_format_source
):
    t2r, _ = real_format_roots
    assert sorted(p.name for p in t2r.iterdir()) == sorted(TREES)  # no meta/, sources/, manifest
    for tree in TREES:
        assert sorted(p.name for p in (t2r / tree / "training").iterdir()) == [
            "calib",
            "image_2",
            "label_2",
            "prompt",
            "velodyne",
        ]
    expected = _first_samples(real_format_source)
    root, source = Talk2RadarRoot(t2r), Talk2RadarRoot(real_format_source)
    assert len(expected) == 4 < sum(len(source.ids(s)) for s in SPLITS)
    for split in SPLITS:
        assert root.ids(split) == [sid for sid, s in expected.items() if s == split]
    assert root.ids(TRAIN_VAL) == root.ids("train") + root.ids("val")
    for sid in expected:
        sample, original = root.load(sid), source.load(sid)
        assert sample.meta is None and sample.prompt == original.prompt
        assert sample.classes == original.classes and len(sample.boxes) >= 1
        assert np.allclose(sample.boxes, original.boxes, atol=1e-6)
        meta = original.meta
        by_id = {a.actor_id: a for a in meta.actors}
        referred = np.array([by_id[i].box for i in meta.referent_ids])
        assert np.allclose(sample.boxes, referred, atol=2e-3)  # the prompt's referents only
        label = (t2r / "lidar/training/label_2" / f"{sid}.txt").read_text()
        for tree in TREES[1:]:
            assert (t2r / tree / "training/label_2" / f"{sid}.txt").read_text() == label
        lidar = t2r / "lidar/training/velodyne" / f"{sid}.bin"
        assert lidar.stat().st_ino == original_path(source, "lidar", "velodyne", sid).stat().st_ino
        assert sample.image_path is not None and sample.image_size == (484, 304)


def boxes_of(labels, name: str, calib) -> np.ndarray:
    """LiDAR-frame boxes ``(K, 7)`` of the labels named ``name``."""
    chosen = [lab for lab in labels if lab.name == name]
    return objects_from_labels(chosen, calib).boxes


def original_path(root: Talk2RadarRoot, tree: str, folder: str, sid: str) -> Path:
    suffix = {"velodyne": ".bin", "image_2": ".jpg"}.get(folder, ".txt")
    return root.path / tree / "training" / folder / f"{sid}{suffix}"


def test_the_vod_tree_labels_every_annotated_object_under_vod_names(
    real_format_roots, real_format_source
):
    t2r, vod = real_format_roots
    assert sorted(p.name for p in vod.iterdir()) == sorted(TREES)
    assert not (vod / "lidar/training/prompt").exists()
    root, source = Talk2RadarRoot(vod), Talk2RadarRoot(real_format_source)
    t2r_root = Talk2RadarRoot(t2r)
    names_seen: set[str] = set()
    for split in (*SPLITS, TRAIN_VAL):
        assert root.ids(split) == t2r_root.ids(split)
    for sid in _first_samples(real_format_source):
        sample, meta = root.load(sid), source.load_meta(sid)
        assert sample.prompt is None and sample.meta is None
        labels = sample.labels
        names = [lab.name for lab in labels]
        names_seen.update(names)
        assert set(names) <= set(VOD_CLASSES) and not set(names) & set(ABSENT_CLASSES)
        cyclists = [b for b, c in zip(sample.boxes, sample.classes, strict=True) if c == "Cyclist"]
        riders = boxes_of(labels, "rider", sample.calib)
        assert 0 < len(riders) <= len(cyclists) or not cyclists
        for rider in riders:  # each inside its cyclist's box
            assert min(np.abs(rider[:2] - c[:2]).max() for c in cyclists) < 1e-3
        for tree in TREES[1:]:
            assert tuple(read_label_file(vod / tree / "training/label_2" / f"{sid}.txt")) == labels
        # The annotated area, checked from the geometry: actors a sensor sees whose centre is in
        # the picture within 48 m are labelled; those behind the camera or beyond 52 m are not.
        unsensed = set(meta.extra["unsensed_actor_ids"])
        actors = [a for a in meta.actors if a.actor_id not in unsensed]
        boxes = np.array([a.box for a in actors]).reshape(-1, 7)
        uv, depth = _in_view_centre(boxes, sample)
        width, height = sample.image_size
        dist = np.linalg.norm(boxes[:, :3], axis=1)
        inside = (depth > 1) & (uv[:, 0] > 1) & (uv[:, 0] < width - 1) & (uv[:, 1] > 1)
        inside &= (uv[:, 1] < height - 1) & (dist < 48)
        outside = (depth < 0) | (dist > 52)
        for actor, must, must_not in zip(actors, inside, outside, strict=True):
            hit = [
                np.abs(np.array(b) - actor.box).max() < 2e-3
                for b, c in zip(sample.boxes, sample.classes, strict=True)
                if c == actor.cls
            ]
            assert not (must and not any(hit)), f"{sid}: actor {actor.actor_id} not labelled"
            assert not (must_not and any(hit)), f"{sid}: actor {actor.actor_id} labelled"
        assert len(sample.boxes) <= len(actors)
        clutter = [c["cls"] for c in meta.extra["clutter"]]
        for kind in ("bicycle", "bicycle_rack", "moped_scooter"):
            assert names.count(kind) <= clutter.count(kind)
        for lab in labels:
            assert 0 <= lab.bbox[0] < lab.bbox[2] <= width and 0 <= lab.bbox[1] < lab.bbox[3]
            assert lab.bbox[3] <= height and lab.score == 1.0 and lab.occluded == 0
        # Every referent of the Talk2Radar tree in the annotated area is one of these objects.
        referents = t2r_root.load(sid)
        for box, cls in zip(referents.boxes, referents.classes, strict=True):
            if np.linalg.norm(box[:3]) < 48 and _in_view_centre(box[None], sample)[1][0] > 1:
                same = [
                    c == cls and np.abs(b - box).max() < 2e-3
                    for b, c in zip(sample.boxes, sample.classes, strict=True)
                ]
                assert any(same), f"{sid}: referent {cls} at {box[:2]} not in the VoD labels"
    assert {"Car", "Pedestrian", "Cyclist", "rider", "bicycle"} <= names_seen


def test_radar_trees_are_the_source_scans(real_format_roots, real_format_source):
    t2r, vod = real_format_roots
    for sid in _first_samples(real_format_source):
        five = real_format_source / "radar_5frames/training/velodyne" / f"{sid}.bin"
        points = read_points(five, 7)
        newest = points[points[:, 6] == 0]
        assert 0 < len(newest) < len(points)
        for out in (t2r, vod):
            assert (out / "radar_5frames/training/velodyne" / f"{sid}.bin").stat().st_ino == (
                five.stat().st_ino
            )
            single = read_points(out / "radar/training/velodyne" / f"{sid}.bin", 7)
            assert np.array_equal(single, newest)
        # written once, linked into the other tree
        a = (t2r / "radar/training/velodyne" / f"{sid}.bin").stat().st_ino
        assert a == (vod / "radar/training/velodyne" / f"{sid}.bin").stat().st_ino
    one = Talk2RadarRoot(t2r, radar="radar").load(sid)
    five_scans = Talk2RadarRoot(t2r, radar="radar_5frames").load(sid)
    assert 0 < len(one.radar) < len(five_scans.radar)


def test_reading_the_exported_roots_never_opens_meta(real_format_roots, monkeypatch):
    t2r, vod = real_format_roots
    opened: list[str] = []
    real_open, real_os_open = builtins.open, os.open

    def spy_open(file, *args, **kwargs):
        opened.append(os.fspath(file) if isinstance(file, (str, os.PathLike)) else "")
        return real_open(file, *args, **kwargs)

    def spy_os_open(path, *args, **kwargs):
        opened.append(os.fspath(path))
        return real_os_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", spy_open)
    monkeypatch.setattr(io, "open", spy_open)
    monkeypatch.setattr(os, "open", spy_os_open)
    labels = SceneLabels(vod)
    for radar in ("radar", "radar_5frames"):
        root = Talk2RadarRoot(t2r, radar=radar)
        for sid in root.ids(TRAIN_VAL) + root.ids("test"):
            sample = root.load(sid)
            assert sample.meta is None and sample.prompt and sample.image is not None
            assert len(labels.load(sid)) > len(sample.boxes)
    assert any("/label_2/" in p for p in opened) and any("/prompt/" in p for p in opened)
    assert not [p for p in opened if "/meta/" in p or p.endswith(".json")]
    assert not (t2r / "meta").exists() and not (vod / "meta").exists()


def test_scene_labels_read_the_vod_tree(real_format_roots, real_format_source):
    _, vod = real_format_roots
    labels, root = SceneLabels(vod), Talk2RadarRoot(vod)
    for sid in _first_samples(real_format_source):
        objects, sample = labels.load(sid), root.load(sid)
        assert objects.names == tuple(lab.name for lab in sample.labels)
        boxes, index = objects.metric()
        assert np.allclose(boxes, sample.boxes, atol=1e-6)
        assert [("Car", "Pedestrian", "Cyclist")[i] for i in index] == list(sample.classes)
        assert len(objects.others()) == len(objects) - len(boxes) > 0


def test_rider_boxes_follow_the_cyclist_mesh():
    size = np.array([1.75, 0.65, 1.7])
    box = np.array([[10.0, 2.0, -0.85, *size, 0.0]])
    rider = rider_boxes(box)[0]
    lo, hi = rider[:3] - rider[3:6] / 2, rider[:3] + rider[3:6] / 2
    checked = 0
    for seed in range(40):
        mesh = cyclist_mesh(size, np.random.default_rng(seed))
        dark = mesh.material == Mat.CLOTHING_DARK
        if not dark.any():  # light clothing is also the panniers' material: not told apart
            continue
        person = dark | (mesh.material == Mat.SKIN)
        verts = mesh.vertices[np.unique(mesh.faces[person])] + box[0, :3]
        inside = np.all((verts >= lo - 0.03) & (verts <= hi + 0.03), axis=1)
        assert inside.mean() > 0.93  # the pedals (lowest) turn with the crank
        extent = verts.max(axis=0) - verts.min(axis=0)
        assert np.allclose(extent, rider[3:6], rtol=0.12), (extent, rider[3:6])
        checked += 1
    assert checked >= 10
    assert RIDER_IN_CYCLIST[1] == 1.0 and rider[5] < size[2] and rider[3] < size[0]


def test_frame_objects_refuse_clutter_without_a_vod_class():
    meta = SampleMeta(extra={"clutter": [{"cls": "lamp_post", "box": [5, 0, 0, 1, 1, 1, 0]}]})
    with pytest.raises(ValueError, match="lamp_post"):
        frame_objects(meta, "meta/00001.json")
    empty = frame_objects(SampleMeta())
    assert empty.boxes.shape == (0, 7) and empty.names == ()


def test_export_resumes_and_refuses_what_it_must_not_write(
    tmp_path, real_format_source, write_vod_root, capsys
):
    vod = tmp_path / "vod"
    first = export(real_format_source, None, vod, splits=("train", "test"))
    assert (first.written, first.skipped) == (3, 0) and first.radar_folders == ("radar_5frames",)
    assert sorted(p.name for p in (vod / "lidar/ImageSets").iterdir()) == ["test.txt", "train.txt"]
    again = export(real_format_source, None, vod, splits=("train", "test"))
    assert (again.written, again.skipped) == (0, 3) and again.objects == first.objects
    sid = Talk2RadarRoot(vod).ids("test")[0]
    (vod / "radar_5frames/training/label_2" / f"{sid}.txt").unlink()
    assert export(real_format_source, None, vod, splits=("train", "test")).written == 1
    assert not list(vod.rglob(".*.tmp"))
    t2r_only = export(real_format_source, tmp_path / "t2r", None, splits=("val",), radar="radar")
    assert t2r_only.written == 1 and (tmp_path / "t2r/radar/training/velodyne").is_dir()
    assert not (tmp_path / "t2r/radar_5frames").exists()

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    bare = write_vod_root(tmp_path / "plain", frames=1)
    single = tmp_path / "single"
    shutil.copytree(real_format_source, single)
    shutil.rmtree(single / "radar_5frames")
    shutil.copytree(vod / "radar_5frames", single / "radar")  # a source of one radar tree
    cases = [
        (["--t2r", str(foreign)], "neither empty nor an earlier export"),
        (["--t2r", str(real_format_source)], "is the source root"),
        (["--t2r", str(tmp_path / "x"), "--vod", str(tmp_path / "x")], "different folders"),
        ([], "nothing to write"),
        (["--vod", str(tmp_path / "y"), "--splits", "nope"], "split 'nope' not found"),
    ]
    for extra, message in cases:
        assert main(["--source", str(real_format_source), "--quiet", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error: ") and message in err and "\n" not in err
    assert main(["--source", str(bare), "--vod", str(tmp_path / "z"), "--quiet"]) == 2
    assert "missing sidecar" in capsys.readouterr().err
    code = main(["--source", str(single), "--vod", str(tmp_path / "w"), "--radar", "both"])
    assert code == 2 and "needs 5 radar scans" in capsys.readouterr().err
    assert not (foreign / "lidar").exists() and not (tmp_path / "w").exists()


def test_the_command_line_reports_what_it_wrote(tmp_path, real_format_source, capsys):
    out = tmp_path / "t2r"
    assert main(["--source", str(real_format_source), "--t2r", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "4 frames (4 written, 0 already complete)" in text and "train_val 3" in text
    assert (
        "4 further prompts of the same worlds left out" in text and "Talk2Radar referents" in text
    )


def test_the_newest_scan_is_the_single_scan_generation(tmp_path):
    """``--radar radar`` from a 5-scan root gives, byte for byte, the radar files that
    ``scenes.synth --radar-scans 1`` writes for the same seed (scan 0 is drawn first)."""
    from scenes.synth.generate import SynthSettings, generate_root

    for scans in (1, 5):
        settings = SynthSettings(seed=77, radar_scans=scans, camera=None)
        generate_root(tmp_path / f"s{scans}", 1, settings, split_fractions=(1.0, 0.0, 0.0))
    export(tmp_path / "s5", None, tmp_path / "vod", splits=("train",), radar="radar")
    single = (tmp_path / "s1/radar/training/velodyne/00000.bin").read_bytes()
    assert (tmp_path / "vod/radar/training/velodyne/00000.bin").read_bytes() == single


def test_the_training_frames_read_the_exported_pair(real_format_roots):
    """The referent path's labels source (scenes.datasets.frames) on the pair: one frame per sample,
    the given prompt, its referents found among the View-of-Delft objects, never a sidecar."""
    from scenes.datasets.frames import FrameDataset

    t2r, vod = real_format_roots
    frames = FrameDataset(t2r, "train", scene_labels=SceneLabels(vod))
    root = Talk2RadarRoot(t2r)
    assert frames.source == "labels" and frames.ids == root.ids("train")
    for index, sid in enumerate(frames.ids):
        item, sample = frames[index], root.load(sid)
        assert item.from_labels and len(item.given) == 1 and item.given[0].text == sample.prompt
        metric = SceneLabels(vod).load(sid).metric()[0]
        assert len(item.actors) == len(metric) and item.region is not None
        assert 1 <= len(item.given[0].referent_ids) <= len(sample.boxes)
        by_id = {a.actor_id: a for a in item.actors}
        chosen = np.array([by_id[i].box for i in item.given[0].referent_ids])
        for box in chosen:
            assert np.min(np.abs(sample.boxes - box).max(axis=1)) < 2e-3
