"""``python -m model.adapt``: self-training adaptation to unlabelled frames (issue 38, item 3).

Tiny roots (:func:`tests.conftest.write_tiny_root`, 3 frames) and an untrained referent model;
the run tests share one uninterrupted run (module fixture)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from model.adapt.__main__ import main
from model.adapt.augment import View
from model.adapt.config import DEFAULT_THRESHOLDS, AdaptConfig, AdaptError
from model.adapt.frames import UnlabelledFrames
from model.adapt.pseudo import FrameMemory, ensemble, partition, seat_on_ground, select
from model.adapt.run import step_indices
from model.checkpoint import load_checkpoint, save_checkpoint
from model.training.referent_step import in_bev_footprint
from scenes.geometry.classes import NUSCENES, VOD
from scenes.talk2radar.layout import LABEL, LIDAR_FOLDER, PROMPT, sample_dir
from tools.unlabelled_root import sensor_only_copy

LOW = ["--class-threshold", "Car=0.09", "--class-threshold", "Pedestrian=0.09"]
LOW += ["--class-threshold", "Cyclist=0.09"]
"""Thresholds an untrained head's scores (about sigmoid(-2.19) = 0.1) reach: pseudo-labels."""


def config(**changes: object) -> AdaptConfig:
    return AdaptConfig(data="d", init="i", out="o", **changes)


# ------------------------------------------------------------------ pseudo-labels


def test_pseudo_labels_are_selected_by_per_class_thresholds():
    # labels Car, Pedestrian, Cyclist, Car; scores straddling each class's own threshold
    labels = np.array([0, 1, 2, 0, 1])
    scores = np.array([0.45, 0.35, 0.39, 0.55, 0.25])
    three = ("Car", "Pedestrian", "Cyclist")
    picked = select(labels, scores, {"Car": 0.5, "Pedestrian": 0.3, "Cyclist": 0.4}, three)
    assert picked.tolist() == [False, True, False, True, False]
    # one threshold for all would pick otherwise: the thresholds are per class
    assert select(labels, scores, dict.fromkeys(three, 0.3), three).sum() == 4


def test_partition_keeps_confident_near_boxes_and_ignores_the_rest():
    cfg = config(rounds=3, class_threshold=("Car=0.6:0.3",), range_start=20.0, range_end=40.0)
    boxes = np.zeros((4, 7))
    boxes[:, 3:6] = (4.0, 1.8, 1.5)
    boxes[:, 0] = [10.0, 30.0, 10.0, 10.0]
    memory = FrameMemory(
        boxes, np.zeros(4, np.int64), np.array([0.5, 0.7, 0.7, 0.7]), np.array([0, 0, 0, 1])
    )
    classes = VOD.names
    first, last = cfg.round_plan(0, classes), cfg.round_plan(2, classes)
    assert first.positive["Car"] == pytest.approx(0.6) and last.positive["Car"] == pytest.approx(
        0.3
    )
    assert (first.max_range, last.max_range) == (20.0, 40.0)
    t = partition(memory, first)  # 0.5 < 0.6; 30 m beyond 20 m; missed this round
    assert t.boxes[:, 0].tolist() == [10.0] and len(t.ignore) == 3
    t = partition(memory, last)  # the curriculum admits the less certain and the farther box
    assert sorted(t.boxes[:, 0].tolist()) == [10.0, 10.0, 30.0] and len(t.ignore) == 1


def test_memory_keeps_the_surer_box_and_drops_one_missed_too_often():
    box = np.array([[10.0, 0.0, -1.0, 4.0, 1.8, 1.5, 0.0]])
    memory, stats = ensemble(FrameMemory.empty(), box, np.array([0]), np.array([0.6]), 0.1, 1)
    assert (stats.added, len(memory)) == (1, 1)
    moved = box + np.array([0.3, 0, 0, 0, 0, 0, 0])
    memory, stats = ensemble(memory, moved, np.array([0]), np.array([0.4]), 0.1, 1)
    assert stats.matched == 1 and memory.scores.tolist() == [0.6]
    assert memory.boxes[0, 0] == 10.0  # the surer, remembered box is kept
    memory, stats = ensemble(memory, np.zeros((0, 7)), np.zeros(0), np.zeros(0), 0.1, 1)
    assert stats.missed == 1 and memory.misses.tolist() == [1]
    memory, stats = ensemble(memory, np.zeros((0, 7)), np.zeros(0), np.zeros(0), 0.1, 1)
    assert stats.dropped == 1 and len(memory) == 0


