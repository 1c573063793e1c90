"""The annotation store: round trips through Talk2RadarRoot, edits, deletions, concurrency, crash
safety (exceptions and real process deaths at every step), full disks, torn manifest lines."""

from __future__ import annotations

import errno
import json
import os
import threading
from pathlib import Path

import numpy as np
import pytest

import annotate.manifest as manifest_module
from annotate import (
    Action,
    AnnotationStore,
    ConflictError,
    DiskFullError,
    Draft,
    SaveError,
    SourceFrame,
    StoreError,
    ValidationError,
    read_manifest,
)
from annotate.errors import SplitError
from scenes import Actor, SampleMeta, Talk2RadarRoot, Talk2RadarWriter, read_label_file
from scenes.geometry.boxes import wrap_yaw
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.geometry.projection import scale_calibration
from scenes.talk2radar.pointcloud import read_points

CAR = (12.0, 3.0, -0.95, 4.2, 1.8, 1.5, 0.4)
PED = (20.0, -5.0, -0.85, 0.7, 0.6, 1.7, -2.9)
CYC = (25.0, 1.0, -0.9, 1.8, 0.7, 1.6, 3.1)


def _draft(prompt: str = "the car and the pedestrian ahead") -> Draft:
    return Draft().set_prompt(prompt).add_box(CAR, "Car").add_box(PED, "Pedestrian")


@pytest.fixture
def source_root(tmp_path: Path) -> Path:
    """A small Talk2Radar root with frames 3 (with a VoD-size camera image) and 7 (without one),
    VoD-like calibration."""
    rng = np.random.default_rng(0)
    path = tmp_path / "source"
    writer = Talk2RadarWriter(path)
    for frame in (3, 7):
        lidar = rng.uniform(-10, 30, (300, 4)).astype(np.float32)
        radar = rng.uniform(-10, 30, (30, 7)).astype(np.float32)
        image = np.full((1216, 1936, 3), 90, np.uint8) if frame == 3 else None
        files = writer.write_sensors(
            f"w{frame}", lidar, radar, vod_lidar_calibration(), vod_radar_calibration(), image
        )
        actors = (Actor(0, "Car", CAR, [3.0, 0.0]), Actor(1, "Cyclist", CYC, [0.0, 2.0]))
        meta = SampleMeta(tags=frozenset({"class"}), actors=actors, referent_ids=(0,), world_id=5)
        writer.write_sample(frame, files, np.array([CAR]), ["Car"], "the car", meta)
    writer.write_image_sets({"train": [3], "val": [7]})
    return path


@pytest.fixture
def out_root(tmp_path: Path) -> Path:
    return tmp_path / "annotated"


def _snapshot(root: Path) -> dict[str, bytes]:
    """Every file of a root (but the lock file) with its bytes."""
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def _assert_loadable(root: Path) -> dict[str, object]:
    """Every listed sample of every split loads; returns id -> sample."""
    reader = Talk2RadarRoot(root)
    out = {}
    for split in reader.splits():
        for sid in reader.ids(split):
            sample = reader.load(sid)
            assert sample.prompt
            out[sid] = sample
    return out


