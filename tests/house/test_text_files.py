"""Files as people save them (issue 39.1): one reading policy for every text file read
(scenes.utils.textfile). A leading UTF-8 byte-order mark is removed and said once per root, CRLF is
read as LF, anything else odd is refused with one line naming the file and the line.

One test per file kind with a BOM: each reads what the same file without the mark reads (before
the policy, the mark stuck to the first field: a label's first object dropped, a calib's P0 lost,
a prompt fed to training as "\\ufeffthe car", JSON and split lists refused).
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from annotate import AnnotationStore, SourceFrame, default_box
from annotate.draft import Draft
from annotate.review import record_review
from bench.studies.language_cases import SUITE_FILE, SuiteError, load_suite
from model.evaluation.files import load_label_dir, score_directories
from model.evaluation.pipeline import write_json
from model.evaluation.results_table import load_row
from scenes.frame import RootError
from scenes.frame.kitti import LabelError, read_label_file
from scenes.frame.sample_meta import SampleMeta
from scenes.geometry.calib import CalibrationError, read_calib
from scenes.talk2radar.layout import (
    CALIB,
    LABEL,
    LIDAR_FOLDER,
    PROMPT,
    manifest_file,
    sample_file,
    split_file,
)
from scenes.talk2radar.poses import Pose, read_pose, write_pose
from scenes.talk2radar.reviews import approved_ids
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.scene_labels import SceneLabels
from scenes.utils.textfile import BOM, read_text_file, root_of

UTF8_BOM = BOM


def _add_bom(path: Path) -> None:
    path.write_bytes(UTF8_BOM + path.read_bytes())


def _twin(tmp_path: Path, root: Path) -> Path:
    """A copy of ``root`` (files copied, not linked) beside it."""
    copy = tmp_path / f"{root.name}-bom"
    shutil.copytree(root, copy)
    return copy


@pytest.fixture
def tiny(tmp_path: Path, write_tiny_root) -> tuple[Path, Path]:
    root = write_tiny_root(tmp_path / "plain", frames=2)
    return root, _twin(tmp_path, root)


def _quiet(fn, *args):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return fn(*args)


def test_a_talk2radar_label_2_with_a_bom_keeps_its_first_object(tiny) -> None:
    plain, bom = tiny
    _add_bom(sample_file(bom / LIDAR_FOLDER, LABEL, "00000"))
    a = Talk2RadarRoot(plain).load("00000")
    b = _quiet(Talk2RadarRoot(bom).load, "00000")
    assert b.classes == a.classes == ("Car",)
    np.testing.assert_array_equal(b.boxes, a.boxes)
    assert b.labels == a.labels


def test_a_view_of_delft_label_2_with_a_bom_keeps_every_object(tmp_path, write_vod_root) -> None:
    plain = write_vod_root(tmp_path / "vod", frames=1)
    bom = _twin(tmp_path, plain)
    _add_bom(sample_file(bom / LIDAR_FOLDER, LABEL, "00000"))
    a = SceneLabels(plain).load("00000")
    b = _quiet(SceneLabels(bom).load, "00000")
    assert len(a.metric()[1]) > 1
    np.testing.assert_array_equal(b.metric()[0], a.metric()[0])
    np.testing.assert_array_equal(b.metric()[1], a.metric()[1])


def test_a_prompt_file_with_a_bom_is_the_sentence_the_app_would_run(tiny) -> None:
    plain, bom = tiny
    _add_bom(sample_file(bom / LIDAR_FOLDER, PROMPT, "00001"))
    assert _quiet(Talk2RadarRoot(bom).load_prompt, 1) == Talk2RadarRoot(plain).load_prompt(1)
    assert _quiet(Talk2RadarRoot(bom).load, 1).prompt == "the car about 15 m ahead"


def test_a_calib_file_with_a_bom_keeps_its_first_matrix(tiny) -> None:
    plain, bom = tiny
    path = sample_file(bom / LIDAR_FOLDER, CALIB, "00000")
    for root in (plain, bom):  # a P0 of its own (the reader fills a missing P0 with P2)
        file = sample_file(root / LIDAR_FOLDER, CALIB, "00000")
        first, rest = file.read_text().split("\n", 1)
        assert first.startswith("P0:")
        file.write_text("P0: " + " ".join(["2.5"] * 12) + "\n" + rest)
    _add_bom(path)
    a = read_calib(sample_file(plain / LIDAR_FOLDER, CALIB, "00000"))
    assert a.P0[0, 0] == 2.5
    b = _quiet(read_calib, path)
    assert a.P0 is not None and b.P0 is not None
    for key in ("P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam"):
        np.testing.assert_array_equal(getattr(b, key), getattr(a, key))


def test_an_image_sets_list_with_a_bom_lists_the_same_ids(tiny) -> None:
    plain, bom = tiny
    _add_bom(split_file(bom / LIDAR_FOLDER, "test"))
    assert _quiet(Talk2RadarRoot(bom).ids, "test") == Talk2RadarRoot(plain).ids("test")


def test_a_pose_file_with_a_bom_reads_the_same_pose(tiny) -> None:
    plain, bom = tiny
    pose = Pose(np.eye(4), np.eye(4) * 2.0, np.eye(4) * 3.0)
    pose.odom[0, 3] = 4.5
    for root in (plain, bom):
        path = write_pose(root / LIDAR_FOLDER, 0, pose)
    _add_bom(path)
    got = _quiet(read_pose, bom / LIDAR_FOLDER, 0)
    assert got is not None
    np.testing.assert_array_equal(got.odom, pose.odom)
    np.testing.assert_array_equal(got.utm, read_pose(plain / LIDAR_FOLDER, 0).utm)


def test_a_sidecar_with_a_bom_reads_the_same_meta(tiny) -> None:
    plain, bom = tiny
    meta = SampleMeta(tags=frozenset({"depth"}), weather="rain", extra={"annotator": "ada"})
    for root in (plain, bom):
        path = root / "meta" / "00000.json"
        path.parent.mkdir(exist_ok=True)
        path.write_text(json.dumps(meta.to_json(), indent=1))
    _add_bom(path)
    assert _quiet(Talk2RadarRoot(bom).load_meta, 0) == Talk2RadarRoot(plain).load_meta(0) == meta


def test_a_language_suite_with_a_bom_reads_the_same_sentences(tmp_path) -> None:
    path = tmp_path / "suite.json"
    path.write_bytes(UTF8_BOM + SUITE_FILE.read_bytes())
    assert _quiet(load_suite, path).sentences == load_suite(SUITE_FILE).sentences


def test_a_manifest_with_a_bom_keeps_its_first_line(tmp_path, write_tiny_root) -> None:
    root = write_tiny_root(tmp_path / "root", frames=1)
    store = AnnotationStore(root)
    draft = Draft().add_box(default_box("Car", 12.0, 2.0), "Car").set_prompt("the car at 12 m")
    sid = store.save(draft, SourceFrame.from_root(root, 0), annotator="ada").sample_id
    record_review(store, sid, "approved", "rita", version=1)
    assert approved_ids(root, "train") == (sid,)
    _add_bom(manifest_file(root))
    assert _quiet(approved_ids, root, "train") == (sid,)


def test_a_results_file_with_a_bom_reads_the_same_row(tmp_path, write_vod_root) -> None:
    folder = write_vod_root(tmp_path / "vod", frames=2) / LIDAR_FOLDER / "training" / LABEL
    plain, bom = tmp_path / "plain.json", tmp_path / "bom.json"
    write_json(plain, score_directories(folder, folder).result)
    bom.write_bytes(UTF8_BOM + plain.read_bytes())
    a, b = load_row(f"x={plain}"), _quiet(load_row, f"x={bom}")
    assert b.report.areas == a.report.areas and a.report.num_frames == b.report.num_frames


def test_evaluation_figures_are_the_same_for_a_root_saved_with_boms(tmp_path, write_vod_root):
    plain = write_vod_root(tmp_path / "vod", frames=3)
    bom = _twin(tmp_path, plain)
    labels = sorted((bom / LIDAR_FOLDER / "training" / LABEL).glob("*.txt"))
    for path in labels:
        _add_bom(path)
    folder = plain / LIDAR_FOLDER / "training" / LABEL
    preds = tmp_path / "preds"  # the labels as predictions (score 1), one object left out
    preds.mkdir()
    for path in sorted(folder.glob("*.txt")):
        lines = path.read_text().splitlines(keepends=True)
        (preds / path.name).write_text("".join(lines[1:]))
    a = score_directories(folder, preds).result.to_dict()
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        gt = load_label_dir(labels[0].parent)
        b = score_directories(labels[0].parent, preds).result.to_dict()
    assert gt == load_label_dir(folder)
    assert b == a
    boms = [w for w in said if "byte-order mark" in str(w.message)]
    assert len(boms) == 1 and str(bom) in str(boms[0].message)  # once per root, not per file


def test_the_bom_is_said_once_per_root(tmp_path, write_tiny_root) -> None:
    roots = [write_tiny_root(tmp_path / name, frames=2) for name in ("one", "two")]
    for root in roots:
        for sid in ("00000", "00001"):
            _add_bom(sample_file(root / LIDAR_FOLDER, LABEL, sid))
            _add_bom(sample_file(root / LIDAR_FOLDER, PROMPT, sid))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for root in roots:
            for _ in range(2):
                reader = Talk2RadarRoot(root)
                for sid in reader.ids("test"):
                    reader.load(sid)
    messages = [str(w.message) for w in said if "byte-order mark" in str(w.message)]
    assert len(messages) == 2
    assert messages[0].startswith(f"{roots[0]}:") and messages[1].startswith(f"{roots[1]}:")
    assert root_of(sample_file(roots[0] / LIDAR_FOLDER, LABEL, "00000")) == roots[0]
    assert root_of(roots[0] / "meta" / "00000.json") == roots[0]
    assert root_of(roots[0] / "annotations" / "pending" / "x.json") == roots[0]


def test_crlf_line_ends_read_as_lf(tiny) -> None:
    plain, bom = tiny
    for folder in (LABEL, CALIB, PROMPT):
        path = sample_file(bom / LIDAR_FOLDER, folder, "00000")
        path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    ids = split_file(bom / LIDAR_FOLDER, "test")
    ids.write_bytes(ids.read_bytes().replace(b"\n", b"\r\n"))
    a, b = Talk2RadarRoot(plain).load(0), Talk2RadarRoot(bom).load(0)
    assert b.labels == a.labels and b.prompt == a.prompt
    np.testing.assert_array_equal(b.calib.P2, a.calib.P2)
    assert Talk2RadarRoot(bom).ids("test") == Talk2RadarRoot(plain).ids("test")


@pytest.mark.parametrize(
    ("inject", "named"),
    [
        (b"\r", "U+000D (CR)"),
        (b"\x0b", "U+000B (VT)"),
        ("\u2028".encode(), "U+2028 (LINE SEPARATOR)"),
        ("\u200b".encode(), "U+200B (ZERO WIDTH SPACE)"),
        ("\u202e".encode(), "U+202E (RIGHT-TO-LEFT OVERRIDE)"),
        ("\x85".encode(), "U+0085 (NEL)"),
        (UTF8_BOM, "U+FEFF"),  # a byte-order mark anywhere but at the start
    ],
)
def test_other_odd_characters_are_refused_naming_file_line_and_character(
    tiny, inject: bytes, named: str
) -> None:
    _, root = tiny
    path = sample_file(root / LIDAR_FOLDER, LABEL, "00000")
    line = path.read_bytes().rstrip(b"\n")
    path.write_bytes(line + b"\n" + line.replace(b"Car", b"Car" + inject, 1) + b"\n")
    with pytest.raises(LabelError) as err:
        read_label_file(path)
    message = str(err.value)
    assert message.startswith(f"{path}:2: the label file holds ") and named in message
    assert "\n" not in message


def test_undecodable_and_nul_bytes_name_the_line(tmp_path) -> None:
    path = tmp_path / "calib.txt"
    path.write_bytes(b"P0: 1\nP2: 1 \xff\n")
    with pytest.raises(CalibrationError, match=r"calib\.txt: the calib file is not UTF-8 text "):
        read_calib(path)
    with pytest.raises(CalibrationError, match=r"line 2: byte 0xff"):
        read_calib(path)
    path.write_bytes(b"P0: 1\n\nP2\x00 1\n")
    with pytest.raises(CalibrationError, match=r"binary, not text \(a NUL byte on line 3\)"):
        read_calib(path)


def test_a_prompt_file_follows_the_prompt_rule(tiny) -> None:
    _, root = tiny
    path = sample_file(root / LIDAR_FOLDER, PROMPT, "00000")
    path.write_text("the  car\t\uff11\uff15 m ahead\n")  # spaces collapsed, NFKC: "15"
    assert Talk2RadarRoot(root).load_prompt(0) == "the car 15 m ahead"
    path.write_text("the car\nthe truck\n")
    with pytest.raises(RootError, match=r"00000\.txt: the prompt contains a character not allowed"):
        Talk2RadarRoot(root).load_prompt(0)
    path.write_text("the car\u200b ahead")  # the app refuses it: so does training
    with pytest.raises(RootError, match=r"U\+200B"):
        Talk2RadarRoot(root).load(0)


def test_a_json_file_that_does_not_parse_names_the_line(tmp_path) -> None:
    path = tmp_path / "suite.json"
    path.write_bytes(UTF8_BOM + b'{\n "sentences": [,]\n}')
    with pytest.raises(SuiteError, match=r"suite\.json:2: the language suite is not valid JSON"):
        _quiet(load_suite, path)


def test_read_text_file_is_the_policy(tmp_path) -> None:
    path = tmp_path / "x.txt"
    path.write_bytes(UTF8_BOM + b"a\r\nb\tc\r\n")
    assert _quiet(read_text_file, path, "file", ValueError) == "a\nb\tc\n"
