"""Calibration and label_2 formats: parsing, round trips, camera <-> LiDAR conversion."""

import numpy as np
import pytest

from scenes.frame.kitti import (
    LabelError,
    boxes_to_labels,
    format_label_line,
    labels_to_boxes,
    parse_label_line,
    read_label_file,
)
from scenes.geometry.calib import (
    Calibration,
    CalibrationError,
    CameraBoxes,
    boxes_2d,
    boxes_camera_to_lidar,
    boxes_lidar_to_camera,
    read_calib,
    sensor_to_lidar,
    vod_lidar_calibration,
    vod_radar_calibration,
)

VOD_LINE = (
    "bicycle 0 0 -1.7082341282155236 1232.0646 764.3699 1357.1787 941.79224 1.2025487345784636 "
    "0.7674832523233814 2.0832321651914945 2.8273591387840566 2.50387833304944 12.884601376284115 "
    "-1.4922208312468788 1"
)

VOD_CALIB = """P0: 1495.468642 0.0 961.272442 0.0 0.0 1495.468642 624.89592 0.0 0.0 0.0 1.0 0.0
P1: 1495.468642 0.0 961.272442 0.0 0.0 1495.468642 624.89592 0.0 0.0 0.0 1.0 0.0
P2: 1495.468642 0.0 961.272442 0.0 0.0 1495.468642 624.89592 0.0 0.0 0.0 1.0 0.0
P3: 1495.468642 0.0 961.272442 0.0 0.0 1495.468642 624.89592 0.0 0.0 0.0 1.0 0.0
R0_rect: 1.0 0.0 0.0 0.0 1.0 0.0 0.0 0.0 1.0
Tr_velo_to_cam: 0 -1 0 0.15 0 0 -1 -0.46 1 0 0 -0.92

Tr_imu_to_velo:"""


def test_parse_real_vod_line():
    lab = parse_label_line(VOD_LINE)
    assert lab.name == "bicycle" and lab.occluded == 0 and lab.score == 1.0
    assert lab.dimensions_hwl == pytest.approx(
        (1.2025487345784636, 0.7674832523233814, 2.0832321651914945)
    )
    assert lab.location[2] == pytest.approx(12.884601376284115)
    fifteen = parse_label_line(" ".join(VOD_LINE.split()[:15]))
    assert fifteen.score is None
    assert parse_label_line(VOD_LINE.replace("bicycle 0 0", "Car -1 -1")).occluded == -1


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("Car 0 0 1 2 3", "expected 15 or 16 fields"),
        (VOD_LINE.replace("1.2025487345784636", "-1.2"), "size must be positive"),
        (VOD_LINE.replace("1.2025487345784636", "0"), "size must be positive"),
        (VOD_LINE.replace("12.884601376284115", "nan"), "non-finite"),
        (VOD_LINE.replace("bicycle 0 0", "bicycle 0 x"), "non-numeric"),
        (VOD_LINE.replace("bicycle 0 0", "bicycle 0 0.5"), "occluded must be an integer"),
    ],
)
def test_bad_label_lines(line, message):
    with pytest.raises(LabelError, match=message):
        parse_label_line(line, source="f.txt:3")


def test_label_file_error_names_file_and_line(tmp_path):
    path = tmp_path / "00001.txt"
    path.write_text(VOD_LINE + "\n\nCar 0 0 1\n")
    with pytest.raises(LabelError, match=r"00001\.txt:3"):
        read_label_file(path)


def test_label_line_round_trip():
    lab = parse_label_line(VOD_LINE)
    again = parse_label_line(format_label_line(lab, decimals=10))
    assert again.name == lab.name and again.occluded == lab.occluded
    np.testing.assert_allclose(again.location, lab.location, atol=1e-9)
    np.testing.assert_allclose(again.bbox, lab.bbox, atol=1e-9)
    assert again.rotation_y == pytest.approx(lab.rotation_y)
    assert "  " not in format_label_line(lab)


def test_calib_parse_tolerates_empty_lines_and_round_trips(tmp_path):
    calib = Calibration.from_text(VOD_CALIB)
    np.testing.assert_allclose(calib.P2[0, 0], 1495.468642)
    path = tmp_path / "c.txt"
    path.write_text(calib.to_text())
    again = read_calib(path)
    np.testing.assert_allclose(again.velo_to_cam, calib.velo_to_cam, atol=1e-12)
    np.testing.assert_allclose(again.P2, calib.P2)


@pytest.mark.parametrize("missing", ["P2", "Tr_velo_to_cam"])
def test_calib_missing_key(tmp_path, missing):
    text = "\n".join(line for line in VOD_CALIB.splitlines() if not line.startswith(missing + ":"))
    path = tmp_path / "00042.txt"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=rf"00042\.txt: missing {missing}"):
        read_calib(path)


def test_calib_bad_value_names_line():
    with pytest.raises(CalibrationError, match=r"x\.txt:5: R0_rect needs 9 values"):
        Calibration.from_text(VOD_CALIB.replace("R0_rect: 1.0 0.0", "R0_rect: 1.0"), source="x.txt")


