"""Command lines made from frozen dataclass configs: each field is one flag, and its type, default
and help are the only source of that flag (every command: ``python -m scenes.synth``,
``scenes.export_real``, ``model.train``, ``model.evaluate``, ``model.calibrate``,
``model.class_prompts``, the ``bench.*`` entry points and ``python launch.py``). Here, in the bottom
package, so that every package may use it.

A field becomes ``--field-name`` (underscores to hyphens) unless :func:`option` names another
flag; ``Literal[...]`` (or ``Literal[...] | None``) gives the choices, ``int`` / ``float`` /
``str`` the type, a ``tuple[X, ...]`` a flag given once per value (``action="append"``), a
``Path`` (or ``Path | None``) a path, a ``bool`` a switch (``--name`` for a default of False,
``--no-name`` for True, or both forms with ``negatable=True``), a fixed-length ``tuple[X, X, X]`` a
flag taking that many values at once (``nargs``). ``choices`` (for a field typed ``int``, ``float``
or ``str`` whose values a constant lists) and ``metavar`` pass to argparse as they are; help may
name the default as ``%(default)s``, so that no help text restates it. A field without a default
is a required flag. Fields with ``cli=False`` metadata have no flag; fields with a ``group`` title are
listed under that argument group in ``--help`` (groups in the order their first field comes);
fields with one ``exclusive`` title are switches of which a command line gives at most one (an
argparse mutually exclusive group). A ``positional`` field is an argument without a flag (a
``tuple[X, ...]`` one: one or more values).

A command's parser is :func:`command_parser` (its name, description and config classes) and its
``main`` :func:`run_command` (parse into the config, run, report): an expected failure (bad input,
a missing file) is one ``error: ...`` line (:func:`error_line`) and exit status 2, not a traceback
(:func:`report_errors`).

Why not ``tyro``: the commands' flags, help text and errors are relied on by scripts and docs
(docs/DESIGN.md); tyro renames and re-formats them (``--flag/--no-flag`` pairs, its own help
layout and error messages, ``nargs`` lists instead of repeated flags), and keeping every existing
spelling would take a marker on nearly every field. Generating the argparse parser from the
fields keeps the command lines exactly and still has one source for each setting.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import types
import typing
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal, TextIO, TypeVar

C = TypeVar("C")


def option(
    default: Any = dataclasses.MISSING,
    *,
    help: str | None = None,
    flag: str | None = None,
    negatable: bool = False,
    on_resume: bool = False,
    default_factory: Callable[[], Any] | Any = dataclasses.MISSING,
    cli: bool = True,
    group: str | None = None,
    choices: Sequence[Any] | None = None,
    metavar: str | tuple[str, ...] | None = None,
    nargs: str | None = None,
    exclusive: str | None = None,
    positional: bool = False,
) -> Any:
    """A dataclass field with its command-line flag's settings.

    Args:
        default: The field's default (none: a required flag).
        help: The flag's help text.
        flag: The flag's spelling when it is not ``--field-name``.
        negatable: A bool given as ``--name`` / ``--no-name`` (``BooleanOptionalAction``).
        on_resume: The setting may change when a run is resumed (:func:`resumable_fields`).
        default_factory: As :func:`dataclasses.field`'s (also the flag's default).
        cli: False: a field with no flag.
        group: The title of the argument group the flag is listed under (None: the parser's).
        choices: The values the flag takes (default: a ``Literal`` type's, else any).
        metavar: The flag's value name(s) in ``--help`` (a tuple for a fixed-length tuple).
        nargs: For a ``tuple[X, ...]``: the values given after one flag (``"+"``), instead of
            the flag repeated once per value.
        exclusive: The title of a set of switches of which at most one may be given (fields
            with the same title; a ``group`` is then ignored).
        positional: An argument without a flag, named by the field (required unless it has a
            default; a ``tuple[X, ...]``: one or more values, ``nargs="+"``).
    """
    meta = {
        "help": help,
        "flag": flag,
        "negatable": negatable,
        "on_resume": on_resume,
        "cli": cli,
        "group": group,
        "choices": None if choices is None else tuple(choices),
        "metavar": metavar,
        "nargs": nargs,
        "exclusive": exclusive,
        "positional": positional,
    }
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def choices_of(tp: Any) -> tuple[Any, ...] | None:
    """The values of a ``Literal`` type (also inside ``X | None``); None for another type."""
    if typing.get_origin(tp) is Literal:
        return typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            found = choices_of(arg)
            if found is not None:
                return found
    return None


def _base(tp: Any) -> Any:
    """``X`` of ``X | None``."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return args[0] if len(args) == 1 else str
    return tp


def flag_name(field: dataclasses.Field) -> str:
    """The flag of a field: ``--field-name``, ``--no-field-name`` for a switch that is on by
    default, or the one :func:`option` names."""
    if field.metadata.get("flag"):
        return field.metadata["flag"]
    switch_off = field.default is True and not field.metadata.get("negatable")
    return ("--no-" if switch_off else "--") + field.name.replace("_", "-")


def _default(field: dataclasses.Field) -> Any:
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def _shown(value: Any) -> str:
    """A default as ``--help`` names it: a sequence as its values separated by spaces (as they
    are typed), anything else as ``str``."""
    if isinstance(value, (tuple, list)):
        return " ".join(str(v) for v in value)
    return str(value)


def add_options(parser: argparse.ArgumentParser, cls: type, only: tuple[str, ...] = ()) -> None:
    """One flag per field of ``cls`` (in field order; ``only``: just these fields)."""
    hints = typing.get_type_hints(cls, include_extras=True)
    groups: dict[str, argparse._ArgumentGroup] = {}
    exclusive: dict[str, argparse._MutuallyExclusiveGroup] = {}
    for f in dataclasses.fields(cls):
        if not f.metadata.get("cli", True) or (only and f.name not in only):
            continue
        title = f.metadata.get("exclusive")
        if title is not None:
            if title not in exclusive:
                exclusive[title] = parser.add_mutually_exclusive_group()
            _add_option(exclusive[title], f, hints[f.name])
        else:
            _add_option(_group(parser, groups, f.metadata.get("group")), f, hints[f.name])


def _group(
    parser: argparse.ArgumentParser,
    groups: dict[str, argparse._ArgumentGroup],
    title: str | None,
) -> argparse.ArgumentParser | argparse._ArgumentGroup:
    """The parser itself (``title`` None) or its argument group ``title`` (made on first use)."""
    if title is None:
        return parser
    if title not in groups:
        groups[title] = parser.add_argument_group(title)
    return groups[title]


def _add_positional(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, f: dataclasses.Field, tp: Any
) -> None:
    """The flagless argument of field ``f`` (type ``tp``): one value of its type, or one or more
    of a ``tuple[X, ...]``; optional (``?`` / ``*``) when the field has a default."""
    required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    base = _base(tp)
    kw: dict[str, Any] = {}
    if typing.get_origin(base) is tuple:
        base = typing.get_args(base)[0]
        kw["nargs"] = "+" if required else "*"
    elif not required:
        kw["nargs"] = "?"
    if base in (int, float, Path):
        kw["type"] = base
    if not required:
        kw["default"] = _default(f)
    for key in ("help", "metavar", "choices"):
        if f.metadata.get(key) is not None:
            kw[key] = f.metadata[key]
    parser.add_argument(f.name, **kw)


def _add_option(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, f: dataclasses.Field, tp: Any
) -> None:
    """The flag of field ``f`` (type ``tp``) on ``parser`` (module docstring)."""
    if f.metadata.get("positional"):
        _add_positional(parser, f, tp)
        return
    name = flag_name(f)
    kw: dict[str, Any] = {"dest": f.name}
    required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    if f.metadata.get("help") is not None:
        shown = "" if required else _shown(_default(f))
        kw["help"] = f.metadata["help"].replace("%(default)s", shown.replace("%", "%%"))
    base = _base(tp)
    if base is bool:
        if f.metadata.get("negatable"):
            kw.update(action=argparse.BooleanOptionalAction, default=_default(f))
        else:
            kw.update(action="store_false" if _default(f) else "store_true")
    elif typing.get_origin(base) is tuple and Ellipsis not in typing.get_args(base):
        items = typing.get_args(base)
        kw.update(nargs=len(items), type=items[0], required=required)
        if not required:
            kw["default"] = _default(f)
    elif typing.get_origin(base) is tuple:
        item = typing.get_args(base)[0]
        if f.metadata.get("nargs"):
            kw.update(nargs=f.metadata["nargs"], required=required)
        else:
            kw.update(action="append", required=required)
        if not required:
            default = _default(f)
            kw["default"] = None if default is None else list(default)
        if item is not str:
            kw["type"] = item
        if f.metadata.get("choices") is not None:
            kw["choices"] = list(f.metadata["choices"])
        if f.metadata.get("flag"):
            kw["metavar"] = name.lstrip("-").replace("-", "_").upper()
    else:
        listed = f.metadata.get("choices")
        choices = listed if listed is not None else choices_of(tp)
        if base in (int, float, Path):
            kw["type"] = base
        if choices is not None:
            kw["choices"] = list(choices)
        if required:
            kw["required"] = True
        else:
            kw["default"] = _default(f)
    if f.metadata.get("metavar") is not None:
        kw["metavar"] = f.metadata["metavar"]
    parser.add_argument(name, **kw)


def from_args(cls: type, args: argparse.Namespace, **extra: Any) -> Any:
    """``cls`` built from the parsed flags of its fields (tuples from repeated flags) and
    ``extra``."""
    given: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if hasattr(args, f.name):
            value = getattr(args, f.name)
            given[f.name] = tuple(value) if isinstance(value, list) else value
    return cls(**{**given, **extra})


def resumable_fields(cls: type) -> frozenset[str]:
    """The fields of ``cls`` marked ``on_resume`` (settings a resumed run may change)."""
    return frozenset(f.name for f in dataclasses.fields(cls) if f.metadata.get("on_resume"))


def error_line(exc: BaseException) -> str:
    """``exc`` as the one line a command prints after ``error:`` or ``warning:``: an
    ``OSError`` as ``FILE: reason`` (its ``filename`` and ``strerror``), anything else its
    message; whitespace (newlines included) collapsed to single spaces."""
    if isinstance(exc, OSError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    else:
        text = str(exc)
    return " ".join(text.split()) or type(exc).__name__


def command_parser(prog: str, description: str, *configs: type) -> argparse.ArgumentParser:
    """The parser of command ``prog`` (e.g. ``"python -m scenes.export_real"``): the flags of
    each class of ``configs`` in turn (:func:`add_options`)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    for cls in configs:
        add_options(parser, cls)
    return parser


def run_command(
    parser: argparse.ArgumentParser,
    config: type[C],
    run: Callable[[C], int],
    argv: Sequence[str] | None = None,
    errors: tuple[type[BaseException], ...] = (ValueError, OSError),
) -> int:
    """A command's ``main``: ``argv`` (None: ``sys.argv[1:]``) parsed by ``parser`` into
    ``config`` (:func:`from_args`; a usage error exits 2 as argparse does), then ``run(config)``'s
    exit status, an error of ``errors`` reported as one line (:func:`report_errors`)."""
    args = from_args(config, parser.parse_args(argv))
    return report_errors(lambda: run(args), errors)


def report_errors(
    run: Callable[[], int],
    errors: tuple[type[BaseException], ...] = (ValueError, OSError),
    status: int = 2,
) -> int:
    """``run()``'s exit status; when it raises one of ``errors``, that error as one ``error:``
    line on stderr (:func:`error_line`) and ``status``. The one home of a command's
    ``try: ... except: print(error); return 2``."""
    try:
        return run()
    except errors as exc:
        print(f"error: {error_line(exc)}", file=sys.stderr)
        return status


def as_sentence(text: str) -> str:
    """``text`` on one line, spaces collapsed, ending with a full stop (unless it ends with
    ``.``, ``!`` or ``?`` already)."""
    line = " ".join(str(text).split())
    return line if not line or line[-1] in ".!?" else line + "."


def show_warnings_as_lines() -> None:
    """Print each warning this process meets as one ``warning:`` line on stderr: its message as
    a sentence (:func:`as_sentence`), without the file, line, category and source line that
    Python's default display adds ("root.py:243: UserWarning: ...", then "warnings.warn(").
    For commands a person reads; the warnings themselves (their filters, ``pytest.warns``) are
    unchanged."""

    def show(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        print(f"warning: {as_sentence(str(message))}", file=file or sys.stderr, flush=True)

    warnings.showwarning = show


__all__ = [
    "add_options",
    "as_sentence",
    "choices_of",
    "command_parser",
    "error_line",
    "flag_name",
    "from_args",
    "option",
    "report_errors",
    "resumable_fields",
    "run_command",
    "show_warnings_as_lines",
]
