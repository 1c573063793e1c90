"""``python -m model.evaluate``'s command line comes from ``EvaluateConfig`` (model/evaluate.py),
and every command line the README and docs/ show still parses, to what the hand-written parser
before it gave."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from model.checkpoint import DEFAULT_CHECKPOINT
from model.evaluate import EvaluateConfig, build_parser, parse_args
from tests.house.test_documented_commands import documented_command_lines as all_command_lines

COMMAND = "python -m model.evaluate"


def documented_command_lines() -> list[tuple[str, str]]:
    """``(file, arguments)`` of every ``python -m model.evaluate`` command line in README.md and
    docs/*.md, as :func:`tests.house.test_documented_commands.documented_command_lines` finds them."""
    return [(where, args) for where, c, args in all_command_lines() if c == COMMAND]


def test_the_docs_show_command_lines() -> None:
    lines = documented_command_lines()
    assert len(lines) >= 10
    assert sum("[" in a for _, a in lines) >= 2  # README's two synopses


@pytest.mark.parametrize(("where", "args"), documented_command_lines())
def test_every_documented_command_line_parses(where: str, args: str) -> None:
    parser = build_parser()
    if "[" in args:  # a synopsis: its flags and choices exist
        known = {s: a for a in parser._actions for s in a.option_strings}
        for flag, value in re.findall(r"(--[a-z-]+)(?: ([^\s\]]+))?", args):
            assert flag in known, f"{where}: {flag}"
            if value and "|" in value:
                assert set(value.split("|")) == set(known[flag].choices), f"{where}: {flag}"
        return
    cfg = parse_args(shlex.split(args))
    assert cfg.mode() in ("files", "model")


# What the hand-written parser (before EvaluateConfig) gave for lines the docs show.
BEFORE = {
    "--data ROOT --split all": dict(data=Path("ROOT"), split="all"),
    "--data T2R --scene-labels VOD --candidates labels --checkpoint runs/t2r-referent/last.pt": dict(
        data=Path("T2R"),
        scene_labels=Path("VOD"),
        candidates="labels",
        checkpoint=Path("runs/t2r-referent/last.pt"),
    ),
    "--data T2R --scene-labels VOD --split val --limit 20": dict(
        data=Path("T2R"), scene_labels=Path("VOD"), split="val", limit=20
    ),
    "--data data/eval-s99 --out runs/eval/referent-s99 --json docs/results/referent-eval-s99.json": dict(
        data=Path("data/eval-s99"),
        out=Path("runs/eval/referent-s99"),
        json=Path("docs/results/referent-eval-s99.json"),
    ),
    "--labels DIR --preds DIR --json OUT --exact-overlaps": dict(
        labels=Path("DIR"), preds=Path("DIR"), json=Path("OUT"), exact_overlaps=True
    ),
    "--data R --no-baselines --threshold 0.4 --radar-folder none --device cuda": dict(
        data=Path("R"), baselines=False, threshold=0.4, radar_folder="none", device="cuda"
    ),
}

DEFAULTS = dict(
    labels=None,
    preds=None,
    data=None,
    split="test",
    checkpoint=DEFAULT_CHECKPOINT,
    out=None,
    threshold=None,
    baselines=True,
    radar_folder="auto",
    scene_labels=None,
    candidates="detector",
    device="cpu",
    limit=0,
    json=None,
    exact_overlaps=False,
)


@pytest.mark.parametrize("args", sorted(BEFORE))
def test_parses_to_what_the_parser_before_gave(args: str) -> None:
    assert parse_args(shlex.split(args)) == EvaluateConfig(**{**DEFAULTS, **BEFORE[args]})


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "give --labels DIR --preds DIR, or --data ROOT [--checkpoint PATH] [--out DIR]"),
        (["--labels", "a"], "--labels and --preds go together"),
        (["--data", "r", "--preds", "b"], "--data does not go with --labels/--preds"),
        (
            ["--data", "r", "--classes", "nuscenes"],
            "--classes goes with --labels/--preds; --data scores the checkpoint's class set",
        ),
        (
            ["--data", "r", "--candidates", "x"],
            "argument --candidates: invalid choice: 'x' (choose from 'detector', 'labels')",
        ),
    ],
)
def test_mode_errors_are_usage_errors(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: python -m model.evaluate") and f"error: {message}\n" in err


def test_help_keeps_its_groups() -> None:
    groups = {g.title: [a.dest for a in g._group_actions] for g in build_parser()._action_groups}
    assert groups["score prediction files"] == ["labels", "preds", "classes"]
    assert groups["ground a split with a checkpoint, then score it"][0] == "data"
    assert groups["options"] == ["help", "json", "exact_overlaps"]
