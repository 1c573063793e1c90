"""A nuScenes root with Talk2Car commands written by a converter that is not the project's
(tools/nuscenes_converter.py: the release's field names and frames, uuid tokens, shuffled
tables, the release's tilted LIDAR_TOP and CAM_FRONT poses, a random global pose per sample,
CAM_FRONT sample_data tokens, junk radar points, wrapped command wording) is read back exactly as
the synthetic source has it, and trains and evaluates through the command lines."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from scenes.nuscenes.root import NuScenesRoot
from scenes.nuscenes.talk2car import read_commands
from scenes.talk2radar.root import Talk2RadarRoot
from tools.nuscenes_converter import convert


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``(source, root)``: 4 synthetic worlds of 6 prompts (half train, half val, no camera),
    converted with wrapped commands."""
    from scenes.synth.generate import SynthSettings, generate_root

    base = tmp_path_factory.mktemp("converted")
    source = base / "synth"
    settings = SynthSettings(seed=11, prompts_per_world=6, camera=None)
    generate_root(source, 24, settings, split_fractions=(0.5, 0.5, 0.0))
    counts = convert(source, base / "NUSC", seed=5, wrap=True)
    assert counts["train"] and counts["val"]
    return source, base / "NUSC"


def test_the_reader_gives_back_the_source(converted: tuple[Path, Path]) -> None:
    source, path = converted
    src = Talk2RadarRoot(source)
    root = NuScenesRoot(path, radar_sweeps=5)
    by_world = {}
    for sid in src.ids("train") + src.ids("val"):
        by_world.setdefault(src.load_meta(sid).world_id, sid)
    assert len(root.samples) == len(by_world)
    for split in ("train", "val"):
        commands = read_commands(path / "commands", split, root)
        assert not commands.skipped and commands.commands
        for command in commands.commands:
            assert command.cam_token != command.sample_token  # a CAM_FRONT sample_data token
            frame = root.frame(command.sample_token)
            referent = commands.referent[command.command_token]
            # the source world whose actors are this frame's boxes (the tables are shuffled:
            # pair the annotations with the actors by centre)
            for sid in by_world.values():
                meta = src.load_meta(sid)
                boxes = np.array([a.box for a in meta.actors])
                gap, order = cKDTree(boxes[:, :3]).query(frame.boxes[:, :3])
                if len(boxes) == len(frame.boxes) and gap.max() < 1e-3:
                    break
            else:
                raise AssertionError(f"sample {command.sample_token}: no source world matches")
            assert sorted(order.tolist()) == list(range(len(boxes)))
            actors = [meta.actors[i] for i in order]
            np.testing.assert_allclose(frame.boxes[:, :6], boxes[order, :6], atol=1e-4)
            yaw_gap = np.angle(np.exp(1j * (frame.boxes[:, 6] - boxes[order, 6])))
            assert np.abs(yaw_gap).max() < 1e-5
            classes = {"vehicle.car": "Car", "vehicle.bicycle": "Cyclist"}
            assert [classes.get(c, "Pedestrian") for c in frame.categories] == [
                a.cls for a in actors
            ]
            assert referent.cls == actors[referent.index].cls
            np.testing.assert_allclose(referent.box, frame.boxes[referent.index])
            sample = src.load(sid)
            np.testing.assert_allclose(frame.lidar, sample.lidar, atol=2e-3)
            # radar: same points (the junk ones filtered), channels x y z rcs v_r v_r_comp time
            ours, theirs = frame.radar, np.asarray(sample.radar)
            assert len(ours) == len(theirs)
            _, index = cKDTree(np.c_[theirs[:, :3], 100 * theirs[:, 6]]).query(
                np.c_[ours[:, :3], 100 * ours[:, 6]]
            )
            assert len(set(index.tolist())) == len(index)
            np.testing.assert_allclose(ours, theirs[index], atol=2e-3)


def test_trains_and_evaluates_with_the_documented_commands(
    converted: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from model.evaluate import main as evaluate
    from model.training.loop import main as train

    _, path = converted
    run = tmp_path / "RUN"
    torch.manual_seed(0)
    args = ["--data", str(path), "--talk2car", str(path / "commands"), "--freeze-scene"]
    args += ["--init-detector", "checkpoints/tpcnet-small.pt", "--epochs", "1", "--val-every", "0"]
    assert train([*args, "--out", str(run), "--threads", "1"]) == 0
    capsys.readouterr()
    args = ["--data", str(path), "--talk2car", str(path / "commands"), "--split", "val"]
    assert evaluate([*args, "--checkpoint", str(run / "last.pt"), "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "BEV AP_A" in printed and "top-1" in printed
    written = json.loads((tmp_path / "val_predictions.json").read_text())
    val = json.loads((path / "commands" / "val_commands.json").read_text())["commands"]
    assert set(written) == {c["command_token"] for c in val}


def test_a_ten_class_source_converts_with_every_class(tmp_path: Path) -> None:
    """A ``--classes nuscenes`` source: every actor an annotation under one of the release's
    categories of its class, with the release's attribute (two-wheelers with or without a rider,
    cones and barriers none), and commands that read back into the nuScenes class set."""
    from collections import Counter

    from scenes.geometry.classes import NUSCENES
    from scenes.synth.generate import SynthSettings, generate_root
    from tools.nuscenes_converter import CLASS_CATEGORIES

    settings = SynthSettings(seed=2, classes="nuscenes", camera=None, prompts_per_world=8)
    generate_root(tmp_path / "synth", 24, settings, split_fractions=(0.5, 0.5, 0.0))
    convert(tmp_path / "synth", tmp_path / "NUSC", seed=3, wrap=True)
    root = NuScenesRoot(tmp_path / "NUSC")
    found: Counter[str] = Counter()
    for sample in root.samples:
        _, categories, attributes = root.annotation_boxes(sample)
        for category, attrs in zip(categories, attributes, strict=True):
            cls = NUSCENES.category_class(category, attrs)
            assert cls is not None and category in CLASS_CATEGORIES[cls]
            found[cls] += 1
            if cls in ("TrafficCone", "Barrier"):
                assert not attrs
            else:
                assert len(attrs) == 1 and attrs[0].split(".")[0] in (
                    "vehicle", "pedestrian", "cycle"
                )  # fmt: skip
    assert set(found) == set(NUSCENES.names)  # all ten written
    commands = read_commands(tmp_path / "NUSC" / "commands", "train", root, NUSCENES)
    assert commands.commands and not commands.skipped
    assert {commands.referent[c.command_token].cls for c in commands.commands} - {
        "Car", "Pedestrian", "Bicycle"
    }  # fmt: skip
