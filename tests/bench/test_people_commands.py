"""bench.people_commands: people's commands placed on synthetic frames and scored beside the
class noun (issue 49). The command file here is written by the test (sentences of our own, in
the Talk2Car file's format), so the test does not need the licensed test split."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.studies.people_commands import main, run_people_commands
from bench.studies.people_frames import CommandFileError, FramePlacer, read_people_commands, side_of
from model import DEFAULT_CHECKPOINT
from scenes.geometry.classes import VOD
from scenes.talk2radar.root import Talk2RadarRoot


def _command(text: str, category: str, right: float, ahead: float) -> dict:
    return {"command": text, "obj_name": category, "translation": [right, 0.5, ahead]}


@pytest.fixture
def commands_file(tmp_path: Path) -> Path:
    rows = [
        _command("park behind the silver van on the right", "vehicle.car", 4.0, 17.0),
        _command("follow that taxi on the right", "vehicle.car", 4.5, 18.0),
        _command("stop next to the blue car", "vehicle.car", 5.0, 16.0),
        _command("wait for the cow to cross", "animal", 3.0, 10.0),
    ]
    path = tmp_path / "commands.json"
    path.write_text(json.dumps({"scene_tokens": [], "commands": rows}))
    return path


def test_commands_are_read_with_their_side_and_class(commands_file: Path) -> None:
    commands, outside = read_people_commands(commands_file, VOD)
    assert [c.cls for c in commands] == ["Car", "Car", "Car", None]
    assert {c.side for c in commands[:3]} == {"right"} and outside == {"animal": 1}
    assert side_of(0.3) == "centre" and side_of(2.0) == "left" and side_of(-2.0) == "right"


@pytest.mark.parametrize(
    ("body", "field"),
    [('{"commands": [{"command": "", "obj_name": "vehicle.car"}]}', "command"),
     ('{"commands": [{"command": "x", "obj_name": "vehicle.car", "translation": [1]}]}',
      "translation"),
     ("[]", "commands")],
)  # fmt: skip
def test_a_bad_command_file_is_named(tmp_path: Path, body: str, field: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(body)
    with pytest.raises(CommandFileError, match=field) as err:
        read_people_commands(path, VOD)
    assert str(path) in str(err.value)


def test_placed_frames_hold_the_referent_alone_ahead_of_its_class() -> None:
    placer = FramePlacer(VOD, seed=4242, frames_per_bin=2)
    frames = placer.frames(("Car", "right", 3))
    assert len(frames) == 2 and frames[0].frame.world.world_id != frames[1].frame.world.world_id
    for placed in frames:
        ahead = [a for a in placed.frame.world.actors if a.cls == "Car" and a.box[0] > 0]
        assert ahead == [placed.referent]
        assert side_of(float(placed.referent.box[1])) == "right"
        assert 15.0 - 4.0 <= placed.referent.box[0] <= 20.0 + 4.0


def test_the_bench_scores_the_model_beside_the_class_noun(commands_file, tmp_path) -> None:
    root = tmp_path / "root"
    report = run_people_commands(
        commands_file, DEFAULT_CHECKPOINT, 4242, 1, progress=False, root=root
    )
    tally = report.by_class["Car"]
    assert tally.commands == 3 and report.outside == {"animal": 1}
    assert tally.top1["class noun"] >= 2  # the class alone finds the referent on these frames
    assert tally.top1["model"] >= 2  # the colour and the manoeuvre do not lose it
    table = report.table()
    assert "| Car | 3 |" in table and "animal 1" in table
    written = Talk2RadarRoot(root)
    ids = written.ids("test")
    assert len(ids) == 3
    assert {written.load_prompt(i) for i in ids} == {
        "park behind the silver van on the right",
        "follow that taxi on the right",
        "stop next to the blue car",
    }


def test_without_a_command_file_it_says_so(tmp_path, capsys) -> None:
    assert main(["--commands", str(tmp_path / "missing.json")]) == 0
    assert "no such file" in capsys.readouterr().out
    assert main([]) == 0
