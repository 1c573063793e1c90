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
import sys
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from model.evaluation.grounding import SPLIT_NAMES
from model.evaluation.metrics import AREAS, MIN_OVERLAPS
from model.evaluation.report import BASELINES, PROMPT_TYPES, ROW_NAMES

CLASSES: tuple[str, ...] = tuple(MIN_OVERLAPS)
"""The classes the mAP averages, in the official order."""


class ResultsTableError(ValueError):
    """A results file that is missing, unreadable or lacks a field (the message names it)."""


@dataclass(frozen=True)
class Row:
    """One table row: a label and the parsed ``model.evaluate --json`` file."""

    name: str
    result: Mapping[str, object]
    source: str


def _field(mapping: Mapping[str, object], key: str, source: str) -> object:
    if not isinstance(mapping, Mapping) or key not in mapping:
        raise ResultsTableError(f"{source}: missing field {key!r}")
    return mapping[key]


def _num(mapping: Mapping[str, object], key: str, source: str) -> float:
    value = _field(mapping, key, source)
    if not isinstance(value, int | float):
        raise ResultsTableError(f"{source}: field {key!r} is not a number ({value!r})")
    return float(value)


def load_row(spec: str) -> Row:
    """Parse ``NAME=PATH`` and read the JSON file it names."""
    name, sep, path = spec.partition("=")
    if not sep or not name or not path:
        raise ResultsTableError(f"{spec!r}: expected NAME=PATH.json")
    try:
        result = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ResultsTableError(f"{path}: no such results file") from None
    except json.JSONDecodeError as exc:
        raise ResultsTableError(f"{path}: not JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(result, Mapping):
        raise ResultsTableError(f"{path}: expected a JSON object")
    return Row(name, result, path)


def _markdown(head: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    """A markdown table: the first column left-aligned, the others (numbers) right-aligned."""
    lines = ["| " + " | ".join(head) + " |", "| --- |" + " ---: |" * (len(head) - 1)]
    lines += ["| " + " | ".join(cells) + " |" for cells in body]
    return "\n".join(lines)


def overall_table(rows: Sequence[Row]) -> str:
    """Table I's shape: per-class 3D AP, mAP and mAOS (11 points) for both areas, R40 mAP."""
    head = ["model", "frames"]
    head += [f"EAA {c[:3]}" for c in CLASSES] + ["**EAA mAP**", "EAA mAOS", "EAA mAP R40"]
    head += [f"DCA {c[:3]}" for c in CLASSES] + ["DCA mAP", "DCA mAOS"]
    body = []
    for row in rows:
        cells = [row.name, str(int(_num(row.result, "num_frames", row.source)))]
        for area in AREAS:
            scores = _field(row.result, area, row.source)
            where = f"{row.source} [{area}]"
            cells += [f"{_num(scores, f'{c}_3d_all', where):.2f}" for c in CLASSES]
            m = f"{_num(scores, 'mAP_3d', where):.2f}"
            cells += [f"**{m}**" if area == "entire_area" else m]
            cells += [f"{_num(scores, 'mAOS', where):.2f}"]
            if area == "entire_area":
                cells += [f"{_num(scores, 'mAP_3d_R40', where):.2f}"]
        body.append(cells)
    return _markdown(head, body)


def by_type_table(rows: Sequence[Row]) -> str:
    """Table III's shape: entire-area 3D mAP (11 points) per prompt type."""
    body = []
    for row in rows:
        types = _field(row.result, "by_prompt_type", row.source)
        cells = [row.name]
        for t in PROMPT_TYPES:
            entry = _field(types, t, f"{row.source} [by_prompt_type]")
            where = f"{row.source} [by_prompt_type.{t}]"
            cells.append(f"{_num(_field(entry, 'entire_area', where), 'mAP_3d', where):.2f}")
        body.append(cells)
    return _markdown(["model", *PROMPT_TYPES], body)


def by_depth_table(rows: Sequence[Row]) -> str:
    """Table IV's shape: entire-area 3D mAP (11 points) per 10 m depth bin (bins without ground
    truth objects show ``-``); the bins are those of the first row's file."""
    if not rows:
        return ""
    bins = list(_field(rows[0].result, "by_depth", rows[0].source))
    body = []
    for row in rows:
        depth = _field(row.result, "by_depth", row.source)
        cells = [row.name]
        for b in bins:
            where = f"{row.source} [by_depth.{b}]"
            entry = _field(depth, b, where)
            if _num(entry, "gt_objects", where) == 0:
                cells.append("-")
                continue
            cells.append(f"{_num(_field(entry, 'entire_area', where), 'mAP_3d', where):.2f}")
        body.append(cells)
    return _markdown(["model", *(f"{b} m" for b in bins)], body)


def _grounding(row: Row) -> tuple[Mapping[str, object], list[tuple[str, Mapping[str, object]]]]:
    """The file's ``grounding`` block and its answer sets: ``[(row label, block with "grounding"
    and "entire_area")]``, the model first, then the baselines present."""
    if "grounding" not in row.result:
        raise ResultsTableError(
            f"{row.source}: missing field 'grounding' (written before the grounding metrics; "
            "rerun python -m model.evaluate --data ROOT)"
        )
    sets: list[tuple[str, Mapping[str, object]]] = [(row.name, row.result)]
    baselines = row.result.get("baselines", {})
    if not isinstance(baselines, Mapping):
        raise ResultsTableError(f"{row.source}: field 'baselines' is not an object")
    for name in BASELINES:
        if name in baselines:
            sets.append((f"{row.name} {ROW_NAMES[name]}", baselines[name]))
    return _field(row.result, "grounding", row.source), sets  # type: ignore[return-value]


def _answer_sets(
    rows: Sequence[Row],
) -> Iterator[tuple[str, str, Mapping[str, object], Mapping[str, object]]]:
    """``(row label, where, block, its grounding block)`` of every answer set of every file (the
    model, then its baselines), ``where`` naming the file and set in errors."""
    for row in rows:
        _, sets = _grounding(row)
        for label, block in sets:
            where = f"{row.source} [{label}]"
            yield label, where, block, _field(block, "grounding", where)


def grounding_table(rows: Sequence[Row]) -> str:
    """Per-prompt grounding, one row per answer set (model, class noun, oracle) of each file."""
    head = ["model", "prompts", "Acc@0.25", "Acc@0.5", "P", "R", "F1", "**set F1**", "exact"]
    head += ["EAA mAP", "threshold"]
    keys = ("acc_25", "acc_50", "precision", "recall", "f1", "set_f1", "exact")
    body = []
    for label, where, block, g in _answer_sets(rows):
        overall = _field(g, "overall", f"{where} grounding")
        w = f"{where} grounding.overall"
        cells = [label, str(int(_num(overall, "prompts", w)))]
        cells += [f"{_num(overall, k, w):.1f}" for k in keys]
        cells[7] = f"**{cells[7]}**"
        cells.append(f"{_num(_field(block, 'entire_area', where), 'mAP_3d', where):.2f}")
        cells.append(f"{_num(g, 'operating_threshold', f'{where} grounding'):g}")
        body.append(cells)
    return _markdown(head, body)


def grounding_splits_table(rows: Sequence[Row]) -> str:
    """Acc@0.25 / set F1 / exact-set per prompt group and type tag, one row per answer set (``-``
    where a file has no prompt of that kind)."""
    body = []
    for label, where, _, g in _answer_sets(rows):
        groups = _field(g, "by_group", f"{where} grounding")
        types = _field(g, "by_prompt_type", f"{where} grounding")
        cells = [label]
        for split in SPLIT_NAMES:
            entry = groups.get(split) if isinstance(groups, Mapping) else None
            if entry is None and isinstance(types, Mapping):
                entry = types.get(split)
            if entry is None:
                cells.append("-")
                continue
            w = f"{where} grounding [{split}]"
            a, f, e = (_num(entry, k, w) for k in ("acc_25", "set_f1", "exact"))
            cells.append(f"{a:.1f} / {f:.1f} / {e:.1f}")
        body.append(cells)
    return _markdown(["Acc@0.25 / set F1 / exact", *SPLIT_NAMES], body)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m model.results_table", description=__doc__)
    parser.add_argument("rows", nargs="+", metavar="NAME=PATH.json")
    table = parser.add_mutually_exclusive_group()
    table.add_argument("--by-type", action="store_true", help="3D mAP per prompt type")
    table.add_argument("--by-depth", action="store_true", help="3D mAP per 10 m depth bin")
    table.add_argument(
        "--grounding",
        action="store_true",
        help="per-prompt grounding metrics, model and baselines (class noun, oracle)",
    )
    table.add_argument(
        "--grounding-splits",
        action="store_true",
        help="Acc@0.25 / set F1 / exact per prompt group and type, model and baselines",
    )
    args = parser.parse_args(argv)
    try:
        rows = [load_row(spec) for spec in args.rows]
        if args.by_type:
            print(by_type_table(rows))
        elif args.by_depth:
            print(by_depth_table(rows))
        elif args.grounding:
            print(grounding_table(rows))
        elif args.grounding_splits:
            print(grounding_splits_table(rows))
        else:
            print(overall_table(rows))
    except ResultsTableError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
