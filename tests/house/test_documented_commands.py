"""Every command line README.md and docs/*.md show (``python -m <module> ...``, ``python
launch.py ...`` and ``python bench/<kind>/<name>.py ...``) parses with its command's parser, without running the command; a synopsis
(``[--flag VALUE]``) names only flags and choices that exist. A command the docs show that is not
listed here fails the test, so that a new one gets checked too. (``tests/model/evaluation/test_evaluate_config.py``
also checks what ``model.evaluate``'s lines parse to.)"""

from __future__ import annotations

import argparse
import importlib
import re
import shlex
from collections.abc import Callable

import pytest

from tests.paths import REPO

STABLE_ENTRIES = (
    "eval_throughput",
    "floor",
    "language_suite",
    "people_commands",
    "sensor_shift",
    "talk2car_recall",
)
"""Benchmarks whose old command line ``python -m bench.<name>`` stays (an entry module)."""

PARSERS: dict[str, tuple[str, str]] = {
    "python launch.py": ("launch", "build_parser"),
    "python -m scenes.synth": ("scenes.synth.generate", "_parser"),
    "python -m scenes.export_real": ("scenes.export_real", "_parser"),
    "python -m scenes.export_nuscenes": ("scenes.export_nuscenes", "_parser"),
    "python -m model.train": ("model.training.config", "build_parser"),
    "python -m model.evaluate": ("model.evaluate", "build_parser"),
    "python -m model.calibrate": ("model.training.calibrate", "build_parser"),
    "python -m model.class_prompts": ("model.evaluation.class_prompts", "_parser"),
    "python -m model.results_table": ("model.evaluation.results_table", "build_parser"),
    "python -m model.adapt": ("model.adapt.config", "build_parser"),
    "python -m tools.unlabelled_root": ("tools.unlabelled_root", "build_parser"),
    "python -m app.screenshots": ("app.screenshots", "build_parser"),
    "python -m tools.nuscenes_converter": ("tools.nuscenes_converter", "build_parser"),
    "python -m tools.camera_shot": ("tools.camera_shot", "build_parser"),
    "python -m bench.run_all": ("bench.run_all", "build_parser"),
    "python bench/run_all.py": ("bench.run_all", "build_parser"),
    **{
        command: (f"bench.{home}.{name}", "build_parser")
        for home, names in {
            "perf": (
                "bench_synth",
                "eval_throughput",
                "floor",
                "fusion_cost",
                "graph_cost",
                "latency",
                "model_size",
                "soak",
                "train_throughput",
            ),
            "studies": (
                "carry_accuracy",
                "fit_accuracy",
                "labelled_shift",
                "language_suite",
                "people_commands",
                "sensor_shift",
                "sensor_stats",
                "talk2car_recall",
            ),
            "devkit": ("compare_nuscenes_devkit", "compare_vod_devkit"),
        }.items()
        for name in names
        for command in (
            f"python -m bench.{home}.{name}",
            f"python bench/{home}/{name}.py",
            # the stable command lines of bench/<name>.py (which calls the moved module's main)
            *([f"python -m bench.{name}"] if name in STABLE_ENTRIES else []),
        )
    },
}
"""Each documented command and where its parser is made (module, function)."""

HELPERS: tuple[str, ...] = ()
"""Test helpers the docs may show as commands: none. Nothing outside tests/ runs a ``tests.*``
module; a fixture's regeneration is in its test module's docstring, and a figure a doc quotes from
a test is cited as ``python -m pytest tests/<file>.py``."""

COMMAND = re.compile(
    r"python (?:-m [a-z_][a-z0-9_.]*[a-z0-9_]|launch\.py|bench/(?:[a-z]+/)?[a-z0-9_]+\.py)(?=[\s`]|$)"
)


def documented_command_lines() -> list[tuple[str, str, str]]:
    """``(file, command, arguments)`` of every command line in README.md and docs/*.md: an
    inline-code span up to its closing backtick, a code-block line with its ``\\``
    continuations; a ``#`` comment dropped. A mention without flags is not a command line."""
    found = []
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        text = path.read_text()
        for m in COMMAND.finditer(text):
            if m.start() > 0 and text[m.start() - 1] == "`":
                end = text.index("`", m.end())
            else:  # a code-block line and its continuations
                end = text.find("\n", m.end())
                while end != -1 and text[end - 1] == "\\":
                    end = text.find("\n", end + 1)
                end = len(text) if end == -1 else end
            args = text[m.end() : end].replace("\\\n", " ").replace("\\|", "|").split("#")[0]
            args = " ".join(re.split(r"&&|;| [0-9]?> ", args)[0].split())  # this command only
            if args.startswith("-") or (args and m.group(0) == "python -m model.results_table"):
                found.append((path.name, m.group(0), args))
    return found


def _parser(command: str) -> argparse.ArgumentParser:
    module, name = PARSERS[command]
    factory: Callable[[], argparse.ArgumentParser] = getattr(importlib.import_module(module), name)
    return factory()


LINES = documented_command_lines()


def test_the_docs_show_every_kind_of_command() -> None:
    shown = {command for _, command, _ in LINES}
    assert len(LINES) >= 80
    assert {"python launch.py", "python -m scenes.synth", "python -m model.train"} <= shown
    unknown = {c for c in shown if c not in PARSERS and not c.startswith(HELPERS)}
    assert not unknown, f"documented commands without a parser in PARSERS: {sorted(unknown)}"


def test_no_documented_command_runs_a_test_module() -> None:
    shown = [
        f"{path.name}: {m.group(0)}"
        for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
        for m in re.finditer(r"python (?:-m tests\.|tests/)\S*", path.read_text())
    ]
    assert not shown, f"docs run tests.* modules: {shown}"


@pytest.mark.parametrize(
    ("where", "command", "args"),
    [line for line in LINES if line[1] in PARSERS],
    ids=[f"{w}:{c.split()[-1]}:{i}" for i, (w, c, _) in enumerate(LINES) if c in PARSERS],
)
def test_every_documented_command_line_parses(where: str, command: str, args: str) -> None:
    parser = _parser(command)
    if "[" in args or "|" in args or "..." in args:  # a synopsis: its flags and choices exist
        known = {s: a for a in parser._actions for s in a.option_strings}
        for flag, value in re.findall(r"(--[a-z0-9-]+)(?: ([^\s\]]+))?", args):
            assert flag in known, f"{where}: {command} {flag}"
            choices = known[flag].choices
            if "|" in value.strip("|") and choices is not None:  # VALUE|VALUE: all exist
                named = set(value.split("|"))
                assert named <= {str(c) for c in choices}, f"{where}: {command} {flag} {value}"
        return
    try:
        parser.parse_args(shlex.split(args))
    except SystemExit as exc:
        pytest.fail(f"{where}: `{command} {args}` does not parse (exit {exc.code})")
