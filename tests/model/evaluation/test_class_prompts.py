"""Class prompts on a fully labelled root (model.evaluation.class_prompts): exact counting with a fake model
on a hand-written VoD-layout frame (written by scenes.talk2radar.vod_writer), the command line's errors, and
one smoke run of the bundled checkpoint on synthetic frames exported in the View-of-Delft layout
(``real_format_roots``: python -m scenes.export_real)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import model.checkpoint
from model.checkpoint_meta import CheckpointMeta
from model.evaluation.class_prompt_counts import (
    CLASS_PROMPTS,
    ClassSummary,
    assign_matches,
    count_prompt,
)
from model.evaluation.class_prompts import ScoringConfig, main, score_root
from scenes.frame.kitti import boxes_to_labels
from scenes.geometry.calib import vod_lidar_calibration, vod_radar_calibration
from scenes.geometry.projection import in_camera_view
from scenes.talk2radar.layout import CALIB, LABEL, LIDAR_FOLDER, PROMPT, sample_dir, sample_file
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.talk2radar.vod_writer import VodWriter

RADAR = "radar"


def box(x: float, y: float, cls: str) -> list[float]:
    """A LiDAR-frame box of a typical size for ``cls`` standing on the ground (z = -1.7)."""
    l, w, h = {
        "Cyclist": (1.8, 0.6, 1.7),
        "Pedestrian": (0.6, 0.6, 1.7),
        "Car": (4.2, 1.8, 1.6),
    }.get(cls, (1.8, 0.6, 1.1))
    return [x, y, -1.7 + h / 2, l, w, h, 0.0]


# The frame's objects: name -> (class, box).
OBJECTS = {
    "c1": ("Cyclist", box(10, 0, "Cyclist")),
    "c2": ("Cyclist", box(20, 2, "Cyclist")),
    "c_far": ("Cyclist", box(40, 0, "Cyclist")),  # beyond 30 m
    "c_side": ("Cyclist", box(5, 10, "Cyclist")),  # in range, outside the camera's view
    "p1": ("Pedestrian", box(8, -1, "Pedestrian")),
    "car1": ("Car", box(15, 3, "Car")),
    "bike": ("bicycle", box(12, -3, "bicycle")),  # a parked bicycle: never a target
}


def shifted(name: str, dy: float) -> list[float]:
    b = list(OBJECTS[name][1])
    b[1] += dy
    return b


# Answers of the fake model: prompt -> [(class, box, score)].
ANSWERS = {
    "the cyclists": [
        ("Cyclist", OBJECTS["c1"][1], 0.9),  # found
        ("Cyclist", OBJECTS["c1"][1], 0.85),  # duplicate: false
        ("Cyclist", OBJECTS["bike"][1], 0.8),  # on the parked bicycle: false, on other
        ("Cyclist", shifted("c2", 0.8), 0.7),  # 0.8 m off: 3D IoU 0 (false), centre rule found
        ("Cyclist", OBJECTS["c2"][1], 0.2),  # exact but below the threshold 0.5
        ("Cyclist", OBJECTS["c_far"][1], 0.95),  # beyond 30 m: ignored
        ("Pedestrian", OBJECTS["p1"][1], 0.6),  # wrong class: false
    ],
    "the pedestrians": [],
    "the cars": [
        ("Car", OBJECTS["car1"][1], 0.9),  # found
        ("Car", box(5, -10, "Car"), 0.9),  # outside the camera's view: ignored there
    ],
}


class FakeModel:
    """``encode_scene`` / ``ground`` returning :data:`ANSWERS`; records its calls."""

    def __init__(self, threshold: float = 0.5) -> None:
        self.checkpoint_metadata = CheckpointMeta(operating_threshold=threshold, step=7, epoch=1)
        self.encoded = 0
        self.grounded: list[tuple[str, float | None]] = []

    def encode_scene(self, lidar: np.ndarray, radar: np.ndarray) -> tuple[str, int]:
        self.encoded += 1
        return ("scene", len(lidar))

    def ground(self, features: object, prompt: str, score_threshold: float | None = None):
        assert features[0] == "scene"
        self.grounded.append((prompt, score_threshold))
        rows = ANSWERS[prompt]
        return SimpleNamespace(
            boxes=np.array([r[1] for r in rows], dtype=np.float64).reshape(-1, 7),
            scores=np.array([r[2] for r in rows], dtype=np.float64),
            classes=tuple(r[0] for r in rows),
        )


@pytest.fixture(scope="module")
def vod_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two identical hand-written frames in the VoD layout (no prompt folder)."""
    out = tmp_path_factory.mktemp("vod")
    rng = np.random.default_rng(0)
    lidar = rng.uniform([0, -10, -2, 0], [40, 10, 1, 255], size=(500, 4)).astype(np.float32)
    radar = rng.uniform(-1, 1, size=(40, 7)).astype(np.float32) + np.array([20, 0, 0, 0, 0, 0, 0])
    names = list(OBJECTS)
    writer = VodWriter(out, (RADAR,))
    calib = vod_lidar_calibration()
    for sid in ("00003", "00010"):
        writer.write_sensors(sid, lidar, {RADAR: radar}, calib, vod_radar_calibration())
        boxes = np.array([OBJECTS[n][1] for n in names])
        writer.write_labels(sid, boxes_to_labels(boxes, [OBJECTS[n][0] for n in names], calib))
    writer.write_image_sets({"val": ["00003", "00010"], "test": []})
    return out


