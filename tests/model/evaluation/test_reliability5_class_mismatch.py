"""Issue 50 item 4: a class-set mismatch is said, once, with counts.

The three-class checkpoint on a root whose referents include classes outside its set: a prompt
about three bicycles (all its referents outside) is reported apart, never scored as an
empty-answer prompt; a Truck beside a Car stays a referent the model cannot answer (recall
drops); one line per run names them with counts per class, and the JSON says the same. The
app's frame summary and training's set-up say the same count.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from model.evaluate import main as evaluate_main
from scenes.frame.kitti import outside_class_phrase
from scenes.talk2radar.layout import LABEL, LIDAR_FOLDER, sample_file
from tests.paths import REPO

CHECKPOINT = REPO / "checkpoints" / "tpcnet-small.pt"


def _relabel(root: Path, sid: str, lines: list[str]) -> None:
    """Replace sample ``sid``'s label_2 in both trees with ``lines``."""
    for tree in (root / LIDAR_FOLDER, *(p for p in root.glob("radar*") if p.is_dir())):
        path = sample_file(tree, LABEL, sid)
        if path.exists():
            path.write_text("".join(line + "\n" for line in lines))


def _mismatched_root(write_tiny_root, path: Path) -> Path:
    """Three test samples of one car each: 00000 relabelled as three bicycles, 00001 given a
    truck beside its car, 00002 as it was."""
    root = write_tiny_root(path, frames=3)
    car = sample_file(root / LIDAR_FOLDER, LABEL, "00000").read_text().split("\n")[0]
    bikes = [car.replace("Car", "Bicycle", 1) for _ in range(3)]
    _relabel(root, "00000", bikes)
    car1 = sample_file(root / LIDAR_FOLDER, LABEL, "00001").read_text().split("\n")[0]
    _relabel(root, "00001", [car1, car1.replace("Car", "Truck", 1)])
    return root


def test_phrase_counts_and_names_the_classes() -> None:
    assert outside_class_phrase({}) == ""
    assert outside_class_phrase({"Truck": 3, "Bicycle": 9}) == (
        "12 referents of classes outside the model's set (Bicycle 9, Truck 3)"
    )
    assert outside_class_phrase({"Tram": 1}, "labels") == (
        "1 label of classes outside the model's set (Tram 1)"
    )


def test_evaluate_reports_outside_referents_apart_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture, write_tiny_root
) -> None:
    root = _mismatched_root(write_tiny_root, tmp_path / "root")
    out, js = tmp_path / "eval", tmp_path / "eval.json"
    args = ["--data", str(root), "--checkpoint", str(CHECKPOINT), "--out", str(out)]
    assert evaluate_main([*args, "--json", str(js), "--no-baselines", "--workers", "1"]) == 0
    captured = capsys.readouterr()
    text = captured.out + captured.err
    lines = [line for line in text.splitlines() if "outside the model's set" in line]
    assert len(lines) == 1, text[-3000:]  # said once
    line = lines[0]
    assert line.startswith("4 referents of classes outside the model's set (Bicycle 3, Truck 1)")
    assert "1 prompt whose referents all lie outside it reported apart" in line
    assert "00000" in line and "the other 1 stays" in line and "cannot answer" in line
    data = json.loads(js.read_text())
    outside = data["outside_class_set"]
    assert outside["class_set"] == "vod"
    assert outside["referents"] == {"Bicycle": 3, "Truck": 1}
    assert outside["prompts_apart"] == 1 and outside["prompt_ids_apart"] == ["00000"]
    assert outside["referents_in_scored_prompts"] == 1
    grounding = data["grounding"]
    # The bicycle prompt is in no grounding figure, and never an empty-answer prompt.
    assert grounding["overall"]["prompts"] == 2
    assert "empty" not in grounding["by_group"]
    # The truck stays a referent of its prompt (two referents: 1 car + 1 truck), never matched.
    assert grounding["overall"]["referents"] == 3
    assert grounding["by_group"]["multiple"]["prompts"] == 1
    assert grounding["overall"]["recall"] <= 100.0 * 2 / 3 + 1e-9


def test_grounding_outcome_keeps_outside_referents_as_missed() -> None:
    import numpy as np

    from model.evaluation.grounding import PromptBoxes, prompt_outcome

    box = np.array([[10.0, 0.0, -0.9, 4.2, 1.8, 1.5, 0.0]])
    car = PromptBoxes.make(box, ["Car"])
    answer = PromptBoxes.make(box, ["Car"], np.array([0.9]))
    full = prompt_outcome("1", (), answer, car, 0.5)
    with_truck = prompt_outcome("1", (), answer, car, 0.5, outside=1)
    assert full.exact and full.f1 == 1.0
    assert with_truck.num_referents == 2 and with_truck.outside_referents == 1
    assert not with_truck.exact and with_truck.recall == 0.5 and with_truck.hit_25 == 1.0
    none = PromptBoxes.make(np.zeros((0, 7)), [])
    only_outside = prompt_outcome("2", (), none, none, 0.5, outside=3)
    assert only_outside.hit_25 == 0.0 and only_outside.f1 == 0.0 and not only_outside.exact


def test_app_frame_summary_says_the_outside_referents(tmp_path: Path, write_tiny_root) -> None:
    """The served frame's summary (the app's status under the Scene controls) names the
    referents the served checkpoint's set leaves out; a frame without any says nothing."""
    from app.serving.navigation import FrameStore, frame_markdown
    from app.serving.served import serve_root
    from scenes.geometry.classes import VOD

    root = _mismatched_root(write_tiny_root, tmp_path / "root")
    served = serve_root(root, classes=VOD)
    frames = FrameStore(served.root, "test", notes=served.frame_notes)
    shown = [frame_markdown(frames.load(i), len(frames)).replace("\\", "") for i in range(3)]
    bikes, truck, plain = shown  # markdown escapes taken off
    assert "3 referents of classes outside the model's set (Bicycle 3)" in bikes
    assert "GT: none" in bikes and "cannot answer" in bikes
    assert "1 referent of classes outside the model's set (Truck 1)" in truck
    assert "outside the model" not in plain


def test_training_counts_the_labels_it_leaves_out_and_says_so_once(
    tmp_path: Path, capsys: pytest.CaptureFixture, write_tiny_root
) -> None:
    """model.train on a three-class model: the Bicycle and Truck labels of the training split
    are counted and named in one line at set-up (before, they were dropped without a word)."""
    from model.training.data import RootSpec
    from model.training.label_check import check_labels
    from model.training.loop import main as train_main
    from scenes.talk2radar.layout import split_file

    root = _mismatched_root(write_tiny_root, tmp_path / "root")
    ids = ["00000", "00001", "00002"]
    for tree in (root / LIDAR_FOLDER, *(p for p in root.glob("radar*") if p.is_dir())):
        split_file(tree, "train").write_text("".join(i + "\n" for i in ids))
    assert check_labels(RootSpec(str(root)), "train") == {"Bicycle": 3, "Truck": 1}
    args = ["--data", str(root), "--out", str(tmp_path / "run"), "--grounding", "tpcnet"]
    args += ["--max-steps", "1", "--batch-size", "1", "--val-every", "0", "--threads", "1"]
    assert train_main(args) == 0
    captured = capsys.readouterr()
    text = captured.out + captured.err
    lines = [line for line in text.splitlines() if "outside the model's set" in line]
    assert len(lines) == 1, text[-3000:]
    assert "4 labels of classes outside the model's set (Bicycle 3, Truck 1)" in lines[0]
    assert str(root) in lines[0] and "left out of training" in lines[0]
