"""Camera images in a Talk2Radar root: written once and hard-linked into both trees, read lazily
as ``Sample.image``, None without ``image_2``, and clear errors for broken files."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from scenes import Talk2RadarRoot, Talk2RadarWriter
from scenes.frame.image import ImageError, encode_jpeg, read_image
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.geometry.projection import scale_calibration

BOX = np.array([[12.0, 3.0, -0.9, 4.2, 1.8, 1.5, 0.4]])


def _image(width: int, height: int) -> np.ndarray:
    """A smooth test picture (JPEG keeps it to within a few levels)."""
    u, v = np.meshgrid(np.linspace(0, 1, width), np.linspace(0, 1, height))
    return (np.stack([u, v, 0.5 * (u + v)], axis=-1) * 200 + 20).astype(np.uint8)


def _root(tmp_path, image: np.ndarray | None, scale: float = 1.0):
    writer = Talk2RadarWriter(tmp_path)
    rng = np.random.default_rng(0)
    lidar = rng.uniform(-10, 10, (200, 4)).astype(np.float32)
    radar = rng.uniform(-10, 10, (20, 7)).astype(np.float32)
    lidar_calib = scale_calibration(vod_lidar_calibration(), scale)
    radar_calib = scale_calibration(vod_radar_calibration(), scale)
    files = writer.write_sensors("w0", lidar, radar, lidar_calib, radar_calib, image=image)
    for sid in (1, 2):
        writer.write_sample(sid, files, BOX, ["Car"], "the car", calib=lidar_calib)
    writer.write_image_sets({"train": [1, 2]})
    return Talk2RadarRoot(tmp_path)


def test_image_is_hard_linked_and_read_lazily(tmp_path):
    picture = _image(968, 608)
    root = _root(tmp_path, picture, scale=0.5)
    a = tmp_path / "lidar" / "training" / "image_2" / "00001.jpg"
    b = tmp_path / "radar_5frames" / "training" / "image_2" / "00002.jpg"
    source = tmp_path / "sources" / "w0" / "image.jpg"
    assert a.stat().st_ino == b.stat().st_ino == source.stat().st_ino
    sample = root.load(1)
    assert sample.image_path == a and "image" not in sample.__dict__  # nothing decoded yet
    image = sample.image
    assert image.shape == (608, 968, 3) and image.dtype == np.uint8
    assert np.abs(image.astype(int) - picture).mean() < 2  # JPEG, quality 90
    assert sample.image is image  # decoded once
    # The 2D box of label_2 is clipped to the 968 x 608 image: half of the full-size one.
    full = _root(tmp_path / "full", _image(1936, 1216)).load(1).labels[0].bbox
    np.testing.assert_allclose(sample.labels[0].bbox, np.array(full) / 2, atol=1e-5)


def test_a_root_without_image_2_has_no_image(tmp_path):
    sample = _root(tmp_path, None).load(2)
    assert sample.image_path is None and sample.image is None
    assert not (tmp_path / "lidar" / "training" / "image_2").exists()


def test_a_corrupt_or_truncated_jpeg_is_an_error_naming_the_file(tmp_path):
    root = _root(tmp_path, _image(1936, 1216))
    path = tmp_path / "lidar" / "training" / "image_2" / "00001.jpg"
    data = path.read_bytes()
    path.unlink()  # break the link: the radar tree and the other sample keep the good file
    path.write_bytes(data[: len(data) // 2])
    sample = root.load(1)  # loading the sample does not decode the image
    with pytest.raises(ImageError, match=r"00001\.jpg: corrupt or truncated"):
        _ = sample.image
    path.write_bytes(b"\xff\xd8 this is not a JPEG at all")
    with pytest.raises(ImageError, match=r"00001\.jpg"):
        _ = root.load(1).image
    path.write_bytes(b"")
    with pytest.raises(ImageError, match=r"00001\.jpg: the image file is empty"):
        _ = root.load(1).image
    assert root.load(2).image.shape == (1216, 1936, 3)
    with pytest.raises(ImageError, match="not found"):
        read_image(tmp_path / "nope.jpg")


def test_an_image_whose_size_disagrees_with_p2_warns(tmp_path):
    root = _root(tmp_path, None)  # VoD's full-size P2
    folder = tmp_path / "lidar" / "training" / "image_2"
    folder.mkdir(parents=True)
    (folder / "00001.jpg").write_bytes(encode_jpeg(_image(968, 608)))  # a half-size image
    with pytest.warns(UserWarning, match=r"00001\.jpg: the image is 968 x 608 but P2"):
        assert root.load(1).image.shape == (608, 968, 3)
    (folder / "00002.jpg").write_bytes(encode_jpeg(_image(1936, 1216)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert root.load(2).image.shape == (1216, 1936, 3)  # VoD's own size: no warning
    # The writer refuses to write such a pair in the first place.
    with pytest.raises(ValueError, match="principal point"):
        _root(tmp_path / "bad", _image(968, 608), scale=1.0)