def score(root: Path, **config: object) -> tuple:
    fake = FakeModel()
    cfg = ScoringConfig(**{"threshold": 0.5, **config})
    rt = Talk2RadarRoot(root)
    report = score_root(fake, rt, rt.ids("val"), cfg)
    return report, fake


def test_counts_found_missed_false_and_range_cut(vod_root: Path) -> None:
    report, fake = score(vod_root)
    cyc, ped, car = (report.per_class[c] for c in ("Cyclist", "Pedestrian", "Car"))
    # Per frame: cyclists c1 and c2 are targets (c_far beyond 30 m, c_side outside the view).
    assert (cyc.prompts, cyc.targets, cyc.found, cyc.false_boxes) == (2, 4, 2, 8)
    assert (cyc.false_wrong_class, cyc.false_on_other) == (2, 2)
    assert (cyc.found_centre, cyc.false_centre, cyc.answered) == (4, 6, 10)
    assert cyc.recall == pytest.approx(50.0) and cyc.recall_centre == pytest.approx(100.0)
    assert cyc.false_per_prompt == pytest.approx(4.0)
    assert (ped.targets, ped.found, ped.false_boxes) == (2, 0, 0)
    assert (car.targets, car.found, car.false_boxes) == (2, 2, 0)
    o = report.overall
    assert (o.prompts, o.targets, o.found, o.false_boxes) == (6, 8, 4, 8)
    assert o.recall == pytest.approx(50.0) and o.false_per_prompt == pytest.approx(8 / 6)
    assert not o.meets_targets()
    assert report.other_labels == {"bicycle": 2}
    # One encoding per frame, three prompts on it, asked at the operating threshold.
    assert fake.encoded == 2
    assert fake.grounded == [(p, 0.5) for p in CLASS_PROMPTS.values()] * 2


def test_range_fov_and_threshold_change_the_counts(vod_root: Path) -> None:
    far, _ = score(vod_root, max_range=50.0)
    assert (far.per_class["Cyclist"].targets, far.per_class["Cyclist"].found) == (6, 4)
    everywhere, _ = score(vod_root, fov="all")
    cyc, car = everywhere.per_class["Cyclist"], everywhere.per_class["Car"]
    assert (cyc.targets, cyc.found) == (6, 2)  # c_side is a target now, and missed
    assert car.false_boxes == 2  # the car box outside the view counts now
    low, fake = score(vod_root, threshold=0.1)
    cyc = low.per_class["Cyclist"]
    # The exact 0.2 box finds c2 by IoU; by centre the 0.7 box took c2 first, so it is false.
    assert (cyc.found, cyc.false_boxes, cyc.found_centre, cyc.false_centre) == (4, 8, 4, 8)
    assert fake.grounded[0] == ("the cyclists", 0.1)


def test_sweep_equals_separate_runs_and_asks_once(vod_root: Path) -> None:
    report, fake = score(vod_root, sweep=(0.1, 0.95))
    assert {p for p, _ in fake.grounded} == set(CLASS_PROMPTS.values())
    assert all(t == 0.1 for _, t in fake.grounded) and fake.encoded == 2
    low, _ = score(vod_root, threshold=0.1)
    t, per_class, overall = report.sweep[0]
    assert t == 0.1 and per_class == low.per_class and overall == low.overall
    assert report.sweep[1][2].answered == 0 and report.sweep[1][2].targets == 8
    assert report.per_class == score(vod_root)[0].per_class


def test_assign_matches_greedy_by_score_and_strict_overlap() -> None:
    ped = np.array([box(10, 0, "Pedestrian")])
    near = ped.copy()
    near[0, 0] += 0.35  # IoU 0.25 / 0.95 > 0.25: a match
    off = ped.copy()
    off[0, 0] += 0.37  # IoU just under 0.25: none
    both = np.concatenate([off, near, ped])
    got = assign_matches(both, np.array([0.9, 0.8, 0.7]), ped, "Pedestrian")
    assert got.tolist() == [-1, 0, -1]  # the higher-scored near box takes it first
    assert assign_matches(both, np.array([0.1, 0.2, 0.7]), ped, "Pedestrian").tolist() == [
        -1,
        -1,
        0,
    ]
    centre = assign_matches(both, np.array([0.9, 0.8, 0.7]), ped, "Pedestrian", rule="centre")
    assert centre.tolist() == [0, -1, -1]
    two = np.array([box(10.8, 0, "Pedestrian"), box(10, 0, "Pedestrian")])
    between = np.array([box(10.3, 0, "Pedestrian")])
    for rule in ("iou", "centre"):  # the best (largest IoU, nearest) free one
        assert assign_matches(between, np.ones(1), two, "Pedestrian", rule).tolist() == [1]
    assert assign_matches(np.zeros((0, 7)), np.zeros(0), ped, "Car").tolist() == []
    with pytest.raises(ValueError, match="rule"):
        assign_matches(ped, np.ones(1), ped, "Pedestrian", rule="bev")


