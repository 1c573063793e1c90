"""Reliability round 5 (issue 50), what is read: Talk2Car command text goes through the one text
policy (a refused command is skipped, counted and named: file, command, reason; never fed on);
every malformed sensor file is refused where it is read, naming the file, the point and the
channel (nuScenes LiDAR and radar, Talk2Radar / VoD ``.bin``), and the app shows that frame's
error and keeps serving; two version folders, bad CAM_FRONT intrinsics and an empty ``--split``
list of ``model.adapt`` each give one line saying what is wrong and where.

The nuScenes cases use the session's ``nuscenes_root`` (tests/conftest.py), copied before a change.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from app.serving.navigation import FrameLoadError, FrameStore, Navigator
from model.adapt.config import AdaptError
from model.adapt.frames import UnlabelledFrames
from scenes.datasets.nuscenes_frames import open_talk2car
from scenes.datasets.source import NuScenesSource
from scenes.geometry.classes import VOD
from scenes.nuscenes.root import CAM_FRONT, LIDAR_TOP, NuScenesRoot
from scenes.nuscenes.sensorfiles import (
    SensorFileError,
    radar_dtype,
    read_lidar,
    read_radar,
    write_lidar,
    write_radar,
)
from scenes.nuscenes.tables import NuScenesError
from scenes.nuscenes.talk2car import read_commands
from scenes.talk2radar.layout import LIDAR_FOLDER, split_file
from scenes.talk2radar.pointcloud import PointCloudError, read_points

TABLES = "v1.0-trainval"
"""The version folder of the ``nuscenes_root`` fixture."""


def _one_line(exc: BaseException, *parts: str) -> str:
    """``exc``'s message, checked to be one line holding every one of ``parts``."""
    message = str(exc)
    assert "\n" not in message, message
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"
    return message


def _edit_json(path: Path, change) -> None:
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))  # ensure_ascii: a NUL is written as the escape \u0000


def _tables_copy(source: Path, out: Path) -> Path:
    """``out``: a root whose version folder is a copy of ``source``'s, its sensor files
    ``source``'s own (links: read only)."""
    out.mkdir()
    shutil.copytree(source / TABLES, out / TABLES)
    for name in ("samples", "sweeps"):
        (out / name).symlink_to(source / name)
    return out


# ---------------------------------------------------------------------------- command text

REFUSED = (
    ("stop behind the car\x00 ahead", "U+0000 (NUL)"),
    ("\u202epark next to the truck", "U+202E (RIGHT-TO-LEFT OVERRIDE)"),
    ("follow the bus\u2028then stop", "U+2028 (LINE SEPARATOR)"),
    ("a" * 100_000, "100,000 characters"),
)
"""Command texts the policy refuses (as a JSON escape in the file) and a part of the reason."""


