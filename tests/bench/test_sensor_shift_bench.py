"""``python -m bench.sensor_shift`` (issue 38): its counting and a run end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.studies.sensor_shift import FrameCounts, main, prompt_f1, summarise
from model.checkpoint import save_checkpoint
from model.evaluation.class_prompt_counts import PromptCount


def count(cls: str, targets: int, found: int, false: int, answered: int) -> PromptCount:
    return PromptCount(cls, targets, found, false, 0, 0, found, false, answered)


def test_prompt_f1_and_the_pooled_figures():
    assert prompt_f1(count("Car", 0, 0, 0, 0)) == 1.0  # nothing asked for, nothing answered
    assert prompt_f1(count("Car", 2, 1, 1, 2)) == pytest.approx(0.5)
    assert prompt_f1(count("Car", 2, 0, 3, 3)) == 0.0
    frames = [
        FrameCounts(
            detection=(
                count("Cyclist", 2, 1, 1, 2),
                count("Pedestrian", 1, 1, 0, 1),
                count("Car", 0, 0, 2, 2),
            ),
            prompts=(
                count("Cyclist", 2, 2, 0, 2),
                count("Pedestrian", 1, 0, 1, 1),
                count("Car", 0, 0, 0, 0),
            ),
        ),
        FrameCounts(
            detection=(
                count("Cyclist", 1, 0, 0, 0),
                count("Pedestrian", 0, 0, 0, 0),
                count("Car", 1, 1, 0, 1),
            ),
            prompts=(
                count("Cyclist", 1, 0, 0, 0),
                count("Pedestrian", 0, 0, 0, 0),
                count("Car", 1, 1, 0, 1),
            ),
        ),
    ]
    f = summarise("x", "a rig", frames, 1.0)
    assert f.targets == {"Cyclist": 3, "Pedestrian": 1, "Car": 1, "all": 5}
    assert f.recall["Cyclist"] == pytest.approx(100 / 3) and f.recall["all"] == pytest.approx(60.0)
    assert f.false_per_frame == pytest.approx(1.5)
    assert f.prompt_f1 == pytest.approx(100 * (1 + 0 + 1 + 0 + 1 + 1) / 6)
    assert f.prompt_recall == pytest.approx(60.0)  # 3 of 5


def test_the_benchmark_runs_end_to_end_on_a_random_weights_model(tmp_path, untrained_model, capsys):
    model = untrained_model("referent", text_encoder="gru", operating_threshold=0.5)
    ckpt = save_checkpoint(tmp_path / "random.pt", model, step=1)
    argv = ["--checkpoint", str(ckpt), "--worlds", "1", "--setups", "radar-1scan", "intensity-x2"]
    assert main([*argv, "--out-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "| `vod`: in domain" in out and "| `radar-1scan`:" in out and "| `intensity-x2`:" in out
    data = json.loads((tmp_path / "sensor_shift.json").read_text())
    rows = data["data"]["setups"]
    assert [r["name"] for r in rows] == ["vod", "radar-1scan", "intensity-x2"]
    assert all(r["frames"] == 1 and r["targets"]["all"] > 0 for r in rows)
    # The same actors in every rig sensing them alike: the LiDAR-only change keeps the targets.
    assert rows[2]["targets"] == rows[0]["targets"]
    assert all(0.0 <= r["recall"]["all"] <= 100.0 or np.isnan(r["recall"]["all"]) for r in rows)
    assert data["data"]["targets"][0]["name"].startswith("held-out detection recall gap")


def test_a_nuscenes_class_checkpoint_is_measured_on_its_own_road_users(
    tmp_path, untrained_model, capsys
):
    """The worlds hold the checkpoint's classes, each counted and prompted (10 for nuScenes')."""
    model = untrained_model(
        "referent", text_encoder="gru", operating_threshold=0.5, classes="nuscenes"
    )
    ckpt = save_checkpoint(tmp_path / "random-nusc.pt", model, step=1)
    argv = ["--checkpoint", str(ckpt), "--worlds", "2", "--setups", "radar-1scan"]
    assert main([*argv, "--out-dir", str(tmp_path), "--quick"]) == 0
    assert "| Barrier recall (targets) |" in capsys.readouterr().out
    rows = json.loads((tmp_path / "sensor_shift.json").read_text())["data"]["setups"]
    names = set(model.cfg.class_set.names)
    assert all(set(r["targets"]) == names | {"all"} for r in rows)
    assert sum(r["targets"]["all"] for r in rows) > sum(r["targets"]["Car"] for r in rows) > 0


def test_bad_options_are_one_line_errors(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--setups", "no-such-rig", "--out-dir", str(tmp_path)])
    assert main(["--worlds", "0", "--out-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "error: --worlds must be >= 1, got 0"


def test_the_level_reference_is_where_the_training_rigs_ground_is_found():
    from model.config import PillarConfig
    from scenes.geometry.calib import sensor_to_lidar
    from scenes.geometry.ground import estimate_ground
    from scenes.synth.frame import SynthSettings, synthesize

    settings = SynthSettings(seed=38, camera=None)
    r2l = sensor_to_lidar(*settings.calibrations())
    found = [-estimate_ground(synthesize(settings, i, r2l).lidar.points, 1.7).c for i in range(4)]
    assert float(np.median(found)) == pytest.approx(PillarConfig().ground_height, abs=0.03)


def test_levelled_heights_run_and_say_so(tmp_path, untrained_model, capsys):
    model = untrained_model("referent", text_encoder="gru", operating_threshold=0.5)
    ckpt = save_checkpoint(tmp_path / "random.pt", model, step=1)
    argv = ["--checkpoint", str(ckpt), "--worlds", "1", "--setups", "lidar-low-pitched"]
    assert main([*argv, "--level-ground", "--out-dir", str(tmp_path)]) == 0
    assert "heights above the estimated ground" in capsys.readouterr().out
    data = json.loads((tmp_path / "sensor_shift.json").read_text())["data"]
    assert data["level_ground"] is True and len(data["setups"]) == 2