def test_count_prompt_without_ground_truth_or_answer() -> None:
    empty = np.zeros((0, 7))
    pred = np.array([box(10, 0, "Car")])
    c = count_prompt(
        "Car", pred, np.ones(1), ["Car"], empty, [], np.ones(1, bool), np.zeros(0, bool)
    )
    assert (c.targets, c.found, c.false_boxes, c.answered) == (0, 0, 1, 1)
    c = count_prompt(
        "Car", empty, np.zeros(0), [], pred, ["Car"], np.zeros(0, bool), np.ones(1, bool)
    )
    assert (c.targets, c.found, c.false_boxes) == (1, 0, 0)
    assert ClassSummary.of([]).recall == 0.0


def test_camera_view() -> None:
    calib = vod_lidar_calibration()
    boxes = np.array(
        [box(10, 0, "Car"), box(5, 10, "Car"), box(-10, 0, "Car"), box(30, -15, "Car")]
    )
    assert in_camera_view(boxes, calib).tolist() == [True, False, False, True]


def fake_loader(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(model.checkpoint, "load_checkpoint", lambda *a, **k: FakeModel())


def test_cli_table_and_json(
    vod_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    fake_loader(monkeypatch)
    out = tmp_path / "cp.json"
    ckpt = tmp_path / "fake.pt"
    ckpt.write_bytes(b"not read: the loader is faked")
    argv = ["--data", str(vod_root), "--checkpoint", str(ckpt), "--json", str(out), "--quiet"]
    assert main([*argv, "--sweep", "0.1"]) == 0
    text = capsys.readouterr().out
    assert "the cyclists" in text and "50.0%" in text and "not met" in text
    data = json.loads(out.read_text())
    assert data["frames"] == 2 and data["root_kind"] == "full labels"
    assert data["per_class"]["Cyclist"]["found"] == 2 and data["config"]["threshold"] == 0.5
    assert data["checkpoint_step"] == 7 and data["threshold_source"] == "checkpoint"
    assert data["sweep"][0]["threshold"] == 0.1 and len(data["per_frame"]) == 2
    assert data["command"].startswith("python -m model.class_prompts --data")
    assert main([*argv, "--split", "val", "--limit", "1", "--threshold", "0.1"]) == 0
    assert json.loads(out.read_text())["frames"] == 1
    assert main([*argv, "--split", "test"]) == 2
    assert "no frames" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("damage", "expect"),
    [
        ("no_lidar", "lidar: missing"),
        ("bad_label", "label_2/00003.txt:1"),
        ("no_labels", "label_2: no label files"),
        ("odd_name", "7.txt: not named by a 5-digit frame id"),
        ("no_calib", "calib/00010.txt"),
    ],
)
def test_cli_bad_roots_fail_in_one_line(
    vod_root: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys,
    damage: str,
    expect: str,
) -> None:
    import shutil

    fake_loader(monkeypatch)
    root = tmp_path / "root"
    shutil.copytree(vod_root, root)
    labels = sample_dir(root / LIDAR_FOLDER, LABEL)
    if damage == "no_lidar":
        shutil.rmtree(root / LIDAR_FOLDER)
    elif damage == "bad_label":
        (labels / "00003.txt").write_text("Cyclist 0 0 1 2 3\n")
    elif damage == "no_labels":
        for f in labels.iterdir():
            f.unlink()
    elif damage == "odd_name":
        (labels / "7.txt").write_text("")
    else:
        sample_file(root / LIDAR_FOLDER, CALIB, "00010").unlink()
    assert main(["--data", str(root), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and expect in err


def test_cli_says_a_talk2radar_root_has_referent_labels_only(
    vod_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    import shutil

    fake_loader(monkeypatch)
    root = tmp_path / "t2r"
    shutil.copytree(vod_root, root)
    prompts = sample_dir(root / LIDAR_FOLDER, PROMPT)
    prompts.mkdir()
    for sid in ("00003", "00010"):
        (prompts / f"{sid}.txt").write_text("the cyclist on the left\n")
    assert main(["--data", str(root), "--quiet"]) == 0
    assert "Talk2Radar root" in capsys.readouterr().err


def test_bundled_checkpoint_smoke_on_exported_frames(
    real_format_roots: tuple[Path, Path], tmp_path: Path, capsys
) -> None:
    _, root = real_format_roots
    out = tmp_path / "smoke.json"
    assert main(["--data", str(root), "--limit", "2", "--json", str(out), "--quiet"]) == 0
    data = json.loads(out.read_text())
    assert data["frames"] == 2 and data["checkpoint"].endswith("tpcnet-small.pt")
    for s in [*data["per_class"].values(), data["overall"]]:
        assert 0 <= s["found"] <= s["targets"] and 0 <= s["found_centre"] <= s["targets"]
        assert s["false_boxes"] <= s["answered"]
    assert data["overall"]["targets"] > 0
    assert "issue-14 targets" in capsys.readouterr().out
