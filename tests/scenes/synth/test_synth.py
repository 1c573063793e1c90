"""python -m scenes.synth: a complete, deterministic, resumable Talk2Radar root."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenes import Talk2RadarRoot
from scenes.geometry.boxes import wrap_yaw
from scenes.geometry.calib import vod_lidar_calibration
from scenes.synth.camera import CameraConfig
from scenes.synth.frame import GENERATOR_VERSION
from scenes.synth.generate import (
    MANIFEST,
    SynthError,
    SynthSettings,
    assign_splits,
    generate_root,
    main,
    sensed_actor_ids,
    world_streams,
)
from scenes.synth.lidar import LidarScan
from scenes.synth.radar import RadarScan

FRAMES = 5


@pytest.fixture(scope="module")
def root_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "root"
    assert main(["--out", str(out), "--frames", str(FRAMES), "--seed", "3", "--quiet"]) == 0
    return out


def _all_ids(root: Talk2RadarRoot) -> list[str]:
    return sorted(i for split in ("train", "val", "test") for i in root.ids(split))


def test_cli_writes_a_root_that_loads_back_with_the_same_boxes(root_dir):
    root = Talk2RadarRoot(root_dir)
    assert root.radar_folder == "radar_5frames"
    assert _all_ids(root) == [f"{i:05d}" for i in range(FRAMES)]
    for sid in _all_ids(root):
        sample = root.load(sid)
        meta = sample.meta
        assert sample.prompt and meta is not None and meta.weather == "clear"
        assert meta.radar_scans == 5 and len(meta.referent_ids) == len(sample.boxes) >= 1
        by_id = {a.actor_id: a for a in meta.actors}
        expected = np.array([by_id[i].box for i in meta.referent_ids])
        np.testing.assert_allclose(sample.boxes[:, :6], expected[:, :6], atol=1e-4)
        np.testing.assert_allclose(wrap_yaw(sample.boxes[:, 6] - expected[:, 6]), 0.0, atol=1e-4)
        assert sample.classes == tuple(by_id[i].cls for i in meta.referent_ids)
        assert not set(meta.referent_ids) & set(meta.extra["unsensed_actor_ids"])
        # Street clutter is recorded in the sidecar, never among the labelled referents.
        clutter = meta.extra["clutter"]
        assert {c["cls"] for c in clutter} <= {"bicycle", "bicycle_rack", "moped_scooter"}
        assert set(sample.classes) <= {"Car", "Pedestrian", "Cyclist"}
        assert sample.lidar.shape[1] == 4 and len(sample.lidar) > 10_000
        assert set(np.unique(sample.radar[:, 6]).tolist()) <= {0.0, -1.0, -2.0, -3.0, -4.0}
        # Radar comes back in the LiDAR frame: static points' v_r is the ego-motion term there.
        assert np.isfinite(sample.radar).all() and len(sample.radar) > 100


def test_splits_are_by_world(root_dir):
    root = Talk2RadarRoot(root_dir)
    split_of_world: dict[int, set[str]] = {}
    for split in ("train", "val", "test"):
        for sid in root.ids(split):
            split_of_world.setdefault(root.load_meta(sid).world_id, set()).add(split)
    assert all(len(s) == 1 for s in split_of_world.values())
    # Samples of one world share their sensor files (hard links).
    ids = root.ids("train")
    worlds = [root.load_meta(i).world_id for i in ids]
    if len(ids) > 1 and worlds[0] == worlds[1]:
        a = root_dir / "lidar" / "training" / "velodyne" / f"{ids[0]}.bin"
        b = root_dir / "lidar" / "training" / "velodyne" / f"{ids[1]}.bin"
        assert a.stat().st_ino == b.stat().st_ino


def test_assign_splits_goes_to_the_split_furthest_below_its_share():
    # Hand-computed deficits for (0.5, 0.25, 0.25): train; val (tie 0.5/0.5 -> first); test;
    # then train (deficits 1, 0, 0).
    assert assign_splits(4, (0.5, 0.25, 0.25)) == ["train", "val", "test", "train"]
    assert assign_splits(10, (0.7, 0.1, 0.2)).count("train") == 7
    assert assign_splits(3, (1.0, 0.0, 0.0)) == ["train"] * 3


def test_rerun_skips_complete_worlds_and_redoes_a_partial_one(root_dir):
    settings = SynthSettings(seed=3)
    velodyne = root_dir / "lidar" / "training" / "velodyne"
    before = {p.name: p.read_bytes() for p in velodyne.glob("*.bin")}
    images = root_dir / "lidar" / "training" / "image_2"
    before_images = {p.name: p.read_bytes() for p in images.glob("*.jpg")}
    again = generate_root(root_dir, FRAMES, settings)
    assert again.generated_worlds == 0 and again.samples == FRAMES
    # Break the last world half-way (its label is missing): only that world is redone, exactly.
    lines = (root_dir / MANIFEST).read_text().splitlines()
    last = json.loads(lines[-1])
    (root_dir / "radar_5frames" / "training" / "label_2" / f"{last['ids'][-1]}.txt").unlink()
    (velodyne / f"{last['ids'][-1]}.bin").unlink()
    redo = generate_root(root_dir, FRAMES, settings)
    assert redo.generated_worlds == 1
    after = {p.name: p.read_bytes() for p in velodyne.glob("*.bin")}
    assert after == before
    assert {p.name: p.read_bytes() for p in images.glob("*.jpg")} == before_images
    # An interruption that tore the manifest's last line: the line is dropped, nothing redone.
    lines = (root_dir / MANIFEST).read_text().splitlines()
    with open(root_dir / MANIFEST, "a") as handle:
        handle.write('{"world": 9, "fir')
    assert generate_root(root_dir, FRAMES, settings).generated_worlds == 0
    assert (root_dir / MANIFEST).read_text().splitlines() == lines


def test_same_seed_same_root_and_extension_is_exact(root_dir, tmp_path):
    # Written in two steps (3 then 5 samples) equals written at once.
    generate_root(tmp_path / "b", 3, SynthSettings(seed=3))
    generate_root(tmp_path / "b", FRAMES, SynthSettings(seed=3))
    for tree, folder in (("lidar", "velodyne"), ("radar_5frames", "velodyne"), ("lidar", "prompt")):
        for i in range(FRAMES):
            name = f"{i:05d}.{'bin' if folder == 'velodyne' else 'txt'}"
            a = (root_dir / tree / "training" / folder / name).read_bytes()
            b = (tmp_path / "b" / tree / "training" / folder / name).read_bytes()
            assert a == b, (tree, folder, name)


def test_other_settings_are_refused_and_bad_arguments_are_errors(root_dir, tmp_path, capsys):
    assert main(["--out", str(root_dir), "--frames", "5", "--seed", "4", "--quiet"]) == 2
    assert "generated with" in capsys.readouterr().err
    with pytest.raises(SynthError, match="frames"):
        generate_root(tmp_path / "x", 0)
    with pytest.raises(SynthError, match="split fractions"):
        generate_root(tmp_path / "x", 2, split_fractions=(0.5, 0.5, 0.5))
    with pytest.raises(SynthError, match="radar_scans"):
        SynthSettings(radar_scans=2)
    with pytest.raises(SynthError, match="weather"):
        SynthSettings(weather="snow")
    (tmp_path / "real" / "lidar").mkdir(parents=True)
    with pytest.raises(SynthError, match="without"):
        generate_root(tmp_path / "real", 2)


def test_a_root_of_another_generator_version_is_not_resumed(tmp_path):
    settings = SynthSettings(seed=3, camera=None)
    out = tmp_path / "old"
    out.mkdir()
    old_key = {k: v for k, v in settings.key().items() if k != "generator"}  # version 1 roots
    (out / MANIFEST).write_text(json.dumps({"settings": old_key}) + "\n")
    with pytest.raises(SynthError, match="generated with"):
        generate_root(out, 1, settings)
    assert settings.key()["generator"] == GENERATOR_VERSION


def test_an_unreadable_manifest_line_before_the_last_is_an_error_naming_it(tmp_path):
    settings = SynthSettings(seed=3)
    out = tmp_path / "broken"
    out.mkdir()
    world = {"world": 0, "first_id": 0, "ids": [], "available": 0}
    lines = [{"settings": settings.key()}, "not json", world]
    (out / MANIFEST).write_text(
        "".join(f"{json.dumps(x) if x != 'not json' else x}\n" for x in lines)
    )
    with pytest.raises(SynthError, match=r"synth_manifest\.jsonl:2: unreadable manifest line"):
        generate_root(out, 1, settings)
    (out / MANIFEST).write_text("{}\n")
    with pytest.raises(SynthError, match=r":1: unreadable manifest \(neither the settings nor"):
        generate_root(out, 1, settings)


def test_single_scan_fog_root(tmp_path):
    report = generate_root(
        tmp_path / "fog",
        2,
        SynthSettings(seed=1, weather="fog", radar_scans=1, prompts_per_world=1),
    )
    assert report.samples == 2 and report.worlds >= 2
    root = Talk2RadarRoot(tmp_path / "fog")
    assert root.radar_folder == "radar"
    sample = root.load("00001")
    assert sample.meta.weather == "fog" and sample.meta.radar_scans == 1
    assert (sample.radar[:, 6] == 0).all()
    assert (np.hypot(sample.lidar[:, 0], sample.lidar[:, 1]) > 30).mean() < 0.01


def test_world_streams_depend_on_seed_and_world_only():
    a = world_streams(3, 7)["lidar"].random(4)
    b = world_streams(3, 7)["lidar"].random(4)
    c = world_streams(3, 8)["lidar"].random(4)
    d = world_streams(3, 7)["radar"].random(4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c) and not np.array_equal(a, d)


def test_only_sensed_actors_can_be_referents():
    # Actor 0: 3 LiDAR points; 1: 2 LiDAR points; 2: 1 radar point; 3: nothing; -1/-2: not actors.
    lidar = LidarScan(np.zeros((7, 4), np.float32), np.array([0, 0, 0, 1, 1, -1, -2]))
    radar = RadarScan(np.zeros((3, 7), np.float32), np.array([2, -1, -3]))
    assert sensed_actor_ids(lidar, radar, 3, 1) == (0, 2)
    assert sensed_actor_ids(lidar, radar, 2, 2) == (0, 1)


def test_camera_images_are_written_in_both_trees_and_sit_where_p2_says(root_dir):
    root = Talk2RadarRoot(root_dir)
    sample = root.load("00000")
    lidar_image = root_dir / "lidar" / "training" / "image_2" / "00000.jpg"
    radar_image = root_dir / "radar_5frames" / "training" / "image_2" / "00000.jpg"
    assert sample.image_path == lidar_image
    assert lidar_image.stat().st_ino == radar_image.stat().st_ino  # one file, hard-linked
    assert sample.image.shape == (1216, 1936, 3)  # VoD's size; the calib is VoD's own
    np.testing.assert_array_equal(sample.calib.P2, vod_lidar_calibration().P2)
    # A referent's 2D box covers something other than sky (the camera sees what the label says).
    x1, y1, x2, y2 = (int(v) for v in sample.labels[0].bbox)
    patch = sample.image[y1:y2, x1:x2].astype(float)
    sky = sample.image[:40].reshape(-1, 3).astype(float).mean(axis=0)
    assert np.abs(patch - sky).max(axis=2).mean() > 20


def test_no_camera_changes_nothing_but_the_images(root_dir, tmp_path):
    assert main(["--out", str(tmp_path / "n"), "--frames", "2", "--seed", "3", "--quiet",
                 "--no-camera"]) == 0  # fmt: skip
    assert not (tmp_path / "n" / "lidar" / "training" / "image_2").exists()
    assert "camera" not in (tmp_path / "n" / MANIFEST).read_text().splitlines()[0]
    for tree in ("lidar", "radar_5frames"):
        for folder, ext in (("velodyne", "bin"), ("calib", "txt"), ("label_2", "txt")):
            for i in range(2):
                name = f"{tree}/training/{folder}/{i:05d}.{ext}"
                assert (tmp_path / "n" / name).read_bytes() == (root_dir / name).read_bytes()
    # A root generated with images is not resumed without them (nor the other way round).
    assert main(["--out", str(root_dir), "--frames", str(FRAMES), "--seed", "3", "--quiet",
                 "--no-camera"]) == 2  # fmt: skip


def test_a_smaller_camera_image_scales_p2_and_the_2d_boxes(tmp_path):
    settings = SynthSettings(seed=3, camera=CameraConfig(image_scale=0.25))
    generate_root(tmp_path / "q", 2, settings)
    generate_root(tmp_path / "f", 2, SynthSettings(seed=3, camera=None))
    quarter, full = Talk2RadarRoot(tmp_path / "q").load(0), Talk2RadarRoot(tmp_path / "f").load(0)
    assert quarter.image.shape == (304, 484, 3)
    np.testing.assert_allclose(quarter.calib.P2[:2], full.calib.P2[:2] / 4)
    np.testing.assert_allclose(quarter.radar_calib.P2[:2], full.radar_calib.P2[:2] / 4)
    np.testing.assert_allclose(quarter.boxes, full.boxes, atol=1e-5)  # 3D boxes unchanged
    for q, f in zip(quarter.labels, full.labels, strict=True):
        expected = np.clip(np.array(f.bbox) / 4, 0, [484, 304, 484, 304])
        np.testing.assert_allclose(q.bbox, expected, atol=1e-5)


def test_bad_camera_options_are_one_error_line(tmp_path, capsys):
    argv = ["--out", str(tmp_path / "c"), "--frames", "1", "--quiet", "--camera-scale", "0.125"]
    assert main([*argv, "--camera-ray-step", "4"]) == 2  # 242 x 152 is not a multiple of 4
    assert "error: camera: ray_step" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