def test_camera_to_lidar_worked_example():
    # Untilted camera: x_cam = -y_lidar + 0.15, y_cam = -z_lidar - 0.46, z_cam = x_lidar - 0.92.
    calib = Calibration.from_text(VOD_CALIB)
    cam = CameraBoxes(
        location=np.array([[-2.85, 1.19, 11.08]]),  # bottom centre
        dimensions_hwl=np.array([[1.5, 1.8, 4.2]]),
        rotation_y=np.array([-1.9707963267948966]),
    )
    box = boxes_camera_to_lidar(cam, calib)[0]
    # x = z_cam + 0.92 = 12; y = -(x_cam - 0.15) = 3; bottom z = -(y_cam + 0.46) = -1.65,
    # centre z = -1.65 + h/2 = -0.9; dims (l, w, h) = (4.2, 1.8, 1.5); yaw = -ry - pi/2 = 0.4.
    np.testing.assert_allclose(box, [12, 3, -0.9, 4.2, 1.8, 1.5, 0.4], atol=1e-12)
    back = boxes_lidar_to_camera(box[None], calib)
    np.testing.assert_allclose(back.location, cam.location, atol=1e-12)
    np.testing.assert_allclose(back.dimensions_hwl, cam.dimensions_hwl)
    np.testing.assert_allclose(back.rotation_y, cam.rotation_y, atol=1e-12)


def test_projected_2d_box_of_a_box_straight_ahead():
    calib = vod_lidar_calibration()
    # A 2 m cube whose camera-frame centre is on the optical axis, 10.92 - 0.92 = 10 m ahead.
    box = np.array([[10.92, 0.15, -0.46, 2, 2, 2, 0.0]])
    bbox = boxes_2d(boxes_lidar_to_camera(box, calib), calib)[0]
    f, cx, cy = 1495.468642, 961.272442, 624.89592
    # The nearest face is at depth 9, spanning +-1 m: u in cx +- f/9.
    np.testing.assert_allclose(bbox, [cx - f / 9, cy - f / 9, cx + f / 9, cy + f / 9], atol=1e-6)


def test_labels_round_trip_and_unknown_classes_kept_out():
    calib = vod_lidar_calibration()
    rng = np.random.default_rng(3)
    boxes = np.c_[
        rng.uniform(3, 50, 20),
        rng.uniform(-20, 20, 20),
        rng.uniform(-1.5, 0, 20),
        rng.uniform(0.5, 5, (20, 3)),
        rng.uniform(-np.pi, np.pi, 20),
    ]
    classes = ["Car", "Pedestrian", "Cyclist", "bicycle"] * 5
    labels = [
        parse_label_line(format_label_line(lab, 6))
        for lab in boxes_to_labels(boxes, classes, calib)
    ]
    back, names = labels_to_boxes(labels, calib)
    keep = [i for i, c in enumerate(classes) if c != "bicycle"]
    assert names == tuple(classes[i] for i in keep)
    diff = back - boxes[keep]
    diff[:, 6] = (diff[:, 6] + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(diff).max() < 1e-4


def test_boxes_to_labels_rejects_bad_size():
    with pytest.raises(ValueError, match="box 1 has a non-positive size"):
        boxes_to_labels(
            np.array([[10, 0, 0, 1, 1, 1, 0], [10, 0, 0, 1, -1, 1, 0]]),
            ["Car", "Car"],
            vod_lidar_calibration(),
        )


def test_radar_calibration_places_radar_ahead_and_below():
    t = sensor_to_lidar(vod_lidar_calibration(), vod_radar_calibration())
    np.testing.assert_allclose(t[:3, 3], [2.51, 0.0, -1.15], atol=1e-12)
    np.testing.assert_allclose(t[:3, :3], np.eye(3), atol=1e-12)


# ------------------------------------------------------------------------------------------ reliability
# (issue 11: one error type per kind of file, one line naming it)


def test_singular_calibration_is_refused_with_the_source():
    zero = " ".join(["0"] * 12)
    text = VOD_CALIB.replace("Tr_velo_to_cam: 0 -1 0 0.15 0 0 -1 -0.46 1 0 0 -0.92", "")
    with pytest.raises(CalibrationError, match=r"c\.txt: R0_rect · Tr_velo_to_cam is singular"):
        Calibration.from_text(text + f"\nTr_velo_to_cam: {zero}\n", source="c.txt")
    flat = text.replace("R0_rect: 1.0 0.0 0.0 0.0 1.0 0.0 0.0 0.0 1.0", "R0_rect: " + "1 " * 9)
    with pytest.raises(CalibrationError, match="singular"):
        Calibration.from_text(flat + "\nTr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n", "c.txt")
    huge = VOD_CALIB.replace("0 -1 0 0.15", "1e300 -1e300 0 0.15")
    with pytest.raises(CalibrationError, match="singular"):
        Calibration.from_text(huge, source="c.txt")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"P2: 1 \xff", "not UTF-8"),
        (b"\x00\x01", "binary"),
    ],
)
def test_unreadable_calib_and_label_files(tmp_path, content, message):
    path = tmp_path / "00001.txt"
    path.write_bytes(content)
    with pytest.raises(CalibrationError, match=rf"00001\.txt: the calib file is {message}"):
        read_calib(path)
    with pytest.raises(LabelError, match=rf"00001\.txt: the label file is {message}"):
        read_label_file(path)
    path.unlink()
    path.mkdir()
    with pytest.raises(CalibrationError, match=r"00001\.txt: cannot read the calib file"):
        read_calib(path)
    with pytest.raises(LabelError, match=r"00001\.txt: cannot read the label file"):
        read_label_file(path)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        (VOD_LINE.replace("bicycle 0 0", "bicycle 0 1e300"), "field 3 .* out of range"),
        (VOD_LINE.replace("12.884601376284115", "1e308"), "field 14 .* out of range"),
        (VOD_LINE.replace("1232.0646", "-2e6"), "field 5 .* out of range"),
    ],
)
def test_absurd_label_values_are_refused(line, message):
    with pytest.raises(LabelError, match=message):
        parse_label_line(line, source="f.txt:3")
