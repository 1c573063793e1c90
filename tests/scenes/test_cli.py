"""``scenes/utils/cli.py``: a command line made from a frozen dataclass's fields."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import pytest

from scenes.utils.cli import add_options, from_args, option, report_errors

Colour = Literal["red", "green"]


@dataclass(frozen=True, kw_only=True)
class Example:
    name: str = option(help="a required flag")
    count: int = option(3, group="numbers", help="how many")
    ratio: float | None = option(None, group="numbers")
    colour: Colour = option("red", group="looks")
    where: Path | None = option(None, help="a path")
    tags: tuple[str, ...] = option((), flag="--tag")
    verbose: bool = option(False)
    colours: bool = option(True)
    baselines: bool = option(True, negatable=True, group="looks")
    hidden: int = option(7, cli=False)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="example")
    add_options(p, Example)
    return p


def test_defaults_types_and_switches() -> None:
    cfg = from_args(Example, parser().parse_args(["--name", "a"]))
    assert cfg == Example(name="a")
    cfg = from_args(
        Example,
        parser().parse_args(
            [
                "--name",
                "a",
                "--count",
                "5",
                "--ratio",
                "0.5",
                "--colour",
                "green",
                "--where",
                "x/y",
                "--tag",
                "p",
                "--tag",
                "q",
                "--verbose",
                "--no-colours",
                "--no-baselines",
            ]
        ),
    )
    assert cfg == Example(
        name="a",
        count=5,
        ratio=0.5,
        colour="green",
        where=Path("x/y"),
        tags=("p", "q"),
        verbose=True,
        colours=False,
        baselines=False,
    )
    assert isinstance(cfg.where, Path)


def test_errors_are_argparses(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, message in (
        ([], "the following arguments are required: --name"),
        (
            ["--name", "a", "--colour", "blue"],
            "invalid choice: 'blue' (choose from 'red', 'green')",
        ),
        (["--name", "a", "--count", "x"], "argument --count: invalid int value: 'x'"),
        (["--name", "a", "--hidden", "1"], "unrecognized arguments: --hidden"),
    ):
        with pytest.raises(SystemExit) as exc:
            parser().parse_args(argv)
        assert exc.value.code == 2
        assert message in capsys.readouterr().err


def test_groups_list_their_fields_in_field_order() -> None:
    groups = {g.title: [a.dest for a in g._group_actions] for g in parser()._action_groups}
    assert list(groups)[-2:] == ["numbers", "looks"]
    assert groups["numbers"] == ["count", "ratio"]
    assert groups["looks"] == ["colour", "baselines"]
    # ungrouped flags stay in the parser's own list
    assert groups["options"] == ["help", "name", "where", "tags", "verbose", "colours"]
    help_text = parser().format_help()
    assert help_text.index("\nnumbers:\n") < help_text.index("\nlooks:\n")


@dataclass(frozen=True, kw_only=True)
class Table:
    rows: tuple[str, ...] = option(positional=True, metavar="ROW")
    wide: bool = option(False, exclusive="shape")
    tall: bool = option(False, exclusive="shape")


def test_positional_fields_and_exclusive_switches(capsys: pytest.CaptureFixture[str]) -> None:
    p = argparse.ArgumentParser(prog="table")
    add_options(p, Table)
    assert from_args(Table, p.parse_args(["a", "b", "--tall"])) == Table(rows=("a", "b"), tall=True)
    assert from_args(Table, p.parse_args(["a"])) == Table(rows=("a",))
    for argv, message in (
        (["--wide"], "the following arguments are required: ROW"),
        (["a", "--wide", "--tall"], "argument --tall: not allowed with argument --wide"),
    ):
        with pytest.raises(SystemExit) as exc:
            p.parse_args(argv)
        assert exc.value.code == 2
        assert message in capsys.readouterr().err
    assert "[--wide | --tall]" in p.format_usage()


def test_report_errors_prints_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    def bad_value() -> int:
        raise ValueError("labels.txt line 3:\n  field 'x' is not a number")

    def missing_file() -> int:
        return len((tmp_path / "nope.json").read_text())

    assert report_errors(lambda: 0) == 0
    assert report_errors(bad_value) == 2
    assert capsys.readouterr().err == "error: labels.txt line 3: field 'x' is not a number\n"
    assert report_errors(missing_file) == 2
    assert (
        capsys.readouterr().err == f"error: {tmp_path / 'nope.json'}: No such file or directory\n"
    )
    with pytest.raises(KeyError):  # not an expected failure: a traceback
        report_errors(lambda: {}["k"])
    assert report_errors(bad_value, (KeyError, ValueError), status=3) == 3
