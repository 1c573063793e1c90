"""``python -m model.evaluate --labels DIR --preds DIR [--json OUT]`` (model/evaluate.py)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from model.evaluate import main
from model.evaluation.files import score_directories
from scenes.frame.kitti import ObjectLabel, format_label_line, read_label_file
from scenes.talk2radar.layout import LIDAR_FOLDER, PROMPT, sample_file
from tests.paths import REPO


def car(z: float) -> ObjectLabel:
    return ObjectLabel(
        name="Car",
        truncated=0.0,
        occluded=0,
        alpha=0.2,
        bbox=(500.0, 400.0, 580.0, 500.0),
        dimensions_hwl=(1.5, 1.8, 4.0),
        location=(0.0, 1.5, z),
        rotation_y=0.2,
        score=1.0,
    )


def detection(gt: ObjectLabel, score: float) -> ObjectLabel:
    return replace(gt, truncated=-1.0, occluded=-1, rotation_y=gt.rotation_y + 0.01, score=score)


def write(folder: Path, frame: str, labels: list[ObjectLabel]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{frame}.txt"
    path.write_text("".join(format_label_line(lab) + "\n" for lab in labels))
    return path


def make_root(tmp_path: Path, frames: int, predicted: int) -> tuple[Path, Path]:
    """``frames`` frames with one car each; prediction files for the first ``predicted``."""
    labels, preds = tmp_path / "labels", tmp_path / "preds"
    for i in range(frames):
        gt = car(6.0 + i % 10)
        write(labels, f"{i:05d}", [gt])
        if i < predicted:
            write(preds, f"{i:05d}", [detection(gt, 1.0 - i / 100)])
    preds.mkdir(parents=True, exist_ok=True)
    return labels, preds


def test_help_runs():
    proc = subprocess.run(
        [sys.executable, "-m", "model.evaluate", "--help"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "--labels" in proc.stdout and "--preds" in proc.stdout and "--json" in proc.stdout


def test_table_and_json(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=6, predicted=6)
    out = tmp_path / "out" / "metrics.json"
    assert main(["--labels", str(labels), "--preds", str(preds), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Entire annotated area" in printed and "Driving corridor" in printed
    assert "Car" in printed and "Pedestrian" in printed and "Cyclist" in printed
    data = json.loads(out.read_text())
    expected_r11 = math.ceil(6 / 4) / 11 * 100  # perfect detector, 6 objects
    for area in ("entire_area", "roi"):
        block = data[area]
        assert block["Car_3d_all"] == pytest.approx(expected_r11)
        assert block["Car_bev_all"] == pytest.approx(expected_r11)
        assert block["Car_aos_all"] == pytest.approx(expected_r11)
        assert block["Car_3d_all_R40"] == pytest.approx(5 / 40 * 100)
        assert block["Pedestrian_3d_all"] == 0.0
        assert block["mAP_3d"] == pytest.approx(expected_r11 / 3)
        assert block["mAP_bev"] == pytest.approx(expected_r11 / 3)
        assert block["mAOS"] == pytest.approx(expected_r11 / 3)


def test_missing_prediction_files_count_as_misses(tmp_path, capsys):
    # 80 cars, predictions (perfect) for 40 frames only. Counted as misses: 40 of 80 found, the
    # thresholds sit at TP indices 0, 1, 3, ..., 39 (21 of them): R11 = 6/11, R40 = 20/40. Had the
    # 40 frames been dropped (the devkit's behaviour), R11 would be 10/11.
    labels, preds = make_root(tmp_path, frames=80, predicted=40)
    scored = score_directories(labels, preds)
    assert len(scored.frame_ids) == 80
    assert len(scored.missing_predictions) == 40
    car_result = scored.result.entire_area["Car"]
    assert car_result.num_gt == 80
    assert car_result.ap_3d.r11 == pytest.approx(6 / 11 * 100)
    assert car_result.ap_3d.r40 == pytest.approx(20 / 40 * 100)
    assert main(["--labels", str(labels), "--preds", str(preds)]) == 0
    assert "40 files missing" in capsys.readouterr().out


def test_prediction_without_label_is_an_error(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=3, predicted=3)
    stray = write(preds, "00042", [detection(car(10.0), 0.5)])
    assert main(["--labels", str(labels), "--preds", str(preds)]) == 2
    err = capsys.readouterr().err
    assert str(stray) in err and "no label file" in err


def test_malformed_prediction_line_names_file_and_line(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=2, predicted=2)
    path = preds / "00001.txt"
    path.write_text(path.read_text() + "Car -1 -1 0.1 1 2 3\n")
    assert main(["--labels", str(labels), "--preds", str(preds)]) == 2
    assert f"{path}:2" in capsys.readouterr().err


def test_prediction_lines_mixing_scores_are_an_error(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=1, predicted=1)
    path = preds / "00000.txt"
    no_score = replace(detection(car(20.0), 0.5), score=None)
    path.write_text(path.read_text() + "\n" + format_label_line(no_score) + "\n")
    assert main(["--labels", str(labels), "--preds", str(preds)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:3" in err and "score" in err


def test_empty_or_missing_label_folder_is_an_error(tmp_path, capsys):
    (tmp_path / "labels").mkdir()
    (tmp_path / "preds").mkdir()
    assert main(["--labels", str(tmp_path / "labels"), "--preds", str(tmp_path / "preds")]) == 2
    assert "no .txt label files" in capsys.readouterr().err
    assert main(["--labels", str(tmp_path / "nope"), "--preds", str(tmp_path / "preds")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_empty_prediction_files_and_exact_overlaps(tmp_path):
    labels, preds = make_root(tmp_path, frames=4, predicted=4)
    (preds / "00003.txt").write_text("")
    scored = score_directories(labels, preds, devkit_offsets=False)
    assert scored.missing_predictions == ()
    assert scored.result.entire_area["Car"].ap_3d.r40 == pytest.approx(2 / 40 * 100)  # 3 found
    assert main(["--labels", str(labels), "--preds", str(preds), "--exact-overlaps"]) == 0


def test_labels_and_preds_are_required_together(tmp_path):
    with pytest.raises(SystemExit):
        main(["--labels", str(tmp_path)])
    with pytest.raises(SystemExit):
        main([])


# ------------------------------------------------------------------------------------------ reliability
# (issue 11: no file can silently change a score; every error is one line and exit code 2)


def _error_line(capsys, progress: bool = False) -> str:
    """The one error line on stderr (after the progress bar's lines when ``progress``)."""
    err = capsys.readouterr().err.strip().splitlines()
    if progress:
        assert all(line.startswith("predict:") for line in err[:-1]), err
        err = err[-1:]
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_unknown_class_names_are_counted_and_reported(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=4, predicted=4)
    typo = replace(car(30.0), name="Cyclst")
    write(labels, "00001", [*read_label_file(labels / "00001.txt"), typo, typo])
    write(labels, "00002", [*read_label_file(labels / "00002.txt"), replace(typo, name="bicycle")])
    scored = score_directories(labels, preds)
    assert scored.result.unknown_gt_classes == {"Cyclst": 2}  # bicycle is a known VoD class
    assert scored.result.unknown_dt_classes == {}
    assert scored.result.entire_area["Cyclist"].num_gt == 0  # kept out, as the protocol says
    assert main(["--labels", str(labels), "--preds", str(preds)]) == 0
    out, err = capsys.readouterr()
    assert "Not scored, unknown class name: 2 ground-truth object(s) ('Cyclst' x2)" in out
    assert err.startswith("warning: ") and "'Cyclst' x2" in err


def test_prediction_line_without_score_is_an_error(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=2, predicted=2)
    path = preds / "00001.txt"
    path.write_text(format_label_line(replace(detection(car(7.0), 0.5), score=None)) + "\n")
    assert main(["--labels", str(labels), "--preds", str(preds)]) == 2
    line = _error_line(capsys)
    assert f"{path}:1: prediction line without a score" in line


def test_frame_files_that_could_change_a_score_are_errors(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=3, predicted=3)
    args = ["--labels", str(labels), "--preds", str(preds)]
    unpadded = write(labels, "2", [car(9.0)])  # beside 00002.txt: the same frame twice
    assert main(args) == 2
    assert f"{unpadded}: frame id '2' is not written as 5 digits" in _error_line(capsys)
    unpadded.unlink()
    loop = labels / "00007.txt"
    loop.symlink_to(loop)  # a symlink loop would drop the frame
    assert main(args) == 2
    assert f"{loop}: cannot read this label file" in _error_line(capsys)
    loop.unlink()
    (preds / "00001.txt").write_bytes(b"Car \xff\xfe 0 0")
    assert main(args) == 2
    assert f"{preds / '00001.txt'}: the prediction file is not UTF-8" in _error_line(capsys)
    (labels / "00000.txt").write_bytes(b"\x00\x01\x02")
    assert main(args) == 2
    assert f"{labels / '00000.txt'}: the label file is binary" in _error_line(capsys)


def test_unwritable_json_is_an_error(tmp_path, capsys):
    labels, preds = make_root(tmp_path, frames=2, predicted=2)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    out = blocker / "metrics.json"
    assert main(["--labels", str(labels), "--preds", str(preds), "--json", str(out)]) == 2
    assert str(blocker) in _error_line(capsys)


def test_data_mode_with_an_empty_prompt_names_the_sample(tmp_path, capsys, write_tiny_root):
    root = write_tiny_root(tmp_path / "root", frames=2)
    prompt = sample_file(root / LIDAR_FOLDER, PROMPT, "00001")
    prompt.write_text("  \n")
    checkpoint = REPO / "checkpoints" / "tpcnet-small.pt"
    args = ["--data", str(root), "--checkpoint", str(checkpoint), "--out", str(tmp_path / "o")]
    assert main(args) == 2
    line = _error_line(capsys, progress=True)
    assert f"{prompt}: the prompt file of sample 00001 is empty" in line


def test_data_mode_with_an_unwritable_out_is_an_error(tmp_path, capsys, write_tiny_root):
    root = write_tiny_root(tmp_path / "root", frames=1)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    checkpoint = REPO / "checkpoints" / "tpcnet-small.pt"
    args = ["--data", str(root), "--checkpoint", str(checkpoint), "--out", str(blocker / "o")]
    assert main(args) == 2
    assert str(blocker) in _error_line(capsys, progress=True)