def test_pseudo_labels_rest_on_the_ground_the_new_sensor_sees():
    rng = np.random.default_rng(1)
    ground = np.c_[rng.uniform([-20, -20], [20, 20], (20000, 2)), rng.normal(-1.84, 0.01, 20000)]
    lidar = np.c_[ground, np.zeros(len(ground))].astype(np.float32)
    h = 1.6
    boxes = np.array([[8.0, 2.0, -1.84 + h / 2 + dz, 4.0, 1.8, h, 0.3] for dz in (0.1, -0.12, 0.6)])
    seated = seat_on_ground(boxes, lidar)
    assert seated[:2, 2] == pytest.approx(-1.84 + h / 2, abs=0.02)  # a floating or sunk box
    assert seated[2, 2] == boxes[2, 2]  # a move past MAX_SEAT_SHIFT is not made
    assert np.array_equal(seated[:, [0, 1, 3, 4, 5, 6]], boxes[:, [0, 1, 3, 4, 5, 6]])
    far = boxes.copy()
    far[:, 0] = 60.0  # no points around: the box stays
    assert np.array_equal(seat_on_ground(far, lidar), far)


def test_bad_class_threshold_is_one_line():
    with pytest.raises(AdaptError, match=r"--class-threshold 'Tram=0\.5'"):
        config(class_threshold=("Tram=0.5",))
    # a class of another class set: refused against the checkpoint's classes
    with pytest.raises(AdaptError, match=r"Truck=\.\.\.: the checkpoint's classes are Car, Ped"):
        config(class_threshold=("Truck=0.5",)).thresholds(VOD.names)


def test_every_class_of_a_nuscenes_checkpoint_has_thresholds():
    cfg = config(class_threshold=("TrafficCone=0.6:0.45",), threshold_start=0.55)
    plan = cfg.round_plan(0, NUSCENES.names)
    assert plan.classes == NUSCENES.names and set(plan.positive) == set(NUSCENES.names)
    assert plan.positive["TrafficCone"] == 0.6 and plan.positive["Truck"] == 0.55
    assert plan.positive["Pedestrian"] == DEFAULT_THRESHOLDS["Pedestrian"][0]
    labels = np.array([NUSCENES.index("Truck"), NUSCENES.index("TrafficCone")])
    assert select(labels, np.array([0.56, 0.56]), plan.positive, plan.classes).tolist() == [
        True,
        False,
    ]


# ------------------------------------------------------------------ augmentation consistency


@pytest.mark.parametrize(
    "view",
    [View(True, 0.0, 1.0), View(False, 0.35, 1.0), View(True, -0.3, 1.05), View(False, 3.0, 0.95)],
)
def test_views_move_boxes_with_the_cloud(view: View):
    rng = np.random.default_rng(0)
    box = np.array([12.0, 4.0, -0.9, 4.2, 1.9, 1.6, 0.6])
    local = rng.uniform(-0.48, 0.48, (300, 3)) * box[3:6]
    c, s = np.cos(box[6]), np.sin(box[6])
    inside = np.c_[
        box[0] + c * local[:, 0] - s * local[:, 1],
        box[1] + s * local[:, 0] + c * local[:, 1],
        box[2] + local[:, 2],
        rng.uniform(0, 255, 300),
    ].astype(np.float32)
    moved_points, moved_box = view.points(inside), view.boxes(box[None])[0]
    assert in_bev_footprint(moved_points[:, :2], moved_box[None]).all()
    assert np.all(np.abs(moved_points[:, 2] - moved_box[2]) <= moved_box[5] / 2 + 1e-4)
    assert np.allclose(moved_points[:, 3], inside[:, 3])  # intensity untouched
    assert not np.allclose(moved_points[:, :2], inside[:, :2])  # the view did move the scene


def test_step_batches_cycle_every_frame():
    seen = [i for s in range(5) for i in step_indices(5, 2, 0, 0, s)]
    assert sorted(seen) == sorted(list(range(5)) * 2)
    assert step_indices(5, 2, 0, 1, 0) == step_indices(5, 2, 0, 1, 0)


# ------------------------------------------------------------------ roots


@pytest.fixture(scope="module")
def labelled_root(tmp_path_factory, write_tiny_root) -> Path:
    return write_tiny_root(tmp_path_factory.mktemp("adapt") / "t2r", frames=3)