def _assert_box_close(actual: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(actual[:, :6], expected[:, :6], atol=1e-4)
    np.testing.assert_allclose(wrap_yaw(actual[:, 6] - expected[:, 6]), 0.0, atol=1e-4)


# ------------------------------------------------------------------------------------------ basics


def test_round_trip_through_talk2radar_root(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    result = store.create(_draft(), source, annotator="Ada Lovelace", split="val")
    assert result.sample_id == "00000" and result.version == 1

    reader = Talk2RadarRoot(out_root)
    assert reader.ids("val") == ["00000"]
    sample = reader.load("00000")
    assert sample.prompt == "the car and the pedestrian ahead"
    assert sample.classes == ("Car", "Pedestrian")
    _assert_box_close(sample.boxes, np.array([CAR, PED]))
    src = Talk2RadarRoot(source_root).load(3)
    np.testing.assert_array_equal(sample.lidar, src.lidar)
    np.testing.assert_allclose(sample.radar, src.radar, atol=1e-5)

    # The label file is what the metric reads: 16 single-space fields, camera frame, 2D boxes.
    for tree in ("lidar", "radar_5frames"):
        label_path = out_root / tree / "training" / "label_2" / "00000.txt"
        labels = read_label_file(label_path)
        assert [lab.name for lab in labels] == ["Car", "Pedestrian"]
        for line in label_path.read_text().splitlines():
            assert len(line.split(" ")) == 16
        left, top, right, bottom = labels[0].bbox
        assert 0 <= left < right <= 1936 and 0 <= top < bottom <= 1216
        # Bottom centre in the camera frame: LiDAR z - h/2, seen from a camera 0.46 m lower.
        assert labels[0].location[1] == pytest.approx(-(CAR[2] - CAR[5] / 2) - 0.46, abs=1e-5)
    # Sensors and the camera image are hard links of the source frame's files, not copies.
    for folder, name in (("velodyne", "{}.bin"), ("image_2", "{}.jpg")):
        for tree in ("lidar", "radar_5frames"):
            a = source_root / tree / "training" / folder / name.format("00003")
            b = out_root / tree / "training" / folder / name.format("00000")
            assert a.stat().st_ino == b.stat().st_ino
    assert sample.image_path is not None and sample.image_size == (1936, 1216)

    (record,) = read_manifest(store.manifest_path).records
    assert record.action is Action.CREATE and record.annotator == "Ada Lovelace"
    assert record.source["sample_id"] == "00003" and record.splits == ("val",)
    assert record.label_text == label_path.read_text()
    assert sample.meta.extra["annotator"] == "Ada Lovelace"
    assert sample.meta.referent_ids == (0, 1)
    # The Car coincides with the source frame's actor 0 and takes its known velocity; the source
    # frame's cyclist stays as a distractor.
    np.testing.assert_allclose(sample.meta.actors[0].velocity, [3.0, 0.0])
    assert [a.cls for a in sample.meta.actors] == ["Car", "Pedestrian", "Cyclist"]
    assert sample.meta.tags == {"class", "position"}


def test_refers_to_nothing_pair(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    draft = Draft().set_prompt("the bus on the left").set_refers_to_nothing(True)
    sid = store.create(draft, SourceFrame.from_root(source_root, 3)).sample_id
    assert (out_root / "lidar" / "training" / "label_2" / f"{sid}.txt").read_text() == ""
    sample = Talk2RadarRoot(out_root).load(sid)
    assert sample.boxes.shape == (0, 7) and sample.prompt == "the bus on the left"
    reopened = store.open(sid)
    assert reopened.refers_to_nothing and not reopened.boxes


def test_in_memory_source_writes_sensors_once(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    frame = Talk2RadarRoot(source_root).load(7)
    source = SourceFrame.from_sample(frame, key="synthetic/7")
    first = store.create(_draft(), source).sample_id
    second = store.create(_draft("the two objects"), source).sample_id
    (folder,) = (out_root / "sources").iterdir()
    assert folder.name.startswith("synthetic_7-")
    velodyne = out_root / "lidar" / "training" / "velodyne"
    assert (velodyne / f"{first}.bin").stat().st_ino == (velodyne / f"{second}.bin").stat().st_ino
    np.testing.assert_array_equal(read_points(velodyne / f"{first}.bin", 4), frame.lidar)
    assert len(_assert_loadable(out_root)) == 2


def test_ids_go_beyond_every_existing_id(source_root: Path) -> None:
    # An orphan label file (a sample never listed) must not be reused.
    orphan = source_root / "lidar" / "training" / "label_2" / "00041.txt"
    orphan.write_text("")
    before = _snapshot(source_root)
    store = AnnotationStore(source_root)
    sid = store.create(_draft(), SourceFrame.from_root(source_root, 3)).sample_id
    assert sid == "00042"
    reader = Talk2RadarRoot(source_root)
    assert reader.ids("train") == ["00003", "00042"] and reader.ids("val") == ["00007"]
    after = _snapshot(source_root)
    for name in ("lidar/training/label_2/00003.txt", "lidar/training/prompt/00007.txt"):
        assert after[name] == before[name]


def test_invalid_draft_writes_nothing(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    before = _snapshot(out_root)
    bad = [
        _draft("  "),
        Draft().set_prompt("nothing here"),
        _draft().set_class(0, "Truck"),
        _draft().resize_box(1, 0.7, -0.6, 1.7),
        _draft().move_box(0, 60.0, 3.0),
    ]
    for draft in bad:
        with pytest.raises(ValidationError) as info:
            store.create(draft, source)
        assert len(info.value.issues) == 1
    assert _snapshot(out_root) == before


def test_unknown_split_name_is_refused(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    with pytest.raises(ValueError, match=r"invalid split name '\.\./x'"):
        store.create(_draft(), SourceFrame.from_root(source_root, 3), split="../x")


def test_radar_tree_mismatch_is_refused(source_root: Path) -> None:
    with pytest.raises(StoreError, match="radar tree 'radar_5frames'"):
        AnnotationStore(source_root, radar_folder="radar_3frames")


# ------------------------------------------------------------------------------------------ edits


def test_reopen_edit_keeps_old_version_in_manifest(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    sid = store.create(_draft(), SourceFrame.from_root(source_root, 3), annotator="a").sample_id
    old_label = (out_root / "lidar" / "training" / "label_2" / f"{sid}.txt").read_text()

    draft = store.open(sid)
    assert draft.sample_id == sid and draft.base_version == 1
    assert draft.prompt == "the car and the pedestrian ahead"
    _assert_box_close(draft.box_array, np.array([CAR, PED]))
    edited = draft.delete_box(1).move_box(0, 13.0, 2.5).set_prompt("the car on the left")
    result = store.update(edited, annotator="b")
    assert result.version == 2

    sample = Talk2RadarRoot(out_root).load(sid)
    assert sample.prompt == "the car on the left" and sample.classes == ("Car",)
    _assert_box_close(sample.boxes, np.array([[13.0, 2.5, *CAR[2:]]]))
    for tree in ("lidar", "radar_5frames"):
        assert (out_root / tree / "training" / "prompt" / f"{sid}.txt").read_text() == (
            "the car on the left\n"
        )
    create, edit = store.history(sid)
    assert create.prompt == "the car and the pedestrian ahead" and create.label_text == old_label
    assert edit.action is Action.EDIT and edit.annotator == "b"
    assert edit.previous == {
        "version": 1,
        "prompt": "the car and the pedestrian ahead",
        "label_text": old_label,
    }
    assert [p.version for p in store.pairs()] == [2]
    assert sample.meta.extra["version"] == 2


def test_edit_keeps_non_metric_labels(source_root: Path) -> None:
    label = source_root / "lidar" / "training" / "label_2" / "00003.txt"
    bicycle = "bicycle 0 0 0.1 10 10 20 20 1.0 0.5 1.7 1.0 1.0 10.0 -1.5 1\n"
    label.unlink()  # break the hard link with the radar tree's copy
    label.write_text(bicycle)
    store = AnnotationStore(source_root)
    draft = store.open(3)
    assert draft.base_version == 0 and draft.refers_to_nothing  # no metric box in the file
    store.update(draft.add_box(CAR, "Car").set_prompt("the car"))
    names = [lab.name for lab in read_label_file(label)]
    assert names == ["Car", "bicycle"]


def test_stale_draft_is_a_conflict(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    sid = store.create(_draft(), SourceFrame.from_root(source_root, 3)).sample_id
    mine, theirs = store.open(sid), store.open(sid)
    store.update(theirs.set_prompt("the pedestrian and the car"), annotator="bob")
    before = _snapshot(out_root)
    with pytest.raises(ConflictError, match=r"changed by bob .*\(now version 2"):
        store.update(mine.set_prompt("mine"))
    with pytest.raises(ConflictError):
        store.delete(sid, base_version=1)
    assert _snapshot(out_root) == before


def test_delete_unlists_and_never_reuses_the_id(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    first = store.create(_draft(), source).sample_id
    second = store.create(_draft("the two of them"), source).sample_id
    record = store.delete(second, annotator="c")
    assert record.action is Action.DELETE and record.previous["prompt"] == "the two of them"
    for tree in ("lidar", "radar_5frames"):
        text = (out_root / tree / "ImageSets" / "train.txt").read_text()
        assert text.split() == [first]
    assert [p.sample_id for p in store.pairs()] == [first]
    with pytest.raises(StoreError, match="not listed"):
        store.open(second)
    with pytest.raises(StoreError, match="already deleted"):
        store.delete(second)
    third = store.create(_draft("again"), source).sample_id
    assert int(third) > int(second)
    assert sorted(_assert_loadable(out_root)) == [first, third]


# ------------------------------------------------------------------------------------------ concurrency


def test_two_threads_saving_fifty_pairs_each(
    source_root: Path, out_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Durability is not what this test is about; skipping fsync keeps it fast on slow disks.
    monkeypatch.setattr(os, "fsync", lambda fd: None)
    sources = [SourceFrame.from_root(source_root, 3), SourceFrame.from_root(source_root, 7)]
    AnnotationStore(out_root)
    saved: dict[str, str] = {}
    errors: list[BaseException] = []
    guard = threading.Lock()

    def client(name: str, source: SourceFrame) -> None:
        store = AnnotationStore(out_root)  # one store per client, as per-browser sessions
        try:
            for i in range(50):
                prompt = f"client {name} pair {i}"
                sid = store.create(_draft(prompt), source, annotator=name).sample_id
                with guard:
                    saved[sid] = prompt
        except BaseException as exc:
            errors.append(exc)

    threads = [
        threading.Thread(target=client, args=(n, s)) for n, s in zip("AB", sources, strict=True)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(saved) == 100
    samples = _assert_loadable(out_root)
    assert sorted(samples) == sorted(saved)
    for sid, sample in samples.items():
        assert sample.prompt == saved[sid]
        assert sample.boxes.shape == (2, 7)
    log = read_manifest(out_root / "annotations" / "manifest.jsonl")
    assert len(log.records) == 100 and not log.skipped
    assert len({r.sample_id for r in log.records}) == 100


def test_two_processes_get_distinct_ids(source_root: Path, out_root: Path) -> None:
    source = SourceFrame.from_root(source_root, 3)
    AnnotationStore(out_root)
    pids = []
    for name in ("P", "Q"):
        pid = os.fork()
        if pid == 0:  # child
            code = 0
            try:
                store = AnnotationStore(out_root)
                for i in range(8):
                    store.create(_draft(f"{name} {i}"), source, annotator=name)
            except BaseException:
                code = 1
            os._exit(code)
        pids.append(pid)
    for pid in pids:
        assert os.waitpid(pid, 0)[1] == 0
    samples = _assert_loadable(out_root)
    assert len(samples) == 16
    assert sorted(s.prompt for s in samples.values()) == sorted(
        f"{n} {i}" for n in "PQ" for i in range(8)
    )


# ------------------------------------------------------------------------------------------ crashes


class _Fault:
    """Counts calls of a wrapped function and misbehaves on call number ``at``."""

    def __init__(self, real, at: int | None, action) -> None:
        self.real, self.at, self.action, self.calls = real, at, action, 0

    def __call__(self, *args, **kwargs):
        n = self.calls
        self.calls += 1
        if n == self.at:
            self.action(*args, **kwargs)
        return self.real(*args, **kwargs)


def _raise_crash(*args, **kwargs) -> None:
    raise RuntimeError("simulated crash")


def _count_replaces(monkeypatch: pytest.MonkeyPatch, operation) -> int:
    counter = _Fault(os.replace, None, None)
    monkeypatch.setattr(os, "replace", counter)
    operation()
    monkeypatch.setattr(os, "replace", counter.real)
    return counter.calls


def _listed(root: Path) -> dict[str, list[str]]:
    return {
        f"{tree}/{p.name}": p.read_text().split()
        for tree in ("lidar", "radar_5frames")
        for p in sorted((root / tree / "ImageSets").glob("*.txt"))
    }


def test_save_interrupted_after_each_step_is_undone(
    source_root: Path, out_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    store.create(_draft("an earlier pair"), source)
    n = _count_replaces(monkeypatch, lambda: store.create(_draft("a counted pair"), source))
    assert n >= 12  # journal, 4 links, sidecar, 2 prompts, 2 labels, 2 lists
    for k in range(n):
        before = _snapshot(out_root)
        monkeypatch.setattr(os, "replace", _Fault(os.replace, k, _raise_crash))
        with pytest.raises(SaveError, match=r"simulated crash.*nothing was saved"):
            store.create(_draft(f"crash at step {k}"), source)
        monkeypatch.undo()
        # Undone completely: the root is byte for byte what it was.
        assert _snapshot(out_root) == before, f"step {k}"
    samples = _assert_loadable(out_root)
    assert sorted(s.prompt for s in samples.values()) == ["a counted pair", "an earlier pair"]
    assert store.create(_draft("after the crashes"), source).sample_id == "00002"


def test_manifest_failure_after_the_commit_is_completed_later(
    source_root: Path, out_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)

    def broken(path, line):
        raise OSError(errno.EIO, "simulated I/O error")

    monkeypatch.setattr(manifest_module, "append_line", broken)
    with pytest.raises(SaveError, match="resolved the next time the store opens"):
        store.create(_draft(), source)
    monkeypatch.undo()
    # Committed before the manifest: the sample is complete and listed.
    assert list(_assert_loadable(out_root)) == ["00000"]
    assert list((out_root / "annotations" / "pending").iterdir())
    assert AnnotationStore(out_root).recover() == ()  # opening the store already completed it
    assert [r.sample_id for r in store.records()] == ["00000"]
    assert not list((out_root / "annotations" / "pending").iterdir())


def _crash_in_child(operation, fault_target: str, at: int) -> int:
    """Run ``operation`` in a forked child that dies (``os._exit``) at call ``at`` of
    ``os.<fault_target>``; returns the child's exit status."""
    pid = os.fork()
    if pid == 0:
        try:
            real = getattr(os, fault_target)

            def die(*args, **kwargs):
                if fault_target == "write":  # a torn write: half the bytes, then death
                    fd, data = args
                    real(fd, bytes(data)[: len(data) // 2])
                os._exit(17)

            setattr(os, fault_target, _Fault(real, at, die))
            operation()
        except BaseException:
            os._exit(3)
        os._exit(0)
    return os.waitpid(pid, 0)[1] >> 8


def test_killed_at_every_step_leaves_a_consistent_root(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    sid0 = store.create(_draft("an earlier pair"), source).sample_id
    earlier = {k: v for k, v in _snapshot(out_root).items() if "00000" in k}
    k, outcomes = 0, []
    while True:
        listed_before = _listed(out_root)
        status = _crash_in_child(
            lambda k=k: AnnotationStore(out_root).create(_draft(f"killed at {k}"), source),
            "replace",
            k,
        )
        if status == 0:  # no kill: the save ran through
            break
        assert status == 17
        # Before any recovery: the root loads and lists only complete samples.
        samples = _assert_loadable(out_root)
        listed_after = _listed(out_root)
        if listed_after["lidar/train.txt"] != listed_before["lidar/train.txt"]:
            new = set(listed_after["lidar/train.txt"]) - set(listed_before["lidar/train.txt"])
            assert all(samples[s].prompt == f"killed at {k}" for s in new)
        # Reopening recovers: completed (manifest line written) or undone (files removed).
        outcomes.append(AnnotationStore(out_root).recover() or ("resolved on open",))
        visible = set(_listed(out_root)["lidar/train.txt"])
        manifest_ids = {r.sample_id for r in store.records()}
        assert visible == manifest_ids, f"kill at replace {k}"
        assert not list((out_root / "annotations" / "pending").iterdir())
        for sid in os.listdir(out_root / "lidar" / "training" / "label_2"):
            assert sid.removesuffix(".txt") in visible  # no orphan files left
        k += 1
    assert k >= 12
    assert {k2: v for k2, v in _snapshot(out_root).items() if "00000" in k2} == earlier
    assert sid0 in _assert_loadable(out_root)


def test_killed_in_the_middle_of_the_manifest_line(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    store.create(_draft("an earlier pair"), source)
    status = _crash_in_child(
        lambda: AnnotationStore(out_root).create(_draft("torn"), source), "write", 0
    )
    assert status == 17
    log = read_manifest(store.manifest_path)
    assert len(log.records) == 1 and len(log.skipped) == 1  # the torn line is skipped
    # Committed before the manifest, so the reopened store completes the line after the torn one.
    reopened = AnnotationStore(out_root)
    log = read_manifest(reopened.manifest_path)
    assert [r.prompt for r in log.records] == ["an earlier pair", "torn"]
    reopened.create(_draft("next"), source)
    assert [r.prompt for r in reopened.records()] == ["an earlier pair", "torn", "next"]
    assert len(read_manifest(reopened.manifest_path).skipped) == 1


def test_edit_killed_at_every_step_is_old_or_new(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    sid = store.create(_draft("old prompt"), SourceFrame.from_root(source_root, 3)).sample_id
    prompt_path = out_root / "lidar" / "training" / "prompt" / f"{sid}.txt"
    label_path = out_root / "lidar" / "training" / "label_2" / f"{sid}.txt"
    old = (prompt_path.read_text(), label_path.read_text())
    for k in range(20):
        draft = store.open(sid)
        status = _crash_in_child(
            lambda d=draft: AnnotationStore(out_root).update(
                d.set_prompt("new prompt").delete_box(0)
            ),
            "replace",
            k,
        )
        AnnotationStore(out_root)  # recovery
        state = (prompt_path.read_text(), label_path.read_text())
        if status == 0:
            assert state[0] == "new prompt\n" and len(state[1].splitlines()) == 1
            assert store.version(sid) == 2
            break
        assert state == old, f"kill at replace {k}"
        assert store.version(sid) == 1
    else:
        pytest.fail("the edit never completed")


# ------------------------------------------------------------------------------------------ full disk


def _enospc(*args, **kwargs) -> None:
    raise OSError(errno.ENOSPC, "No space left on device")


def test_disk_full_during_a_save(
    source_root: Path, out_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 7)
    store.create(_draft("an earlier pair"), source)
    counter = _Fault(os.fsync, None, None)
    monkeypatch.setattr(os, "fsync", counter)
    store.create(_draft("a counted pair"), source)
    monkeypatch.undo()
    assert counter.calls >= 8
    for k in range(counter.calls):
        before = _snapshot(out_root)
        monkeypatch.setattr(os, "fsync", _Fault(os.fsync, k, _enospc))
        try:
            store.create(_draft(f"full at fsync {k}"), source)
            completed = True
        except DiskFullError as exc:
            completed = False
            assert "disk is full" in str(exc) and "nothing was saved" in str(exc)
        monkeypatch.undo()
        if completed:  # the failed fsync was a directory sync or the manifest's retry succeeded
            store.delete(store.records()[-1].sample_id)
        else:
            assert _snapshot(out_root) == before, f"fsync {k}"
    prompts = sorted(s.prompt for s in _assert_loadable(out_root).values())
    assert prompts == ["a counted pair", "an earlier pair"]


def test_disk_full_during_an_edit_keeps_the_old_files(
    source_root: Path, out_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = AnnotationStore(out_root)
    sid = store.create(_draft("old prompt"), SourceFrame.from_root(source_root, 3)).sample_id
    draft = store.open(sid).set_prompt("new prompt")
    before = _snapshot(out_root)
    for k in (0, 2, 3, 4, 5, 6):  # 0: the journal; 1: its folder (best effort); 2-6: new files
        monkeypatch.setattr(os, "fsync", _Fault(os.fsync, k, _enospc))
        with pytest.raises(DiskFullError):
            store.update(draft)
        monkeypatch.undo()
        assert _snapshot(out_root) == before
    assert store.update(draft).version == 2


def test_torn_manifest_line_is_skipped_and_terminated(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    store.create(_draft("first"), source)
    with open(store.manifest_path, "a") as handle:
        handle.write('{"format": 1, "op": "dead')
    log = read_manifest(store.manifest_path)
    assert [r.prompt for r in log.records] == ["first"]
    assert log.skipped[0][0] == 2 and "unreadable manifest line" in log.skipped[0][1]
    store.create(_draft("second"), source)
    assert [r.prompt for r in store.records()] == ["first", "second"]
    lines = store.manifest_path.read_text().splitlines()
    assert json.loads(lines[-1])["prompt"] == "second" and len(lines) == 3


# ------------------------------------------------------------------------------------------ reliability
# (issue 11: no input can disable saving; every filesystem error is a store error)


def test_overlong_split_name_is_refused_and_saving_keeps_working(
    source_root: Path, out_root: Path
) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    before = _snapshot(out_root)
    with pytest.raises(SplitError, match="invalid split name"):
        store.create(_draft(), source, split="a" * 300)
    assert _snapshot(out_root) == before  # nothing written, no journal left
    # Saving still works, also for a store opened afterwards (a restart).
    sid = store.create(_draft("after the bad split"), source).sample_id
    edited = AnnotationStore(out_root).update(store.open(sid).set_prompt("edited"))
    assert edited.version == 2
    AnnotationStore(out_root).delete(sid)
    assert AnnotationStore(out_root).pairs() == ()


@pytest.mark.parametrize("split", ["holdout", "b" * 200, "../x", "", "train\n"])
def test_only_the_offered_splits_are_accepted(
    source_root: Path, out_root: Path, split: str
) -> None:
    store = AnnotationStore(out_root)
    assert store.splits == ("train", "val", "test")
    with pytest.raises(SplitError) as info:
        store.create(_draft(), SourceFrame.from_root(source_root, 3), split=split)
    assert "\n" not in str(info.value) and len(str(info.value)) < 200
    lists = out_root / "lidar" / "ImageSets"  # nothing written: not even the folder
    assert not lists.exists() or sorted(p.name for p in lists.iterdir()) == []
    custom = AnnotationStore(out_root, splits=("train", "holdout"))
    assert custom.create(_draft(), SourceFrame.from_root(source_root, 3), split="holdout")


def _write_journal(root: Path, op: str, journal: dict | str) -> Path:
    path = root / "annotations" / "pending" / f"{op}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(journal if isinstance(journal, str) else json.dumps(journal))
    return path


def test_a_journal_recovery_cannot_resolve_is_set_aside(
    source_root: Path, out_root: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # What the old store left behind after a save into a 300-character split: a journal whose
    # recovery fails (ENAMETOOLONG), which made every later operation fail, also after a restart.
    AnnotationStore(out_root)
    (out_root / "lidar" / "ImageSets").mkdir(parents=True)  # a root that was saved into before
    bad = _write_journal(
        out_root,
        "a" * 32,
        {"op": "a" * 32, "action": "create", "sample_id": "00041", "splits": ["a" * 300]},
    )
    torn = _write_journal(out_root, "b" * 32, '{"op": "bbbb", "act')
    with caplog.at_level("WARNING", logger="annotate"):
        store = AnnotationStore(out_root)
    unresolved = out_root / "annotations" / "unresolved"
    assert not bad.exists() and not torn.exists()
    assert sorted(p.name for p in unresolved.iterdir()) == [bad.name, torn.name]
    assert sum("could not be resolved" in r.getMessage() for r in caplog.records) == 2
    result = store.create(_draft(), SourceFrame.from_root(source_root, 3))
    assert result.sample_id == "00042"  # the set-aside journal's id stays reserved
    assert store.recover() == ()


def test_full_disk_during_an_edit_is_disk_full_until_space_is_freed(
    source_root: Path, out_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = AnnotationStore(out_root)
    source = SourceFrame.from_root(source_root, 3)
    sid = store.create(_draft("old prompt"), source).sample_id
    prompt_path = out_root / "lidar" / "training" / "prompt" / f"{sid}.txt"
    disk = {"full": False}
    real_fsync, real_append = os.fsync, manifest_module.append_line

    def fsync(fd: int) -> None:
        if disk["full"]:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    def append(path: Path, line: str) -> None:  # the disk fills up just before the manifest line
        disk["full"] = True
        real_append(path, line)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(manifest_module, "append_line", append)
    with pytest.raises(DiskFullError):
        store.update(store.open(sid).set_prompt("new prompt"))
    monkeypatch.setattr(manifest_module, "append_line", real_append)
    # The old files cannot be written back yet: every later call says so, as a store error.
    for attempt in (
        lambda: store.create(_draft("another"), source),
        lambda: store.delete(sid),
        lambda: store.recover(),
    ):
        with pytest.raises(DiskFullError, match="disk is full"):
            attempt()
    AnnotationStore(out_root)  # opening the store still works (a warning in the log)
    disk["full"] = False  # space freed: the next operation finishes the undo
    assert store.recover() == (f"{sid}: edit rolled back",)
    assert prompt_path.read_text() == "old prompt\n" and store.version(sid) == 1
    assert store.update(store.open(sid).set_prompt("new prompt")).version == 2


def test_filesystem_errors_are_store_errors(source_root: Path, out_root: Path) -> None:
    store = AnnotationStore(out_root)
    sid = store.create(_draft(), SourceFrame.from_root(source_root, 3)).sample_id
    split_list = out_root / "lidar" / "ImageSets" / "train.txt"
    text = split_list.read_bytes()
    split_list.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(StoreError, match=r"train\.txt.*not UTF-8"):
        store.open(sid)
    with pytest.raises(StoreError, match=r"train\.txt"):
        store.create(_draft(), SourceFrame.from_root(source_root, 3))
    split_list.write_bytes(text)
    lock = out_root / "annotations" / ".lock"
    lock.unlink()
    lock.mkdir()  # the lock file cannot be opened
    with pytest.raises(StoreError, match=r"lock file .*\.lock"):
        store.delete(sid)
    AnnotationStore(out_root)  # opening writes nothing (issue 39.7): it takes no lock
    lock.rmdir()
    assert store.delete(sid).action is Action.DELETE
    blocked = out_root.parent / "a-file"
    blocked.write_text("not a folder")
    unusable = AnnotationStore(blocked / "root")  # opening writes nothing; the save says why
    assert unusable.pairs() == ()
    with pytest.raises(StoreError, match=r"a-file/root.*first pair"):
        unusable.create(_draft(), SourceFrame.from_root(source_root, 3))


# ------------------------------------------------------------------------------------------ one format


def _pair_files(root: Path, sid: str) -> dict[str, bytes]:
    """The files a save writes for pair ``sid`` (prompt, labels of both trees, sidecar)."""
    names = [
        f"{tree}/training/{folder}/{sid}.txt"
        for tree in ("lidar", "radar_5frames")
        for folder in ("prompt", "label_2")
    ]
    return {name: (root / name).read_bytes() for name in [*names, f"meta/{sid}.json"]}


def test_create_and_update_write_the_same_files(source_root: Path, tmp_path: Path) -> None:
    """A pair saved by create and the same pair saved by an update of another pair on the same
    frame are the same bytes (the sidecar's version aside)."""
    clock = lambda: "2024-01-01T00:00:00.000+00:00"  # noqa: E731
    draft = _draft("the car on the left and the pedestrian")
    created = AnnotationStore(tmp_path / "a", clock=clock)
    sid = created.create(draft, SourceFrame.from_root(source_root, 3), annotator="ada").sample_id
    edited = AnnotationStore(tmp_path / "b", clock=clock)
    first = Draft().set_prompt("the cyclist").add_box(CYC, "Cyclist")
    assert (
        edited.create(first, SourceFrame.from_root(source_root, 3), annotator="ada").sample_id
        == sid
    )
    reopened = edited.open(sid)
    again = reopened.delete_box(0).set_prompt(draft.prompt)
    for item in draft.boxes:
        again = again.add_box(item.box, item.cls)
    assert edited.update(again, annotator="ada").version == 2
    a, b = _pair_files(tmp_path / "a", sid), _pair_files(tmp_path / "b", sid)
    meta_a, meta_b = json.loads(a.pop(f"meta/{sid}.json")), json.loads(b.pop(f"meta/{sid}.json"))
    assert a == b
    assert meta_a["extra"].pop("version") == 1 and meta_b["extra"].pop("version") == 2
    assert meta_a == meta_b


def test_2d_boxes_are_clipped_to_the_frames_image_in_create_and_update(tmp_path: Path) -> None:
    """A frame with a half-size camera image (P2 scaled to match): a pair made on it links the
    image, and both its create and its update clip the 2D boxes to 968 x 608, not VoD's size."""
    lidar_calib = scale_calibration(vod_lidar_calibration(), 0.5)
    radar_calib = scale_calibration(vod_radar_calibration(), 0.5)
    writer = Talk2RadarWriter(tmp_path / "half")
    image = np.full((608, 968, 3), 60, np.uint8)
    points = np.zeros((10, 4), np.float32), np.zeros((0, 7), np.float32)
    files = writer.write_sensors("w0", *points, lidar_calib, radar_calib, image)
    writer.write_sample(0, files, np.array([CAR]), ["Car"], "the car", calib=lidar_calib)
    writer.write_image_sets({"train": [0]})
    edge = (9.0, -5.0, -0.9, 4.0, 1.8, 1.5, 0.1)  # half out of the image on the right
    store = AnnotationStore(tmp_path / "out")
    draft = Draft().set_prompt("the car on the right").add_box(edge, "Car")
    sid = store.create(draft, SourceFrame.from_root(tmp_path / "half", 0)).sample_id
    saved = Talk2RadarRoot(tmp_path / "out").load(sid)
    assert saved.image_size == (968, 608)
    source_image = tmp_path / "half" / "sources" / "w0" / "image.jpg"
    assert saved.image_path.stat().st_ino == source_image.stat().st_ino
    created = saved.labels[0].bbox
    assert created[2] == 968.0 and 0 < created[0] < 968  # clipped at the image's right edge
    store.update(store.open(sid).set_prompt("the car at the right edge"))
    updated = Talk2RadarRoot(tmp_path / "out").load(sid).labels[0].bbox
    assert updated[2] == 968.0  # the reopened box went through label_2's 6 decimals
    np.testing.assert_allclose(updated, created, atol=1e-3)
