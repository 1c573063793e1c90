"""Markdown tables in the shape of the paper's tables I and III from ``model.evaluate`` JSON files.

``python -m model.results_table NAME=PATH.json [NAME=PATH.json ...] [--by-type | --by-depth |
--grounding | --grounding-splits]`` prints one row per file: the overall table (3D AP per class and
mAP/mAOS at 11 recall points, entire annotated area and driving corridor, the 40-point mAP beside
it), or with ``--by-type`` the 3D mAP per prompt type (table III), or with ``--by-depth`` the 3D mAP
per 10 m depth bin (table IV). ``--grounding`` prints the per-prompt grounding metrics
(:mod:`model.evaluation.grounding`) with three rows per file, the model and its baselines (class-noun
prompt, language-blind oracle): Acc@0.25, Acc@0.5, set precision / recall / F1 (micro over boxes),
set F1 (mean per-prompt F1), exact-set accuracy and the entire-area 3D mAP; ``--grounding-splits``
prints Acc@0.25 / set F1 / exact-set per prompt group and type. Files written before the grounding
metrics existed still give the first three tables.
docs/RESULTS.md's comparison tables are made with it, so each figure there is one command away from
the JSON it came from.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from model.evaluation.grounding import SPLIT_NAMES
from model.evaluation.metrics import AREAS
from model.evaluation.report import PROMPT_TYPES, ROW_NAMES
from model.evaluation.report_file import (
    BY_DEPTH,
    BY_TYPE,
    GROUNDING,
    NUM_FRAMES,
    AnswerSetFigures,
    AreaFigures,
    ReportFile,
    ReportFileError,
    SubsetFigures,
)
from scenes.geometry.classes import VOD
from scenes.utils.cli import command_parser, option, run_command
from scenes.utils.textfile import read_text_file

ResultsTableError = ReportFileError
"""A results file that is missing, unreadable or lacks a field (the message names it)."""


@dataclass(frozen=True)
class Row:
    """One table row: a label and its ``model.evaluate --json`` file, read
    (:class:`model.evaluation.report_file.ReportFile`)."""

    name: str
    report: ReportFile

    @property
    def source(self) -> str:
        return self.report.source


def load_row(spec: str) -> Row:
    """Parse ``NAME=PATH`` and read the JSON file it names."""
    name, sep, path = spec.partition("=")
    if not sep or not name or not path:
        raise ResultsTableError(f"{spec!r}: expected NAME=PATH.json")
    if not Path(path).exists():
        raise ResultsTableError(f"{path}: no such results file")
    try:
        data = json.loads(read_text_file(path, "results file", ResultsTableError))
    except json.JSONDecodeError as exc:
        raise ResultsTableError(f"{path}: not JSON (line {exc.lineno}: {exc.msg})") from None
    return Row(name, ReportFile.read(data, path, name, ROW_NAMES))


def _markdown(head: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    """A markdown table: the first column left-aligned, the others (numbers) right-aligned."""
    lines = ["| " + " | ".join(head) + " |", "| --- |" + " ---: |" * (len(head) - 1)]
    lines += ["| " + " | ".join(cells) + " |" for cells in body]
    return "\n".join(lines)


def _classes(rows: Sequence[Row]) -> tuple[str, ...]:
    """The classes of the rows' reports (the first row's order; a class only another row has
    after them): a column each, "-" in a row without it."""
    names: dict[str, None] = {}
    for row in rows:
        figures = row.report.need(AREAS[0])
        assert isinstance(figures, AreaFigures)
        names.update(dict.fromkeys(figures.ap_3d))
    return tuple(names)


def overall_table(rows: Sequence[Row]) -> str:
    """Table I's shape: per-class 3D AP (a column per class of the rows' class sets), mAP and
    mAOS (11 points) for both areas, R40 mAP."""
    classes = _classes(rows)
    short = [c[:3] if c in VOD.names else c for c in classes]  # Car, Ped, Cyc as before
    head = ["model", "frames"]
    head += [f"EAA {c}" for c in short] + ["**EAA mAP**", "EAA mAOS", "EAA mAP R40"]
    head += [f"DCA {c}" for c in short] + ["DCA mAP", "DCA mAOS"]
    body = []
    for row in rows:
        cells = [row.name, str(row.report.need(NUM_FRAMES))]
        for area in AREAS:
            scores = row.report.need(area)
            assert isinstance(scores, AreaFigures)
            cells += [f"{scores.ap_3d[c]:.2f}" if c in scores.ap_3d else "-" for c in classes]
            m = f"{scores.map_3d:.2f}"
            cells += [f"**{m}**" if area == "entire_area" else m]
            cells += [f"{scores.maos:.2f}"]
            if area == "entire_area":
                cells += [f"{scores.map_3d_r40:.2f}"]
        body.append(cells)
    return _markdown(head, body)


def _subsets(row: Row, section: str) -> dict[str, SubsetFigures]:
    subsets = row.report.need(section)
    assert isinstance(subsets, dict)
    return subsets


def by_type_table(rows: Sequence[Row]) -> str:
    """Table III's shape: entire-area 3D mAP (11 points) per prompt type."""
    body = []
    for row in rows:
        types = _subsets(row, BY_TYPE)
        cells = [row.name]
        for t in PROMPT_TYPES:
            if t not in types:
                raise ResultsTableError(f"{row.source} [{BY_TYPE}]: missing field {t!r}")
            cells.append(f"{types[t].entire_area.map_3d:.2f}")
        body.append(cells)
    return _markdown(["model", *PROMPT_TYPES], body)