@pytest.fixture(scope="module")
def sensor_root(labelled_root: Path) -> Path:
    out = labelled_root.parent / "sensors"
    sensor_only_copy(labelled_root, out)
    return out


def test_an_unlabelled_root_is_read_without_labels(sensor_root: Path, tmp_path: Path):
    tree = sensor_root / LIDAR_FOLDER
    assert not sample_dir(tree, LABEL).exists() and not sample_dir(tree, PROMPT).exists()
    frames = UnlabelledFrames(sensor_root)
    assert frames.ids == ["00000", "00001", "00002"]
    first = frames[0]
    assert first.lidar.shape[1] == 4 and len(first.lidar) > 4000 and first.radar.shape[1] == 7
    # labels, prompts and sidecars beside the sensors are never read: garbage in them is fine
    poisoned = tmp_path / "poisoned"
    sensor_only_copy(sensor_root, poisoned)
    for folder in (LABEL, PROMPT):
        sample_dir(poisoned / LIDAR_FOLDER, folder).mkdir(parents=True)
        for sid in frames.ids:
            (sample_dir(poisoned / LIDAR_FOLDER, folder) / f"{sid}.txt").write_bytes(b"\xff\x00")
    (poisoned / "meta").mkdir()
    for sid in frames.ids:
        (poisoned / "meta" / f"{sid}.json").write_text("{not json")
    again = UnlabelledFrames(poisoned)
    assert np.array_equal(again[0].lidar, first.lidar)


# ------------------------------------------------------------------ runs


@pytest.fixture(scope="module")
def init_checkpoint(labelled_root: Path, untrained_model) -> Path:
    path = labelled_root.parent / "init.pt"
    model = untrained_model("referent", seed=3)
    save_checkpoint(path, model, operating_threshold=0.3, training_stages="untrained (test)")
    return path


def run_args(sensor_root: Path, init: Path, out: Path, *more: str) -> list[str]:
    return [
        "--data",
        str(sensor_root),
        "--init",
        str(init),
        "--out",
        str(out),
        "--rounds",
        "2",
        "--steps-per-round",
        "2",
        "--quiet",
        *LOW,
        *more,
    ]


@pytest.fixture(scope="module")
def full_run(sensor_root: Path, init_checkpoint: Path, torch_threads) -> Path:
    out = sensor_root.parent / "run-full"
    with torch_threads(1):
        assert main(run_args(sensor_root, init_checkpoint, out)) == 0
    return out


def test_a_run_reports_pseudo_labels_per_class_and_round(full_run: Path, capsys):
    report = json.loads((full_run / "adapt_report.json").read_text())
    rounds = report["rounds"]
    assert [r["round"] for r in rounds] == [0, 1] and all(r["steps"] == 2 for r in rounds)
    assert set(rounds[0]["pseudo_labels"]) == {"Car", "Pedestrian", "Cyclist"}
    assert sum(rounds[0]["pseudo_labels"].values()) > 0  # the low thresholds admit boxes
    assert (full_run / "round1.pt").is_file() and (full_run / "round2.pt").is_file()


def test_only_the_detector_adapts(full_run: Path, init_checkpoint: Path):
    before, after = load_checkpoint(init_checkpoint), load_checkpoint(full_run / "last.pt")
    a, b = before.state_dict(), after.state_dict()
    changed = {k for k in a if not torch.equal(a[k], b[k])}
    assert changed and all(
        k.split(".")[0] in {"lidar", "radar", "fusion", "neck", "head"} for k in changed
    )
    # --norm-statistics keep (the default): the batch-norm layers learn their scale and shift,
    # their running statistics stay the initial checkpoint's
    assert any(k.endswith(".weight") and k[: -len("weight")] + "running_mean" in a for k in changed)
    assert not any("running_" in k for k in changed)
    meta = after.checkpoint_metadata
    assert meta.operating_threshold == 0.3
    assert meta.extra["adaptation"]["rounds_done"] == 2
    assert meta.extra["adaptation"]["init"] == str(init_checkpoint)
    assert "model.adapt" in meta.training_stages and "untrained (test)" in meta.training_stages


