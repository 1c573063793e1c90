"""Augmentations: the left-right flip (one helper for both datasets); sensor augmentations: shapes,
purity, determinism, and what each one changes."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.datasets.augment import (
    beam_index,
    drop_beams,
    drop_points,
    flip_sample,
    jitter_intensity,
    jitter_rcs,
    mirror_actor,
    mirror_boxes,
    mirror_points,
    single_scan,
    subsample_radar,
)
from scenes.datasets.frames import FrameDataset
from scenes.datasets.grounding import AugmentConfig, GroundingDataset
from scenes.geometry.actors import Actor
from scenes.language.prompts import flip_left_right
from scenes.synth.lidar import LidarConfig, beam_elevations
from scenes.talk2radar.root import Talk2RadarRoot


def _lidar(n: int = 4000, seed: int = 0) -> np.ndarray:
    """Points exactly on the beams: random beam, azimuth and range."""
    rng = np.random.default_rng(seed)
    el = np.radians(beam_elevations()[rng.integers(0, 64, n)])
    az = rng.uniform(-0.7, 0.7, n)
    r = rng.uniform(3.0, 60.0, n)
    pts = np.stack(
        [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], axis=1
    )
    return np.hstack([pts, rng.uniform(0, 255, (n, 1))]).astype(np.float32)


def _radar(n: int = 500, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pts = rng.normal(0, 10, (n, 7)).astype(np.float32)
    pts[:, 6] = -rng.integers(0, 5, n)
    return pts


def test_intensity_jitter_is_one_gain_and_offset_clipped():
    pts = _lidar()
    before = pts.copy()
    out = jitter_intensity(pts, np.random.default_rng(3), scale=(1.5, 1.5), offset=(10, 10))
    np.testing.assert_array_equal(pts, before)  # pure
    np.testing.assert_array_equal(out[:, :3], pts[:, :3])
    np.testing.assert_allclose(out[:, 3], np.clip(pts[:, 3] * 1.5 + 10, 0, 255), rtol=1e-6)
    assert out.dtype == np.float32 and out[:, 3].max() == 255.0
    a = jitter_intensity(pts, np.random.default_rng(4))
    b = jitter_intensity(pts, np.random.default_rng(4))
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match=r"points: expected an \(N, 4\)"):
        jitter_intensity(_radar(), np.random.default_rng(0))


def test_random_dropout_keeps_about_one_minus_rate_in_order():
    pts = _lidar(10000)
    out = drop_points(pts, np.random.default_rng(0), 0.3)
    assert 0.67 < len(out) / len(pts) < 0.73
    rows = {tuple(r) for r in pts.tolist()}
    assert all(tuple(r) in rows for r in out[:50].tolist())
    assert len(drop_points(pts, np.random.default_rng(0), 0.0)) == len(pts)
    assert len(drop_points(_radar(), np.random.default_rng(0), 1.0)) == 0
    with pytest.raises(ValueError, match="rate"):
        drop_points(pts, np.random.default_rng(0), 1.5)


def test_beam_dropout_removes_whole_beams():
    pts = _lidar(20000)
    beams = beam_index(pts)
    el = np.degrees(np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1])))
    np.testing.assert_allclose(beam_elevations()[beams], el, atol=1e-3)  # exact beam recovered
    out = drop_beams(pts, np.random.default_rng(5), 0.5)
    kept = set(beam_index(out).tolist())
    assert 16 < len(kept) < 48
    # Every point of a kept beam survives, none of a dropped one.
    assert len(out) == np.isin(beams, list(kept)).sum()
    assert len(drop_beams(pts, np.random.default_rng(5), 0.0)) == len(pts)
    assert len(set(beam_index(pts, LidarConfig()).tolist())) == 64


def test_radar_subsampling_rcs_offset_and_single_scan():
    pts = _radar(400)
    sub = subsample_radar(pts, np.random.default_rng(0), keep=(0.25, 0.25))
    assert len(sub) == 100 and sub.shape[1] == 7
    assert len(subsample_radar(pts[:1], np.random.default_rng(0), keep=(0.0, 0.0))) == 1
    assert len(subsample_radar(pts[:0], np.random.default_rng(0))) == 0
    shifted = jitter_rcs(pts, np.random.default_rng(0), offset_db=(-4.0, -4.0))
    np.testing.assert_allclose(shifted[:, 3], pts[:, 3] - 4.0, atol=1e-5)
    np.testing.assert_array_equal(np.delete(shifted, 3, 1), np.delete(pts, 3, 1))
    noisy = jitter_rcs(pts, np.random.default_rng(0), offset_db=(0.0, 0.0), noise_db=2.0)
    assert 1.7 < np.std(noisy[:, 3] - pts[:, 3]) < 2.3
    one = single_scan(pts)
    assert (one[:, 6] == 0).all() and len(one) == (pts[:, 6] == 0).sum() > 0
    with pytest.raises(ValueError, match=r"points: expected an \(N, 7\)"):
        single_scan(_lidar())
    with pytest.raises(ValueError, match="keep"):
        subsample_radar(pts, np.random.default_rng(0), keep=(0.8, 0.2))


def test_mirror_points_and_boxes_negate_y_and_yaw_and_leave_the_input():
    radar = _radar(50)
    out = mirror_points(radar)
    assert out.dtype == np.float32 and out is not radar
    np.testing.assert_array_equal(out[:, 1], -radar[:, 1])
    np.testing.assert_array_equal(np.delete(out, 1, axis=1), np.delete(radar, 1, axis=1))
    boxes = np.array([[10.0, 2.0, -1.0, 4.0, 2.0, 1.5, 0.3], [5.0, -1.0, -1.0, 1, 1, 1, -np.pi]])
    mirrored = mirror_boxes(boxes)
    assert mirrored.dtype == np.float64 and boxes[0, 1] == 2.0
    np.testing.assert_allclose(mirrored[:, 1], [-2.0, 1.0])
    np.testing.assert_allclose(mirrored[:, 6], [-0.3, -np.pi])  # pi wraps to -pi
    np.testing.assert_allclose(mirror_boxes(mirrored), boxes)  # the mirror is an involution
    assert mirror_boxes(boxes[0]).shape == (1, 7)


def test_mirror_actor_keeps_its_speed_and_radial_velocity():
    a = Actor(3, "Cyclist", np.array([12.0, 4.0, -1.0, 1.8, 0.6, 1.7, 2.0]), np.array([1.0, 2.0]))
    f = mirror_actor(a)
    assert (f.actor_id, f.cls) == (3, "Cyclist")
    np.testing.assert_allclose(f.box, mirror_boxes(a.box)[0])
    np.testing.assert_allclose(f.velocity, [1.0, -2.0])
    assert f.radial_velocity == pytest.approx(a.radial_velocity) and f.speed == a.speed


def test_both_datasets_flip_a_frame_alike(tmp_path, write_tiny_root):
    root = Talk2RadarRoot(write_tiny_root(tmp_path / "root", frames=1))
    sid = root.ids("train")[0]
    sample = root.load(sid)
    always = AugmentConfig(flip_probability=1.0, lidar_keep_min=1.0, shuffle_points=False)
    item = GroundingDataset(root, "train", augment=always)[0]
    frame = FrameDataset(root, "train", augment=always)[0]
    lidar, radar, boxes, prompt = flip_sample(sample.lidar, sample.radar, sample.boxes, "a")
    assert item.flipped and frame.flipped and prompt == flip_left_right("a")
    np.testing.assert_array_equal(item.lidar.numpy(), lidar)
    np.testing.assert_array_equal(frame.lidar, lidar)
    np.testing.assert_array_equal(frame.radar, radar)
    np.testing.assert_array_equal(item.boxes, boxes)
    assert item.prompt == flip_left_right(sample.prompt)
    plain = FrameDataset(root, "train")[0]
    assert not plain.flipped and len(plain.actors) == len(frame.actors) > 0
    for flipped, actor in zip(frame.actors, plain.actors, strict=True):
        np.testing.assert_array_equal(flipped.box, mirror_actor(actor).box)
        np.testing.assert_array_equal(flipped.velocity, mirror_actor(actor).velocity)
