"""Talk2Radar root reading and writing: round trips and clear errors for broken files."""

import numpy as np
import pytest

from scenes import Actor, SampleMeta, Talk2RadarRoot, Talk2RadarWriter
from scenes.frame import RootError
from scenes.frame.kitti import LabelError
from scenes.geometry.calib import CalibrationError, vod_lidar_calibration, vod_radar_calibration
from scenes.talk2radar import layout
from scenes.talk2radar.pointcloud import PointCloudError, read_points
from scenes.talk2radar.root import sample_text

BOXES = np.array([[12.0, 3.0, -0.9, 4.2, 1.8, 1.5, 0.4], [20.0, -5.0, -0.85, 0.7, 0.6, 1.7, -2.9]])


@pytest.fixture
def root(tmp_path):
    rng = np.random.default_rng(0)
    writer = Talk2RadarWriter(tmp_path)
    lidar = rng.uniform(-10, 10, (500, 4)).astype(np.float32)
    radar = rng.uniform(-10, 10, (40, 7)).astype(np.float32)
    files = writer.write_sensors(
        "w00000", lidar, radar, vod_lidar_calibration(), vod_radar_calibration()
    )
    actors = (Actor(0, "Car", BOXES[0], [3, 0]), Actor(1, "Pedestrian", BOXES[1], [0, 1]))
    meta = SampleMeta(tags=frozenset({"class", "motion"}), actors=actors, referent_ids=(0, 1))
    writer.write_sample(1, files, BOXES, ["Car", "Pedestrian"], "the car and the pedestrian", meta)
    writer.write_sample(2, files, BOXES[:1], ["Car"], "  the car  \n", meta)
    writer.write_image_sets({"train": [1], "test": ["00002"]})
    return tmp_path, lidar, radar


def test_round_trip(root):
    path, lidar, radar = root
    r = Talk2RadarRoot(path)
    assert r.radar_folder == "radar_5frames"
    assert r.ids("train") == ["00001"] and r.ids("test") == ["00002"]
    sample = r.load("00001")
    np.testing.assert_array_equal(sample.lidar, lidar)
    # Radar is stored in the radar frame and read back into the LiDAR frame.
    np.testing.assert_allclose(sample.radar, radar, atol=1e-5)
    np.testing.assert_allclose(sample.boxes, BOXES, atol=1e-4)
    assert sample.classes == ("Car", "Pedestrian")
    assert sample.prompt == "the car and the pedestrian"
    assert sample.meta.tags == {"class", "motion"} and sample.meta.actors[1].cls == "Pedestrian"
    assert r.load(2).prompt == "the car"


def test_the_layout_names_every_file_the_writer_writes(root):
    """Every file of the written root is one the layout names (so the annotation store's rollback,
    which deletes exactly those, misses none), and the writer's text is :func:`sample_text`'s."""
    path, _, _ = root
    writer = Talk2RadarWriter(path)
    named: set = set()
    for sid in ("00001", "00002"):
        for tree in writer.trees:
            named |= {layout.sample_file(tree, f, sid, suffix) for f, suffix in layout.SAMPLE_FILES}
        named.add(layout.meta_file(path, sid))
    for tree in writer.trees:
        named |= {layout.split_file(tree, split) for split in ("train", "test")}
    named |= {layout.source_dir(path, "w00000") / name for name in layout.SOURCE_SENSORS}
    on_disk = {p for p in path.rglob("*") if p.is_file()}
    assert on_disk <= named and len(on_disk) == 2 * 2 * 4 + 2 + 4 + 4
    sample = Talk2RadarRoot(path).load(1)
    text = sample_text(
        BOXES,
        ["Car", "Pedestrian"],
        " the car and the pedestrian",
        sample.calib,
        sample.image_size,
        sample.meta,
    )
    for file, content in writer.text_files("00001", text):
        assert file.read_text() == content
    assert [f.parent.name for f, _ in writer.text_files("00001", text)] == [
        "meta",
        "prompt",
        "prompt",
        "label_2",
        "label_2",  # the label last: the sample is complete
    ]


def test_radar_on_disk_is_in_radar_frame(root):
    path, _, radar = root
    raw = read_points(path / "radar_5frames" / "training" / "velodyne" / "00001.bin", 7)
    np.testing.assert_allclose(raw[:, 0], radar[:, 0] - 2.51, atol=1e-5)
    np.testing.assert_allclose(raw[:, 2], radar[:, 2] + 1.15, atol=1e-5)
    np.testing.assert_array_equal(raw[:, 3:], radar[:, 3:])


def test_samples_share_sensor_files_by_hard_link(root):
    path, _, _ = root
    a = path / "lidar" / "training" / "velodyne" / "00001.bin"
    b = path / "lidar" / "training" / "velodyne" / "00002.bin"
    assert a.stat().st_ino == b.stat().st_ino


def test_label_file_has_camera_boxes_with_2d_boxes(root):
    path, _, _ = root
    line = (path / "lidar" / "training" / "label_2" / "00001.txt").read_text().splitlines()[0]
    fields = line.split(" ")
    assert len(fields) == 16 and fields[0] == "Car"
    x1, y1, x2, y2 = map(float, fields[4:8])
    assert 0 <= x1 < x2 <= 1936 and 0 <= y1 < y2 <= 1216 and y2 - y1 > 40


def test_bin_with_bad_size(root):
    path, _, _ = root
    f = path / "lidar" / "training" / "velodyne" / "00001.bin"
    f.unlink()  # break the hard link first
    f.write_bytes(b"\0" * 18)
    with pytest.raises(PointCloudError, match=r"00001\.bin: 18 bytes is not a multiple of 16"):
        Talk2RadarRoot(path).load(1)


