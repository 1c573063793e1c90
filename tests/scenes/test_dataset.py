"""GroundingDataset: items, collation, and augmentations that keep the prompt true."""

import numpy as np
import pytest

from scenes import Talk2RadarWriter
from scenes.datasets.augment import flip_sample
from scenes.datasets.grounding import AugmentConfig, GroundingDataset, collate
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.language.prompts import flip_left_right

BOXES = np.array([[12.0, 3.0, -0.9, 4.2, 1.8, 1.5, 0.4]])


@pytest.fixture
def root(tmp_path):
    rng = np.random.default_rng(0)
    writer = Talk2RadarWriter(tmp_path)
    lidar = rng.uniform(-10, 10, (300, 4)).astype(np.float32)
    radar = rng.uniform(-10, 10, (30, 7)).astype(np.float32)
    files = writer.write_sensors(
        "w0", lidar, radar, vod_lidar_calibration(), vod_radar_calibration()
    )
    for i in range(3):
        writer.write_sample(i, files, BOXES, ["Car"], "the car about 10 m ahead on the left")
    writer.write_image_sets({"train": [0, 1, 2], "val": []})
    return tmp_path


def test_items_and_collate(root):
    ds = GroundingDataset(root, "train")
    assert len(ds) == 3
    item = ds[1]
    assert item.lidar.shape == (300, 4) and item.radar.shape == (30, 7)
    np.testing.assert_allclose(item.boxes, BOXES, atol=1e-4)
    batch = collate([ds[0], ds[2]])
    assert len(batch) == 2 and batch.sample_ids == ("00000", "00002")
    assert batch.prompts[0] == "the car about 10 m ahead on the left"


def test_empty_split_is_an_error(root):
    with pytest.raises(ValueError, match="split 'val' has no samples"):
        GroundingDataset(root, "val")


def test_flip_mirrors_geometry_and_words():
    lidar = np.array([[5.0, 2.0, 0.0, 10.0]], dtype=np.float32)
    radar = np.array([[6.0, -1.0, 0.0, 1.0, -2.0, -3.0, 0.0]], dtype=np.float32)
    l2, r2, b2, p2 = flip_sample(lidar, radar, BOXES, "the car on the left, right next to us")
    assert l2[0, 1] == -2.0 and r2[0, 1] == 1.0
    assert r2[0, 5] == -3.0  # radial velocities are unchanged by the mirror
    np.testing.assert_allclose(b2[0], [12.0, -3.0, -0.9, 4.2, 1.8, 1.5, -0.4])
    assert p2 == flip_left_right("the car on the left, right next to us")
    assert "right" in p2.split(",")[0]
    assert lidar[0, 1] == 2.0  # inputs untouched


def test_augmentation_is_deterministic_and_flips_both(root):
    aug = AugmentConfig(flip_probability=1.0, lidar_keep_min=0.5)
    ds = GroundingDataset(root, "train", augment=aug, seed=7)
    a, b = ds[0], ds[0]
    assert a.flipped and a.prompt.endswith("on the right")
    np.testing.assert_allclose(a.boxes[0, 1], -3.0, atol=1e-4)
    assert a.lidar.shape == b.lidar.shape and (a.lidar == b.lidar).all()
    assert 150 <= len(a.lidar) <= 300
    ds.set_epoch(1)
    assert not (ds[0].lidar.shape == a.lidar.shape and (ds[0].lidar == a.lidar).all())


def test_bad_augment_config():
    with pytest.raises(ValueError, match="flip_probability"):
        AugmentConfig(flip_probability=2.0)
