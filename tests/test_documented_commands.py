"""Every command line README.md and docs/*.md show (``python -m <module> ...``, ``python
launch.py ...`` and ``python bench/<name>.py ...``) parses with its command's parser, without running the command; a synopsis
(``[--flag VALUE]``) names only flags and choices that exist. A command the docs show that is not
listed here fails the test, so that a new one gets checked too. (``tests/test_evaluate_config.py``
also checks what ``model.evaluate``'s lines parse to.)"""

from __future__ import annotations

import argparse
import importlib
import re
import shlex
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

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
    "python -m bench.unlabelled_root": ("bench.unlabelled_root", "build_parser"),
    "python -m app.screenshots": ("app.screenshots", "build_parser"),
    **{
        command: (f"bench.{name}", "build_parser")
        for name in (
            "bench_synth",
            "carry_accuracy",
            "compare_nuscenes_devkit",
            "compare_vod_devkit",
            "eval_throughput",
            "fit_accuracy",
            "floor",
            "fusion_cost",
            "graph_cost",
            "labelled_shift",
            "language_suite",
            "latency",
            "model_size",
            "people_commands",
            "run_all",
            "sensor_shift",
            "sensor_stats",
            "soak",
            "talk2car_recall",
            "train_throughput",
        )
        for command in (f"python -m bench.{name}", f"python bench/{name}.py")
    },
}
"""Each documented command and where its parser is made (module, function)."""

HELPERS = ("python -m tests.",)
"""Test helpers the docs mention (their own scripts, not the product's commands)."""

COMMAND = re.compile(
    r"python (?:-m [a-z_][a-z0-9_.]*[a-z0-9_]|launch\.py|bench/[a-z0-9_]+\.py)(?=[\s`]|$)"
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
