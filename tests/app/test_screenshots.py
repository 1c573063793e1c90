"""``python -m app.screenshots`` without the browser: its command line, the candidate frames
(from the data alone) and the frame choice (the first candidate answered with one box on its
labelled referent); and, with the shipped checkpoints, that the default seeds give each README
picture a frame the app answers correctly (checked here again with the model called directly).
The render itself runs with ``make screenshots``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.screenshots import (
    DEFAULT_OUT,
    SHOTS,
    ScreenshotConfig,
    ScreenshotError,
    build_parser,
    choose_frame,
    command_frames,
    main,
    synth_settings,
)
from scenes.geometry.boxes import iou3d
from scenes.language.reading import read_prompt
from scenes.talk2radar.root import Talk2RadarRoot
from scenes.utils.cli import from_args

TALK2RADAR, NUSCENES = SHOTS


def _config(argv: list[str]) -> ScreenshotConfig:
    return from_args(ScreenshotConfig, build_parser().parse_args(argv))


def test_the_command_line_builds_its_config() -> None:
    cfg = _config([])
    assert cfg.out == DEFAULT_OUT and cfg.only == "all" and cfg.min_iou == 0.25
    assert [s.file for s in cfg.shots()] == ["app.png", "app-nuscenes.png"]
    assert cfg.checkpoint_of(TALK2RADAR).name == "tpcnet-small.pt"
    assert cfg.checkpoint_of(NUSCENES).name == "tpcnet-nuscenes.pt"
    cfg = _config(["--only", "nuscenes", "--out", "x", "--nuscenes-seed", "3", "--seed", "5"])
    assert cfg.shots() == (NUSCENES,) and cfg.out == Path("x")
    assert cfg.seed_of(NUSCENES) == 3 and cfg.seed_of(TALK2RADAR) == 5
    cfg = _config(["--nuscenes-checkpoint", "n.pt", "--max-distance", "40"])
    assert cfg.checkpoint_of(NUSCENES) == Path("n.pt") and cfg.max_distance == 40.0
    settings = synth_settings(NUSCENES, 3)
    assert (settings.classes, settings.sensors, settings.command_share) == ("nuscenes",) * 2 + (1,)


@pytest.mark.parametrize("argv", [["--min-iou", "1.5"], ["--frames", "0"], ["--threads", "0"]])
def test_a_bad_value_is_one_error_line(argv, capsys) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err


@pytest.fixture(scope="module")
def command_root(tmp_path_factory) -> Path:
    """A small synthetic root of the Talk2Radar picture's settings (no camera: faster)."""
    from dataclasses import replace

    from scenes.synth.generate import generate_root

    root = tmp_path_factory.mktemp("shots") / "root"
    settings = replace(synth_settings(TALK2RADAR, 2), camera=None)
    generate_root(root, 12, settings, split_fractions=(0.0, 0.0, 1.0))
    return root


def test_candidates_are_the_commands_about_one_near_object(command_root) -> None:
    root = Talk2RadarRoot(command_root)
    found = command_frames(root, max_distance=25.0)
    chosen = {index for index, _ in found}
    assert len(found) >= 2, "the settings give too few command frames"
    for index, sid in enumerate(root.ids("test")):
        sample = root.load(sid)
        expected = (
            len(sample.boxes) == 1
            and np.hypot(*sample.boxes[0, :2]) <= 25.0
            and read_prompt(sample.prompt, root.classes).command
        )
        assert (index in chosen) == expected, (sid, sample.prompt)
    assert len(command_frames(root, max_distance=1000.0)) > len(found)  # one is farther


def test_the_first_candidate_answered_on_its_referent_is_chosen(command_root) -> None:
    found = command_frames(Talk2RadarRoot(command_root), max_distance=1000.0)
    assert len(found) >= 3, "the test needs three candidates"
    (_, first), (_, second), (third_index, third) = found[:3]
    moved = third.boxes[0] + np.array([0.1 * third.boxes[0, 3], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    far = second.boxes[0] + np.array([6.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    answers = {
        first.sample_id: np.stack([first.boxes[0], first.boxes[0]]),  # two boxes: not one
        second.sample_id: far[None],  # one box, but not on the referent
        third.sample_id: moved[None],
    }
    choice = choose_frame(found, lambda s: answers.get(s.sample_id, np.zeros((0, 7))), 0.25)
    assert (choice.index, choice.sample_id, choice.prompt) == (
        third_index,
        third.sample_id,
        third.prompt,
    )
    assert choice.passed_over == 2 and choice.candidates == len(found)
    assert choice.iou == pytest.approx(float(iou3d(moved[None], third.boxes)[0, 0]))
    assert choice.iou > 0.25 and choice.cls == third.classes[0]
    with pytest.raises(ScreenshotError, match="none of the"):
        choose_frame(found, lambda s: np.zeros((0, 7)), 0.25)
    with pytest.raises(ScreenshotError, match="no frame"):
        choose_frame([], lambda s: np.zeros((0, 7)), 0.25)


@pytest.mark.parametrize("shot", SHOTS, ids=[s.name for s in SHOTS])
def test_the_shipped_checkpoint_answers_a_default_frame(shot, tmp_path, torch_threads) -> None:
    """What ``make screenshots`` would show: the default seed's root gives a frame that the app's
    own path answers with one box on the labelled referent, and the model called directly agrees."""
    from app import AppConfig, Talk2PCApp
    from app.screenshots import choose_in_app, generate
    from model.checkpoint import load_checkpoint

    cfg = ScreenshotConfig()
    model_path = cfg.checkpoint_of(shot)
    if not model_path.is_file():
        pytest.skip(f"{model_path} is not shipped in this checkout")
    root = generate(shot, tmp_path / shot.name, cfg.frames, cfg.seed_of(shot))
    with torch_threads(1):
        model = load_checkpoint(model_path)
        app = Talk2PCApp(root, model, AppConfig(port=0, split="test"))
        try:
            choice = choose_in_app(app, root, cfg)
        finally:
            app.stop()
        sample = Talk2RadarRoot(root, classes=app.engine.classes).load(choice.sample_id)
        answer = model.ground(
            model.encode_scene(sample.lidar, sample.radar),
            sample.prompt,
            score_threshold=app.score_threshold,
        )
    assert read_prompt(sample.prompt, app.engine.classes).command and len(sample.boxes) == 1
    assert len(answer.boxes) == 1
    assert float(iou3d(np.asarray(answer.boxes).reshape(-1, 7), sample.boxes)[0, 0]) > 0.25