def test_statistics_follow_and_boxes_stay_when_asked(
    sensor_root: Path, init_checkpoint: Path, torch_threads
):
    """``--norm-statistics follow``: the running statistics follow the new frames;
    ``--regression-weight 0`` (no weight decay): the box-regression branch stays as it was."""
    out = sensor_root.parent / "run-follow"
    more = ["--rounds", "1", "--norm-statistics", "follow", "--regression-weight", "0"]
    with torch_threads(1):
        assert main(run_args(sensor_root, init_checkpoint, out, *more, "--weight-decay", "0")) == 0
    a = load_checkpoint(init_checkpoint).state_dict()
    b = load_checkpoint(out / "last.pt").state_dict()
    changed = {k for k in a if not torch.equal(a[k], b[k])}
    assert any("running_mean" in k for k in changed)
    learnt = {k for k in changed if "running_" not in k and "num_batches" not in k}
    assert any(k.startswith("head.heatmap.") for k in learnt)
    assert not any(k.startswith("head.regression.") for k in learnt)


def test_a_nuscenes_class_checkpoint_adapts_over_its_own_classes(
    sensor_root: Path, untrained_model, torch_threads, capsys
):
    init = sensor_root.parent / "init-nusc.pt"
    model = untrained_model("referent", seed=3, classes="nuscenes")
    save_checkpoint(init, model, operating_threshold=0.3)
    out = sensor_root.parent / "run-nusc"
    low = [f"--class-threshold={c}=0.09" for c in NUSCENES.names]
    args = run_args(sensor_root, init, out, "--rounds", "1", *low)
    with torch_threads(1):
        assert main([a for a in args if a not in LOW]) == 0
    report = json.loads((out / "adapt_report.json").read_text())["rounds"][0]
    assert list(report["pseudo_labels"]) == list(NUSCENES.names)
    assert sum(report["pseudo_labels"].values()) > 0
    printed = capsys.readouterr().out  # the table names them apart
    assert "pseudo Trai" in printed and "pseudo Traf" in printed
    assert load_checkpoint(out / "last.pt").cfg.class_set == NUSCENES


def test_resume_continues_where_it_stopped(
    full_run: Path, sensor_root: Path, init_checkpoint: Path, torch_threads
):
    out = sensor_root.parent / "run-resumed"
    with torch_threads(1):
        assert main(run_args(sensor_root, init_checkpoint, out, "--stop-after-round", "1")) == 0
        assert (out / "round1.pt").is_file() and not (out / "round2.pt").exists()
        assert main(run_args(sensor_root, init_checkpoint, out)) == 0
    full = torch.load(full_run / "last.pt", weights_only=True)["state_dict"]
    resumed = torch.load(out / "last.pt", weights_only=True)["state_dict"]
    assert all(torch.equal(full[k], resumed[k]) for k in full)
    report = json.loads((out / "adapt_report.json").read_text())["rounds"]
    assert report == json.loads((full_run / "adapt_report.json").read_text())["rounds"]


def test_a_changed_setting_is_refused_on_resume(
    full_run: Path, sensor_root: Path, init_checkpoint: Path, capsys
):
    assert main(run_args(sensor_root, init_checkpoint, full_run, "--lr", "0.1")) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--lr" in err and "adapt_state.pt" in err


def test_the_result_loads_in_model_evaluate(full_run: Path, labelled_root: Path, tmp_path: Path):
    from model.evaluate import main as evaluate

    out = tmp_path / "eval.json"
    argv = [
        "--data",
        str(labelled_root),
        "--split",
        "test",
        "--checkpoint",
        str(full_run / "last.pt"),
        "--json",
        str(out),
        "--workers",
        "1",
    ]
    assert evaluate(argv) == 0
    assert out.is_file()


# ------------------------------------------------------------------ errors


def test_bad_root_or_checkpoint_is_one_line(
    tmp_path: Path, sensor_root: Path, init_checkpoint: Path, untrained_model, capsys
):
    cases = []
    cases.append((["--data", str(tmp_path / "nowhere"), "--init", str(init_checkpoint)], "nowhere"))
    bad = tmp_path / "bad.pt"
    bad.write_text("not a checkpoint")
    cases.append((["--data", str(sensor_root), "--init", str(bad)], "bad.pt"))
    paper = tmp_path / "paper.pt"
    save_checkpoint(paper, untrained_model("tpcnet"))
    cases.append((["--data", str(sensor_root), "--init", str(paper)], "referent-path"))
    empty = tmp_path / "empty"
    (empty / LIDAR_FOLDER / "training" / "velodyne").mkdir(parents=True)
    cases.append((["--data", str(empty), "--init", str(init_checkpoint)], "no frame"))
    for argv, named in cases:
        assert main([*argv, "--out", str(tmp_path / "run"), "--quiet"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith("error:") and named in err, err