@pytest.fixture(scope="module")
def refused_commands(nuscenes_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the root's command folder whose train commands 0-3 hold :data:`REFUSED` and
    command 4 a text the policy normalises (a double space, a full-width digit)."""
    folder = tmp_path_factory.mktemp("t2c-text") / "commands"
    shutil.copytree(nuscenes_root / "commands", folder)

    def change(data: dict) -> None:
        for cmd, (text, _) in zip(data["commands"], REFUSED, strict=False):
            cmd["command"] = text
        data["commands"][4]["command"] = "  overtake the  car \uff11 metre ahead "

    path = folder / "train_commands.json"
    _edit_json(path, change)
    assert "\\u0000" in path.read_text() and "\\u2028" in path.read_text()
    return folder


def test_command_text_goes_through_the_text_policy(
    nuscenes_root: Path, refused_commands: Path
) -> None:
    root = NuScenesRoot(nuscenes_root)
    path = refused_commands / "train_commands.json"
    records = json.loads(path.read_text())["commands"]
    found = read_commands(refused_commands, "train", root)
    assert len(found.commands) == len(records) - len(REFUSED)
    assert sum(found.skipped.values()) == len(REFUSED)
    for i, (_, why) in enumerate(REFUSED):
        token = records[i]["command_token"]
        named = [r for r in found.skipped if f"command {i} ({token})" in r]
        assert len(named) == 1, found.skipped
        _one_line(ValueError(named[0]), str(path), why)
        assert token not in {c.command_token for c in found.commands}
    kept = {c.command_token: c.text for c in found.commands}
    assert kept[records[4]["command_token"]] == "overtake the car 1 metre ahead"
    for text in kept.values():
        assert text.isprintable() and len(text) <= 500


def test_refused_commands_are_named_by_training_and_the_app(
    nuscenes_root: Path, refused_commands: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = refused_commands / "train_commands.json"
    records = json.loads(path.read_text())["commands"]
    refused = {records[i]["command_token"] for i in range(len(REFUSED))}
    _, found = open_talk2car(nuscenes_root, refused_commands, "train", VOD)
    printed = capsys.readouterr().err
    assert not refused & {c.command_token for c in found.commands}
    for token in refused:
        line = next(line for line in printed.splitlines() if token in line)
        assert str(path) in line and "skipped" in line
    source = NuScenesSource(nuscenes_root, talk2car=refused_commands)
    assert sum(source.skipped["train"].values()) == len(REFUSED)
    served = {
        c.command.command_token: c.command.text
        for s in source.ids("all")
        for c in source.commands(s)
    }
    assert not refused & set(served)
    assert all(text.isprintable() for text in served.values())


# ---------------------------------------------------------------------------- nuScenes radar


def _radar(path: Path, points: int = 3) -> np.ndarray:
    rec = np.zeros(points, dtype=radar_dtype())
    rec["x"], rec["y"], rec["rcs"] = np.arange(1, points + 1), 2.0, 5.0
    write_radar(path, rec)
    return rec


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        (b"WIDTH 3\n", b"WIDTH -1\n", "WIDTH"),
        (b"WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3", b"WIDTH -1\nHEIGHT 1\n"
         b"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS -1", "WIDTH"),
        (b"POINTS 3\n", b"POINTS 5\n", "POINTS"),
        (b"POINTS 3\n", b"POINTS -3\n", "POINTS"),
        (b"WIDTH 3\n", b"WIDTH 2\n", "POINTS"),  # the header disagrees with itself
        (b"WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3", b"WIDTH 2\nHEIGHT 1\n"
         b"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2", "WIDTH / POINTS"),  # a point more than it says
        (b"WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3", b"WIDTH 999999999999\nHEIGHT "
         b"1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 999999999999", "bytes"),  # absurd
        (b"WIDTH 3\n", b"WIDTH 3 3\n", "WIDTH"),
        (b"COUNT 1 1", b"COUNT 2 1", "COUNT"),
        (b"POINTS 3\n", b"", "POINTS"),
    ],
)  # fmt: skip
def test_radar_header_sizes_are_checked(tmp_path: Path, old: bytes, new: bytes, named: str) -> None:
    path = tmp_path / "RADAR_FRONT" / "sweep.pcd"
    path.parent.mkdir()
    _radar(path)
    raw = path.read_bytes()
    assert old in raw
    path.write_bytes(raw.replace(old, new, 1))
    with pytest.raises(SensorFileError) as caught:
        read_radar(path)
    _one_line(caught.value, str(path), named)


@pytest.mark.parametrize(
    ("point", "field", "value"),
    [(1, "x", np.nan), (2, "y", np.nan), (2, "vx_comp", np.inf), (0, "rcs", np.nan),
     (1, "vy", -np.inf), (0, "z", np.inf)],
)  # fmt: skip
def test_radar_nan_or_inf_anywhere_is_named(
    tmp_path: Path, point: int, field: str, value: float
) -> None:
    path = tmp_path / "sweep.pcd"
    rec = _radar(path)
    np.testing.assert_array_equal(read_radar(path), rec)
    rec[field][point] = value
    write_radar(path, rec)
    with pytest.raises(SensorFileError) as caught:
        read_radar(path)
    _one_line(caught.value, str(path), f"point {point} ", repr(field))


def test_an_empty_radar_sweep_still_reads_as_no_point(tmp_path: Path) -> None:
    path = tmp_path / "empty.pcd"
    write_radar(path, np.zeros(0, dtype=radar_dtype()))
    assert len(read_radar(path)) == 0


# ---------------------------------------------------------------------------- LiDAR files


@pytest.mark.parametrize(
    ("point", "column", "name", "value"),
    [(2, 3, "intensity", np.nan), (1, 3, "intensity", np.inf), (3, 4, "ring", np.nan),
     (0, 0, "x", -np.inf)],
)  # fmt: skip
def test_nuscenes_lidar_nan_or_inf_in_any_channel_is_named(
    tmp_path: Path, point: int, column: int, name: str, value: float
) -> None:
    path = tmp_path / "LIDAR_TOP.pcd.bin"
    points = np.arange(20, dtype=np.float32).reshape(4, 5)
    write_lidar(path, points)
    points[point, column] = value
    path.write_bytes(points.astype("<f4").tobytes())
    with pytest.raises(SensorFileError) as caught:
        read_lidar(path)
    _one_line(caught.value, str(path), f"point {point} ", repr(name))


@pytest.mark.parametrize(
    ("features", "point", "column", "name"),
    [(4, 3, 3, "intensity"), (4, 0, 1, "y"), (7, 1, 4, "v_r"), (7, 5, 6, "time"),
     (7, 2, 3, "rcs")],
)  # fmt: skip
def test_talk2radar_point_files_name_the_point_and_channel(
    tmp_path: Path, features: int, point: int, column: int, name: str
) -> None:
    path = tmp_path / "00000.bin"
    points = np.ones((8, features), dtype="<f4")
    points[point, column] = np.nan if point % 2 else np.inf
    points[7, 0] = np.nan  # a later bad point too: the first is named
    path.write_bytes(points.tobytes())
    with pytest.raises(PointCloudError) as caught:
        read_points(path, features)
    _one_line(caught.value, str(path), f"point {point} ", repr(name))


def test_the_app_shows_a_bad_sensor_file_for_its_frame_and_keeps_serving(
    nuscenes_root: Path, tmp_path: Path
) -> None:
    copy = tmp_path / "nusc"
    shutil.copytree(nuscenes_root, copy)
    root = NuScenesRoot(copy)
    records = root.tables.records["sample_data"]
    lidar = copy / records[root.key_data(root.samples[1])[LIDAR_TOP]]["filename"]
    points = read_lidar(lidar)
    points[7, 3] = np.nan  # the intensity of one point
    write_lidar(lidar, points)
    radar = next(
        copy / records[token]["filename"]
        for channel, token in sorted(root.key_data(root.samples[2]).items())
        if channel.startswith("RADAR") and len(read_radar(copy / records[token]["filename"])) > 2
    )
    rec = read_radar(radar)
    rec["x"][2] = np.nan  # the first points are fine
    write_radar(radar, rec)

    nav = Navigator(FrameStore(NuScenesSource(copy), "all"))
    assert nav.load_first().index == 0
    for index, path, named in ((1, lidar, "point 7 has a NaN"), (2, radar, "point 2 has a NaN")):
        with pytest.raises(FrameLoadError) as caught:
            nav.go_to(index)
        assert caught.value.title == f"Could not load frame {index + 1} ({root.samples[index]})"
        assert isinstance(caught.value.cause, SensorFileError)
        _one_line(caught.value, str(path), named)
        assert nav.frame.index == 0  # the frame on screen stays
    assert nav.go_to(3).index == 3  # and the others still load


# ---------------------------------------------------------------------------- smaller items


def test_two_version_folders_say_what_was_found_and_what_to_do(
    nuscenes_root: Path, tmp_path: Path
) -> None:
    root = _tables_copy(nuscenes_root, tmp_path / "nusc")
    shutil.copytree(root / TABLES, root / "v1.0-mini")
    with pytest.raises(NuScenesError) as caught:
        NuScenesRoot(root)
    message = _one_line(caught.value, str(root), "v1.0-mini", TABLES, "move the others out")
    assert "version=" not in message  # no command offers a version option


@pytest.mark.parametrize(
    ("row", "column", "value"),
    [(0, 0, 0.0), (1, 1, 0.0), (0, 0, -800.0), (1, 1, -1.0), (2, 2, 0.0), (0, 0, float("nan"))],
)
def test_bad_cam_front_intrinsics_are_refused_naming_the_record(
    nuscenes_root: Path, tmp_path: Path, row: int, column: int, value: float
) -> None:
    root = _tables_copy(nuscenes_root, tmp_path / "nusc")
    folder = root / TABLES
    sensors = json.loads((folder / "sensor.json").read_text())
    camera = {s["token"] for s in sensors if s["channel"] == CAM_FRONT}
    calibrated = json.loads((folder / "calibrated_sensor.json").read_text())
    tokens = [c["token"] for c in calibrated if c["sensor_token"] in camera]
    nusc = NuScenesRoot(root)
    assert tokens and nusc.frame(nusc.samples[0]).calib is not None  # the copy as it came

    def change(records: list) -> None:
        for record in records:
            if record["token"] in tokens:
                record["camera_intrinsic"][row][column] = value

    _edit_json(folder / "calibrated_sensor.json", change)
    with pytest.raises(NuScenesError) as caught:
        nusc = NuScenesRoot(root)
        nusc.frame(nusc.samples[0])
    message = _one_line(caught.value, "calibrated_sensor.json", "'camera_intrinsic'")
    assert any(token in message for token in tokens), message


def test_adapt_on_an_empty_split_names_the_split_list(tmp_path: Path, write_tiny_root) -> None:
    root = write_tiny_root(tmp_path / "t2r", frames=1)
    listed = split_file(root / LIDAR_FOLDER, "val")
    listed.write_text("\n")
    with pytest.raises(AdaptError) as caught:
        UnlabelledFrames(root, split="val")
    message = _one_line(caught.value, str(listed), "val")
    assert "velodyne" not in message
    assert len(UnlabelledFrames(root, split="test")) == 1


@pytest.mark.parametrize(
    ("old", "new", "named"),
    [
        (b"VIEWPOINT 0 0 0 1 0 0 0", b"VIEWPOINT 5 0 0 1 0 0 0", "VIEWPOINT"),  # would move
        (b"VIEWPOINT 0 0 0 1 0 0 0", b"VIEWPOINT 0 0 0 0.7071 0 0 0.7071", "VIEWPOINT"),
        (b"VIEWPOINT 0 0 0 1 0 0 0", b"VIEWPOINT 0 0 0", "VIEWPOINT"),
        (b"VIEWPOINT 0 0 0 1 0 0 0", b"VIEWPOINT a b c d e f g", "VIEWPOINT"),
        (b"VIEWPOINT 0 0 0 1 0 0 0\n", b"", "VIEWPOINT"),  # missing: the devkit reads by place
        (b"VERSION 0.7", b"VERSION 0.5", "VERSION"),
        (b"VERSION 0.7\n", b"", "VERSION"),
        (b"HEIGHT 1\n", b"HEIGHT 1\nWIDTH 3\n", "VIEWPOINT"),  # a line repeated
        (b"HEIGHT 1\n", b"HEIGHT 1\nCOLOR 1\n", "VIEWPOINT"),  # an unknown line
        (b"WIDTH 3\nHEIGHT 1\n", b"HEIGHT 1\nWIDTH 3\n", "WIDTH"),  # out of order
    ],
)  # fmt: skip
def test_radar_header_lines_and_viewpoint_are_checked(
    tmp_path: Path, old: bytes, new: bytes, named: str
) -> None:
    """Every header line is the release's, in its place; a VIEWPOINT other than the identity
    would move every point (read as if it were the identity before) and is refused."""
    path = tmp_path / "sweep.pcd"
    _radar(path)
    raw = path.read_bytes()
    assert old in raw
    path.write_bytes(raw.replace(old, new, 1))
    with pytest.raises(SensorFileError) as caught:
        read_radar(path)
    _one_line(caught.value, str(path), named)
    path.write_bytes(raw.replace(b"VIEWPOINT 0 0 0 1 0 0 0", b"VIEWPOINT 0.0 0 0 1.0 0 0 -0"))
    assert len(read_radar(path)) == 3  # the identity, however spelled