def test_bin_with_nan(root):
    path, _, _ = root
    f = path / "radar_5frames" / "training" / "velodyne" / "00001.bin"
    pts = read_points(f, 7)
    pts[3, 1] = np.nan
    f.unlink()
    f.write_bytes(pts.tobytes())
    with pytest.raises(PointCloudError, match=r"00001\.bin: point 3 has a NaN"):
        Talk2RadarRoot(path).load(1)


def test_missing_file_for_listed_id(root):
    path, _, _ = root
    (path / "lidar" / "training" / "calib" / "00002.txt").unlink()
    r = Talk2RadarRoot(path)
    assert r.ids("test") == ["00002"]
    with pytest.raises(RootError, match=r"calib/00002\.txt: missing calib file for sample 00002"):
        r.load("00002")


def test_no_prompt_folder_gives_none(root):
    path, _, _ = root
    for p in (path / "lidar" / "training" / "prompt").iterdir():
        p.unlink()
    (path / "lidar" / "training" / "prompt").rmdir()
    assert Talk2RadarRoot(path).load(1).prompt is None


def test_bad_root_and_split(tmp_path, root):
    with pytest.raises(RootError, match="no lidar/ folder"):
        Talk2RadarRoot(tmp_path / "nothing")
    path, _, _ = root
    with pytest.raises(RootError, match="split 'val' not found"):
        Talk2RadarRoot(path).ids("val")
    with pytest.raises(RootError, match="radar tree 'radar' not found"):
        Talk2RadarRoot(path, radar="radar")
    assert len(Talk2RadarRoot(path, radar=None).load(1).radar) == 0


def test_empty_prompt_is_refused(root, tmp_path):
    path, lidar, radar = root
    writer = Talk2RadarWriter(path)
    files = writer.write_sensors(
        "w1", lidar, radar, vod_lidar_calibration(), vod_radar_calibration()
    )
    with pytest.raises(ValueError, match="prompt is empty"):
        writer.write_sample(9, files, BOXES, ["Car", "Car"], "   ")


# ------------------------------------------------------------------------------------------ reliability
# (issue 11: every unreadable file is one error naming it, never a bare exception)


@pytest.mark.parametrize(
    ("relative", "content", "error", "message"),
    [
        ("lidar/training/prompt/00001.txt", b"the car \xff\xfe", RootError, "not UTF-8"),
        ("lidar/training/prompt/00001.txt", b"the\x00car", RootError, "binary"),
        ("lidar/training/prompt/00001.txt", b" \n\t\n", RootError, "prompt file .* is empty"),
        ("lidar/training/label_2/00001.txt", b"\x89PNG\r\n\x1a\n\x00\x00", LabelError, "not UTF"),
        ("lidar/training/calib/00001.txt", b"P2: \xc3\x28", CalibrationError, "not UTF-8"),
        ("radar_5frames/training/calib/00001.txt", b"\x00" * 8, CalibrationError, "binary"),
        ("meta/00001.json", b"\xff", RootError, "not UTF-8"),
        ("meta/00001.json", b"[1, 2]", RootError, "malformed sidecar"),
        ("meta/00001.json", b'{"world_id": 1e400}', RootError, "malformed sidecar"),
    ],
)
def test_unreadable_files_name_the_file(root, relative, content, error, message):
    path, _, _ = root
    target = path / relative
    target.unlink()  # break a hard link first
    target.write_bytes(content)
    with pytest.raises(error, match=message) as info:
        Talk2RadarRoot(path).load(1)
    assert str(target) in str(info.value) and "\n" not in str(info.value)


def test_a_folder_or_a_symlink_loop_instead_of_a_file(root):
    path, _, _ = root
    label = path / "lidar" / "training" / "label_2" / "00001.txt"
    label.unlink()
    label.symlink_to(label)  # a loop
    with pytest.raises(LabelError, match=r"00001\.txt: cannot read the label file"):
        Talk2RadarRoot(path).load(1)
    label.unlink()
    label.mkdir()
    with pytest.raises(LabelError, match=r"00001\.txt: cannot read the label file"):
        Talk2RadarRoot(path).load(1)
    velodyne = path / "lidar" / "training" / "velodyne" / "00002.bin"
    velodyne.unlink()
    velodyne.mkdir()
    with pytest.raises(PointCloudError, match=r"00002\.bin: cannot read the point-cloud file"):
        Talk2RadarRoot(path).load(2)


def test_singular_calibration_is_a_calibration_error(root):
    path, _, _ = root
    calib = path / "radar_5frames" / "training" / "calib" / "00001.txt"
    text = calib.read_text()
    calib.unlink()
    zero = " ".join(["0"] * 12)
    calib.write_text(
        "\n".join(
            f"Tr_velo_to_cam: {zero}" if line.startswith("Tr_velo_to_cam") else line
            for line in text.splitlines()
        )
    )
    with pytest.raises(CalibrationError, match=r"00001\.txt: R0_rect · Tr_velo_to_cam is singular"):
        Talk2RadarRoot(path).load(1)


def test_duplicate_split_ids_are_an_error(root):
    path, _, _ = root
    split = path / "lidar" / "ImageSets" / "test.txt"
    split.write_text("00002\n00001\n00002\n")
    with pytest.raises(RootError, match=r"test\.txt:3: sample 00002 is listed twice"):
        Talk2RadarRoot(path).ids("test")
    split.write_bytes(b"00002\n\xff\n")
    with pytest.raises(RootError, match=r"test\.txt: the split list is not UTF-8"):
        Talk2RadarRoot(path).ids("test")