def by_depth_table(rows: Sequence[Row]) -> str:
    """Table IV's shape: entire-area 3D mAP (11 points) per 10 m depth bin (bins without ground
    truth objects show ``-``); the bins are those of the first row's file."""
    if not rows:
        return ""
    bins = list(_subsets(rows[0], BY_DEPTH))
    body = []
    for row in rows:
        depth = _subsets(row, BY_DEPTH)
        cells = [row.name]
        for b in bins:
            if b not in depth:
                raise ResultsTableError(f"{row.source} [{BY_DEPTH}.{b}]: missing field {b!r}")
            entry = depth[b]
            cells.append("-" if entry.count == 0 else f"{entry.entire_area.map_3d:.2f}")
        body.append(cells)
    return _markdown(["model", *(f"{b} m" for b in bins)], body)


def _answer_sets(rows: Sequence[Row]) -> Iterator[AnswerSetFigures]:
    """Every answer set of every file (the model, then its baselines)."""
    for row in rows:
        if row.report.answer_sets is None:
            raise ResultsTableError(
                f"{row.source}: missing field {GROUNDING!r} (written before the grounding "
                "metrics; rerun python -m model.evaluate --data ROOT)"
            )
        yield from row.report.answer_sets


def grounding_table(rows: Sequence[Row]) -> str:
    """Per-prompt grounding, one row per answer set (model, class noun, oracle) of each file."""
    head = ["model", "prompts", "Acc@0.25", "Acc@0.5", "P", "R", "F1", "**set F1**", "exact"]
    head += ["EAA mAP", "threshold"]
    keys = ("acc_25", "acc_50", "precision", "recall", "f1", "set_f1", "exact")
    body = []
    for answers in _answer_sets(rows):
        overall = answers.overall
        cells = [answers.label, str(overall.prompts)]
        cells += [f"{getattr(overall, k):.1f}" for k in keys]
        cells[7] = f"**{cells[7]}**"
        cells.append(f"{answers.entire_area.map_3d:.2f}")
        cells.append(f"{answers.threshold:g}")
        body.append(cells)
    return _markdown(head, body)


def grounding_splits_table(rows: Sequence[Row]) -> str:
    """Acc@0.25 / set F1 / exact-set per prompt group and type tag, one row per answer set (``-``
    where a file has no prompt of that kind)."""
    body = []
    for answers in _answer_sets(rows):
        cells = [answers.label]
        for split in SPLIT_NAMES:
            entry = answers.by_group.get(split)
            if entry is None:
                entry = answers.by_type.get(split)
            if entry is None:
                cells.append("-")
                continue
            cells.append(f"{entry.acc_25:.1f} / {entry.set_f1:.1f} / {entry.exact:.1f}")
        body.append(cells)
    return _markdown(["Acc@0.25 / set F1 / exact", *SPLIT_NAMES], body)


@dataclass(frozen=True, kw_only=True)
class ResultsTableCommand:
    """``python -m model.results_table``'s command line: the rows and which table (at most one of
    the switches; none: the overall table).

    Attributes:
        rows: ``NAME=PATH.json``, one per table row (:func:`load_row`).
        by_type: Table III's shape (:func:`by_type_table`).
        by_depth: Table IV's shape (:func:`by_depth_table`).
        grounding: The per-prompt grounding metrics (:func:`grounding_table`).
        grounding_splits: Those per prompt group and type (:func:`grounding_splits_table`).
    """

    rows: tuple[str, ...] = option(positional=True, metavar="NAME=PATH.json")
    by_type: bool = option(False, exclusive="table", help="3D mAP per prompt type")
    by_depth: bool = option(False, exclusive="table", help="3D mAP per 10 m depth bin")
    grounding: bool = option(
        False,
        exclusive="table",
        help="per-prompt grounding metrics, model and baselines (class noun, oracle)",
    )
    grounding_splits: bool = option(
        False,
        exclusive="table",
        help="Acc@0.25 / set F1 / exact per prompt group and type, model and baselines",
    )

    def table(self, rows: Sequence[Row]) -> str:
        """The chosen table of ``rows``."""
        if self.by_type:
            return by_type_table(rows)
        if self.by_depth:
            return by_depth_table(rows)
        if self.grounding:
            return grounding_table(rows)
        if self.grounding_splits:
            return grounding_splits_table(rows)
        return overall_table(rows)


def run(command: ResultsTableCommand) -> int:
    """Print the table ``command`` asks for (errors raise)."""
    print(command.table([load_row(spec) for spec in command.rows]))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """``python -m model.results_table``'s parser (:class:`ResultsTableCommand`)."""
    return command_parser("python -m model.results_table", __doc__, ResultsTableCommand)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m model.results_table``; a bad results file is one ``error:`` line, exit 2."""
    return run_command(build_parser(), ResultsTableCommand, run, argv, (ResultsTableError,))


if __name__ == "__main__":
    raise SystemExit(main())
